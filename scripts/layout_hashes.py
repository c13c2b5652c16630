"""Print sha256 of a fixed set of CLI outputs, to check that a refactoring changes no bytes.

Usage: ``python scripts/layout_hashes.py [OUTDIR]`` (use the same OUTDIR for both runs: the ground-truth
report names its input files). Runs ``simcam render`` on the bundled chart (PNG,
16-bit TIFF, linear EXR) and on each DNG in ``../shared/data/dng`` (when present), ``simcam synth`` on
the chart with a profile and a fixed seed, and ``simcam gt`` on a small burst made by ``simcam synth``.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import sys
import tempfile
from pathlib import Path

from simcam.cli import main

ROOT = Path(__file__).resolve().parents[1]
SHARED_DNG = Path(os.environ.get("SIMCAM_SHARED_DATA", ROOT.parent / "shared" / "data")) / "dng"


def _sha(path: Path) -> str:
    """sha256 of the file's bytes; of its pixels for TIFF/EXR (their DateTime tag changes every run);
    of its JSON without ``timing_s`` for a report (wall-clock timings)."""
    if path.suffix in (".tif", ".exr"):
        import numpy as np
        import OpenImageIO as oiio
        import tifffile

        if path.suffix == ".tif":
            pixels = tifffile.imread(path)
        else:  # float32 holds every half value exactly
            inp = oiio.ImageInput.open(str(path))
            pixels = inp.read_image()
            inp.close()
        pixels = np.ascontiguousarray(pixels)
        return "pixels " + hashlib.sha256(f"{pixels.shape} {pixels.dtype}".encode() + pixels.tobytes()).hexdigest()
    if path.suffix == ".json":
        doc = json.loads(path.read_text())
        doc.pop("timing_s", None)
        return "json-no-timing " + hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _run(argv: list[str]) -> None:
    rc = main(argv)
    if rc != 0:
        raise SystemExit(f"simcam {' '.join(argv)} exited {rc}")


def hashes(out: Path) -> dict[str, str]:
    """Run the fixed commands into ``out``; return {output name: sha256}."""
    chart = str(ROOT / "examples" / "data" / "chart.dng")
    result: dict[str, str] = {}
    for name, extra in (("chart.png", []), ("chart16.tif", ["--depth", "16"]),
                        ("chart_linear.exr", ["-p", "linear-srgb"])):
        _run(["render", chart, "-o", str(out / name), *extra])
        result[f"render/{name}"] = _sha(out / name)
    if SHARED_DNG.is_dir():
        for dng in sorted(SHARED_DNG.glob("*.dng")):
            target = out / f"shared_{dng.stem}.png"
            err = io.StringIO()
            with contextlib.redirect_stderr(err):
                rc = main(["render", str(dng), "-o", str(target)])
            if rc == 0:
                result[f"render/{target.name}"] = _sha(target)
            else:  # a corrupt file's one-line error is part of the behaviour
                result[f"render/{target.name}"] = f"rc={rc} " + hashlib.sha256(err.getvalue().encode()).hexdigest()
    profile = str(ROOT / "profiles" / "sidd-gp.yaml")
    _run(["synth", chart, "-o", str(out / "synth"), "--profile", profile, "--iso", "800", "--seed", "7",
          "--frames", "2"])
    for f in sorted((out / "synth").iterdir()):
        result[f"synth/{f.name}"] = _sha(f)
    _run(["synth", chart, "-o", str(out / "burst"), "--profile", profile, "--iso", "400", "--seed", "3",
          "--frames", "4"])
    (out / "burst" / "clean.dng").rename(out / "clean_of_burst.dng")
    _run(["gt", str(out / "burst"), "-o", str(out / "gt.npz"), "-o", str(out / "gt.dng"),
          "--report", str(out / "gt.json")])
    for name in ("gt.npz", "gt.dng", "gt.json"):
        result[f"gt/{name}"] = _sha(out / name)
    return result


if __name__ == "__main__":
    if len(sys.argv) > 1:
        target = Path(sys.argv[1])
        target.mkdir(parents=True, exist_ok=True)
        table = hashes(target)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            table = hashes(Path(tmp))
    for key, value in table.items():
        print(f"{value}  {key}")
