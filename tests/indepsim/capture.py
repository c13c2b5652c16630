"""Write capture sets (DNG / npy directories, EMVA 1288 descriptor) plus ``truth.json``.

Command line::

    python -m tests.indepsim.capture --case NAME --out DIR [--seed S] [--fmt dng|npy|emva]
                                     [--width W --height H] [--list]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from .sensor import SensorModel, SensorSpec, scene_field

#: the standard set shape (small by default; sizes are spec["sensor"]["width"/"height"])
DEFAULT_SPEC = {
    "sensor": {},
    "effects": {},
    "isos": [100, 800, 3200],
    "darks": {"exposures_s": [0.02, 2.0], "frames": 16},
    "flats": {"exposure_s": 0.01, "levels": [0.15, 0.55], "frames": 12},
    "scene": {"exposure_s": 0.01, "level": 0.4, "frames": 16},
    "fmt": "dng",
}


def full_spec(spec: dict | None) -> dict:
    """``spec`` completed with :data:`DEFAULT_SPEC` (top-level keys; None disables darks/flats/scene)."""
    out = json.loads(json.dumps(DEFAULT_SPEC))
    for k, v in (spec or {}).items():
        out[k] = v
    return out


def _ms(t: float) -> str:
    return f"{t * 1000:g}".replace(".", "p")


def sequences_of(spec: dict, sensor: SensorSpec) -> list[dict]:
    """The planned sequences: name, kind, iso, exposure, mean photo-electrons, frames."""
    seqs = []
    for iso in spec["isos"]:
        sat = sensor.saturation_e(iso)
        if spec.get("darks"):
            for t in spec["darks"]["exposures_s"]:
                seqs.append({"name": f"dark_iso{iso}_t{_ms(t)}ms", "kind": "dark", "iso": iso, "exposure_s": t,
                             "mean_e": 0.0, "frames": spec["darks"]["frames"]})
        if spec.get("flats"):
            fl = spec["flats"]
            t = fl["exposure_s"]
            if "photons_per_s" in fl:  # absolute irradiance: photons / pixel / s, converted with the QE
                for q in fl["photons_per_s"]:
                    seqs.append({"name": f"flat_iso{iso}_p{q:.0f}", "kind": "flat", "iso": iso, "exposure_s": t,
                                 "mean_e": q * sensor.qe * t, "frames": fl["frames"]})
            else:  # ``levels``: fraction of the saturation charge at this ISO
                for lv in fl["levels"]:
                    seqs.append({"name": f"flat_iso{iso}_l{round(lv * 100):02d}", "kind": "flat", "iso": iso,
                                 "exposure_s": t, "mean_e": lv * sat, "frames": fl["frames"]})
        if spec.get("scene"):
            sc = spec["scene"]
            seqs.append({"name": f"scene_iso{iso}", "kind": "scene", "iso": iso, "exposure_s": sc["exposure_s"],
                         "mean_e": sc["level"] * sat, "frames": sc["frames"]})
    for s in seqs:
        s["photons_per_pixel"] = s["mean_e"] / sensor.qe
    return seqs


def write_capture_set(out_dir, spec: dict | None = None, seed: int = 0) -> dict:
    """Simulate and write a capture set; returns the truth manifest (also written to ``truth.json``).

    Parameters
    ----------
    out_dir : path
        Created if needed; one sub-directory per sequence (``fmt`` "dng" or "npy"), or an
        ``EMVA1288_Data.txt`` descriptor with PNGs (``fmt`` "emva", monochrome only).
    spec : dict
        Keys of :data:`DEFAULT_SPEC`: ``sensor`` (SensorSpec fields), ``effects``
        (``{name: params}``), ``isos``, ``darks``, ``flats``, ``scene``, ``fmt``.
    seed : int
        Seed of everything (fixed patterns, scene, per-frame noise); same seed -> same bytes.
    """
    spec = full_spec(spec)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sensor = SensorSpec(**spec["sensor"])
    model = SensorModel(sensor, spec["effects"], seed)
    fmt = spec["fmt"]
    if fmt == "emva" and sensor.cfa is not None:
        raise ValueError("fmt 'emva' needs a monochrome sensor (cfa None)")
    scene = scene_field(sensor.height, sensor.width, np.random.default_rng([seed, 3]))
    seqs = sequences_of(spec, sensor)
    emva_lines = [f"n {sensor.bits} {sensor.width} {sensor.height}"]
    for si, s in enumerate(seqs):
        t = s["exposure_s"]
        if s["kind"] == "dark":
            flux = 0.0
        elif s["kind"] == "flat":
            flux = s["mean_e"] / t
        else:
            flux = scene * np.float32(s["mean_e"] / t / float(scene.mean()))
        d = out / s["name"]
        if fmt == "emva":
            d = out / "images" / s["name"]
            emva_lines.append(f"d {t * 1e9:.0f}" if s["kind"] == "dark" else
                              f"b {t * 1e9:.0f} {s['photons_per_pixel']:.6g}")
            if s["kind"] == "scene":
                emva_lines.pop()
                continue
        d.mkdir(parents=True, exist_ok=True)
        for i in range(s["frames"]):
            rng = np.random.default_rng([seed, 4, si, i])
            fr = model.frame(s["kind"], s["iso"], t, flux, rng, i, s["frames"])
            _write_frame(d, i, fr, sensor, s, fmt, emva_lines, out)
        if fmt == "npy":
            _write_yaml(d / "sequence.yaml", sensor, s)
    if fmt == "emva":
        (out / "EMVA1288_Data.txt").write_text("\n".join(emva_lines) + "\n")
    truth = {
        "generator": "tests.indepsim",
        "case": spec.get("case"),
        "held_out": spec.get("held_out"),
        "seed": int(seed),
        "fmt": fmt,
        "sensor": sensor.to_dict(spec["isos"]),
        "black_true_dn": (sensor.black_map2() + _black_offset(spec)).tolist(),
        "effects": {e.name: e.truth() for e in model.effects},
        "sequences": seqs,
        "spec": spec,
    }
    (out / "truth.json").write_text(json.dumps(truth, indent=1, default=float))
    return truth


def _black_offset(spec):
    e = spec["effects"].get("black_level_offset")
    return float(e["offset_dn"]) if e else 0.0


def _write_frame(d: Path, i: int, fr: np.ndarray, sensor: SensorSpec, s: dict, fmt: str, lines, root):
    if fmt == "dng":
        from .dngwrite import write_dng

        write_dng(d / f"frame_{i:03d}.dng", fr, cfa=sensor.cfa, black=sensor.black_map2(), white=sensor.white_dn,
                  iso=s["iso"], exposure_s=s["exposure_s"])
    elif fmt == "npy":
        np.save(d / f"frame_{i:03d}.npy", fr)
    elif fmt == "emva":
        p = d / f"frame_{i:03d}.png"
        write_png(p, fr, sensor.bits)
        lines.append("i " + str(p.relative_to(root)).replace("/", "\\"))
    else:
        raise ValueError(f"fmt {fmt!r}; expected 'dng', 'npy' or 'emva'")


def _write_yaml(path: Path, sensor: SensorSpec, s: dict):
    import yaml

    b = sensor.black_map2()
    black = float(b[0, 0]) if np.all(b == b[0, 0]) else b.tolist()
    path.write_text(yaml.safe_dump({"iso": int(s["iso"]), "exposure_s": float(s["exposure_s"]), "cfa": sensor.cfa,
                                    "black_level": black, "white_level": int(sensor.white_dn)}))


def write_png(path: Path, img: np.ndarray, bits: int) -> None:
    """Monochrome PNG, 8-bit for ``bits <= 8`` else 16-bit, values stored unscaled (OpenImageIO)."""
    import OpenImageIO as oiio

    fmt = oiio.UINT8 if bits <= 8 else oiio.UINT16
    arr = img.astype(np.uint8 if bits <= 8 else np.uint16)
    o = oiio.ImageOutput.create(str(path))
    if o is None or not o.open(str(path), oiio.ImageSpec(arr.shape[1], arr.shape[0], 1, fmt)):
        raise OSError(f"{path}: cannot write PNG ({oiio.geterror()})")
    try:
        if not o.write_image(np.ascontiguousarray(arr[:, :, None])):
            raise OSError(f"{path}: cannot write PNG pixels ({o.geterror()})")
    finally:
        o.close()


def main(argv=None) -> int:
    from .cases import CASES, case_spec

    ap = argparse.ArgumentParser(prog="python -m tests.indepsim.capture", description=__doc__.splitlines()[0])
    ap.add_argument("--case", help="case name (see --list)")
    ap.add_argument("--out", help="output directory")
    ap.add_argument("--seed", type=int, default=None, help="seed (default: the case's own)")
    ap.add_argument("--fmt", choices=["dng", "npy", "emva"], default=None)
    ap.add_argument("--width", type=int)
    ap.add_argument("--height", type=int)
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    a = ap.parse_args(argv)
    if a.list:
        for c in CASES:
            print(f"{c['name']:55s} held_out={c['held_out']!s:5s} effects={','.join(c['effects']) or '-'}")
        return 0
    if not a.case or not a.out:
        ap.error("--case and --out are required")
    byname = {c["name"]: c for c in CASES}
    if a.case not in byname:
        ap.error(f"unknown case {a.case!r}; see --list")
    c = byname[a.case]
    seed = c["seed"] if a.seed is None else a.seed
    spec = case_spec(c, seed)
    if a.fmt:
        spec["fmt"] = a.fmt
    for k in ("width", "height"):
        if getattr(a, k):
            spec.setdefault("sensor", {})[k] = getattr(a, k)
    truth = write_capture_set(a.out, spec, seed)
    print(f"{a.out}: {len(truth['sequences'])} sequences, effects {sorted(truth['effects'])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
