"""simcam.torch noise throughput (GP/s = 1e9 noisy values per second) against baselines measured in the same run.

Batch: 64 x 4x256x256 packed normalised raw (``--quick``: 16), clean uniform in [0.01, 0.8),
beta1 / beta2 of a Poisson-Gaussian profile at ISO 800 (``examples/data/loop_profile.yaml``).

CPU rows: ``simcam.torch.add_noise`` for ``nlf`` (site-independent betas: simcam's fused kernel; per-site
betas: the torch operations used on CUDA), exact ``poisson_gaussian`` (``torch.poisson``)
and the loop profile's ``composite`` (ISO 800: Poisson-Gaussian + column FPN, DSNU, black-level
offset); baselines: the numba NLF kernel (:func:`simcam.noise.kernels.nlf.nlf_noise`, unclipped),
plain numpy NLF (``clean + sqrt(beta1 clean + beta2) * standard_normal``), the numpy
``poisson_gaussian`` model (``NoiseModel.sample_stack``) and ``torch.randn`` of the same shape.
CUDA rows (when available): the same torch rows against ``torch.randn`` of the same shape as the
floor; targets: NLF <= 1.5x the floor, exact Poisson-Gaussian <= 3x.

Wall-clock median of N repeats after one warm-up (``--repeats``); CUDA rows synchronise
before and after each call. The CPU model is read from /proc/cpuinfo; other processes on
the machine slow every row alike (the ratios are the meaningful part on a shared machine).

Usage: ``python benchmarks/torch_noise.py [--quick] [--repeats 5] [--batch 64] [--size 256]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/machine.py, also when loaded by path
from machine import cpu_model  # noqa: E402

from simcam.noise import model_from_entry  # noqa: E402
from simcam.noise.kernels.nlf import nlf_noise  # noqa: E402
from simcam.profiles.schema import load_profile  # noqa: E402
from simcam.torch import add_noise  # noqa: E402




def timed(fn, repeats: int, sync=None) -> float:
    fn()
    if sync:
        sync()
    ts = []
    for _ in range(repeats):
        if sync:
            sync()
        t0 = time.perf_counter()
        fn()
        if sync:
            sync()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def main(argv=None) -> list[tuple]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="batch 16, 3 repeats")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--size", type=int, default=256)
    a = ap.parse_args(argv)
    if a.quick:
        a.batch, a.repeats = min(a.batch, 16), min(a.repeats, 3)
    b, s = a.batch, a.size
    n = b * 4 * s * s
    prof = load_profile(ROOT / "examples" / "data" / "loop_profile.yaml")
    comp = prof.model_for(800)
    base = comp.base
    b1, b2 = float(base.beta1), float(base.beta2)
    nlf = model_from_entry({"type": "nlf", "beta1": b1, "beta2": b2})
    pg = model_from_entry({"type": "poisson_gaussian", "beta1": b1, "beta2": b2})
    print(f"CPU: {cpu_model()} ({os.cpu_count()} logical cores); torch {torch.__version__}, "
          f"{torch.get_num_threads()} threads; batch {b} x 4x{s}x{s} = {n / 1e6:.1f} M values; "
          f"beta1 {b1:.3g}, beta2 {b2:.3g}; median of {a.repeats}")
    rows = []

    def row(device, name, sec, floor=None):
        gps = n / sec / 1e9
        ratio = "" if floor is None else f"{sec / floor:.2f}x"
        rows.append((device, name, sec, gps, ratio))
        print(f"{device:5s} {name:44s} {sec * 1e3:9.1f} ms {gps:8.3f} GP/s  {ratio}", flush=True)

    g = torch.Generator().manual_seed(0)
    clean = 0.01 + 0.79 * torch.rand((b, 4, s, s), generator=g)
    cnp = clean.numpy()
    rng = np.random.default_rng(0)
    floor = timed(lambda: torch.randn(clean.shape, generator=g), a.repeats)
    row("cpu", "torch.randn (floor)", floor)
    row("cpu", "simcam.torch nlf", timed(lambda: add_noise(clean, nlf, generator=g, validate=False), a.repeats), floor)
    nlf4 = model_from_entry({"type": "nlf", "beta1": [b1, b1 * 1.01, b1, b1], "beta2": b2})
    row("cpu", "simcam.torch nlf, torch ops (per-site betas)",
        timed(lambda: add_noise(clean, nlf4, generator=g, validate=False), a.repeats), floor)
    row("cpu", "simcam.torch poisson_gaussian (exact)",
        timed(lambda: add_noise(clean, pg, generator=g), a.repeats), floor)
    row("cpu", "simcam.torch composite (loop profile, ISO 800)",
        timed(lambda: add_noise(clean, comp, generator=g, validate=False), a.repeats), floor)
    out = np.empty_like(cnp)
    row("cpu", "numba nlf_kernel.nlf_noise (1 thread)",
        timed(lambda: nlf_noise(cnp, b1, b2, rng, clip=None, out=out), a.repeats), floor)
    row("cpu", "numpy NLF (standard_normal float32)",
        timed(lambda: cnp + np.sqrt(b1 * cnp + b2) * rng.standard_normal(cnp.shape, dtype=np.float32), a.repeats),
        floor)
    mosaic = np.ascontiguousarray(cnp.reshape(b, 4 * s, s))  # sample_stack: n x H x W, H even (law only)
    row("cpu", "numpy poisson_gaussian (sample_stack)",
        timed(lambda: pg.sample_stack(mosaic, _cond(), rng), a.repeats), floor)
    if torch.cuda.is_available():
        dev = torch.device("cuda")
        gc = torch.Generator(device="cuda").manual_seed(0)
        cc = clean.to(dev)
        sync = torch.cuda.synchronize
        print(f"CUDA: {torch.cuda.get_device_name(0)}")
        floor = timed(lambda: torch.randn(cc.shape, generator=gc, device=dev), a.repeats, sync)
        row("cuda", "torch.randn (floor)", floor)
        row("cuda", "simcam.torch nlf (target <= 1.5x)",
            timed(lambda: add_noise(cc, nlf, generator=gc, validate=False), a.repeats, sync), floor)
        row("cuda", "simcam.torch poisson_gaussian (target <= 3x)",
            timed(lambda: add_noise(cc, pg, generator=gc, validate=False), a.repeats, sync), floor)
        row("cuda", "simcam.torch composite (loop profile, ISO 800)",
            timed(lambda: add_noise(cc, comp, generator=gc, validate=False), a.repeats, sync), floor)
    else:
        print("CUDA: not available (torch.cuda.is_available() is False): CUDA rows skipped")
    return rows


def _cond():
    from simcam.noise import NoiseCondition

    return NoiseCondition(cfa=None)


if __name__ == "__main__":
    main()
