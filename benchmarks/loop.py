"""Wall time and peak memory of ``simcam loop`` on whole frames of 0.2, 1, 3 and 12 MP.

Each capture set has 3 ISOs; per ISO: darks at two exposure times x 16 frames, two flats x 8
frames, one scene x 16 frames (``.npy`` frames + ``sequence.yaml``, 12-bit Bayer RGGB). The sensor
is a plain numpy Poisson-Gaussian with a dark current, a DSNU map and a PRNU map (not simcam's noise
code). The loop runs with its defaults (whole frames; residual battery and bootstrap on at most
448 x 448 pixels per frame, tiles spread over the frame beyond that) in a subprocess; peak RSS is
that process's maximum resident set size (``resource.getrusage(RUSAGE_CHILDREN)``), wall time
includes reading the frames. The machine's load average is printed with each row (other processes
share the cores).

Measured (shared 2-core machine, load average 2.3-4.5): 0.2 MP 148 s / 1.04 GB, 1 MP 317 s /
1.22 GB, 3 MP 344 s / 1.27 GB, 12 MP 202 s / 1.48 GB (docs/loop.md), before attribution by held-out
model comparison. With it (candidates race, replicates on 2 threads, 12 held-out replicates, 448 x 448
budget, a second look for uncertain candidates): 12 MP 458 s / 2.54 GB, load average 1.6 (docs/loop.md
has the steps); session 8: 583 s / 2.53 GB; session 9: 438 s / 2.52 GB with the ISO-100 group stopping
two iterations early; session 10: 662 s / 2.51 GB; session 11: 453 s / 2.49 GB with session 10's results
(docs/loop.md).

Usage::

    python benchmarks/loop.py --sizes 0.2 1 --work /tmp/loopbench
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/machine.py
from machine import cpu_model  # noqa: E402

SHAPES = {"0.2": (384, 512), "1": (864, 1152), "3": (1536, 2048), "12": (3000, 4000)}
ISOS = {100: 0.5, 800: 4.0, 3200: 16.0}  # ISO -> K (DN / e-)
BLACK, WHITE, READ_E = 256.0, 4095.0, 2.0
DARK_CURRENT_E_S = 40.0


def write_set(root: Path, shape, seed: int = 0) -> Path:
    """The capture set described in the module docstring (frames written one at a time)."""
    rng = np.random.default_rng(seed)
    h, w = shape
    dsnu = rng.normal(0.0, 1.5, shape)  # e-
    prnu = 1.0 + rng.normal(0.0, 0.01, shape)
    yy, xx = np.mgrid[0:h, 0:w]
    scene = 0.2 + 0.3 * (np.sin(xx / 37.0) * np.cos(yy / 53.0) + 1.0)  # fraction of full scale
    for iso, K in ISOS.items():
        full_e = (WHITE - BLACK) / K
        seqs = {f"dark_t010_iso{iso}": (0.01, 16, 0.0), f"dark_t100_iso{iso}": (0.1, 16, 0.0),
                f"flat_0_iso{iso}": (0.01, 8, 0.25), f"flat_1_iso{iso}": (0.01, 8, 0.6),
                f"scene_iso{iso}": (0.01, 16, scene)}
        for name, (t, n, level) in seqs.items():
            d = root / name
            if (d / "sequence.yaml").exists():
                continue
            d.mkdir(parents=True, exist_ok=True)
            mean_e = np.asarray(level) * full_e * prnu + DARK_CURRENT_E_S * t + 5.0
            for i in range(n):
                e = rng.poisson(np.broadcast_to(mean_e, shape)) + rng.normal(0.0, READ_E, shape) + dsnu
                dn = np.clip(np.round(BLACK + K * e), 0, WHITE).astype(np.uint16)
                np.save(d / f"frame_{i:03d}.npy", dn)
            (d / "sequence.yaml").write_text(yaml.safe_dump({"iso": iso, "exposure_s": t, "cfa": "RGGB",
                                                              "black_level": BLACK, "white_level": WHITE}))
    return root


def run(size: str, work: Path) -> dict:
    cap = write_set(work / f"set_{size}mp", SHAPES[size])
    out = work / f"out_{size}mp"
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t0 = time.time()
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parent.parent))
    proc = subprocess.run([sys.executable, "-m", "simcam", "loop", str(cap), "--out", str(out)], env=env,
                          capture_output=True, text=True)
    wall = time.time() - t0
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    if proc.returncode != 0:
        raise SystemExit(f"simcam loop failed on {size} MP:\n{proc.stderr[-3000:]}")
    return {"size_mp": size, "frame": f"{SHAPES[size][1]}x{SHAPES[size][0]}", "wall_s": wall,
            "peak_rss_gb": max(peak, before) / 1024 ** 2, "load_avg": os.getloadavg()[0],
            "summary": proc.stdout.strip().splitlines()[:3]}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", nargs="+", default=["0.2", "1", "3", "12"], choices=list(SHAPES))
    ap.add_argument("--work", type=Path, default=Path("/tmp/simcam-loop-bench"))
    args = ap.parse_args()
    print(f"CPU: {cpu_model()}, {os.cpu_count()} cores; SIMCAM_LOOP_THREADS={os.environ.get('SIMCAM_LOOP_THREADS', '')!r}")
    print("| set | frame | wall (s) | peak RSS (GB) | load avg |")
    print("|---|---|---|---|---|")
    for size in args.sizes:
        r = run(size, args.work)
        print(f"| {r['size_mp']} MP | {r['frame']} | {r['wall_s']:.0f} | {r['peak_rss_gb']:.2f} | {r['load_avg']:.1f} |",
              flush=True)
        for line in r["summary"]:
            print("    " + line)


if __name__ == "__main__":
    main()
