"""Throughput of on-the-fly training data: packed patches per second.

Cases: NLF noise (seed eq. 5.2/5.3) and ONNX Noise Flow noise (when
``simcam.noise.onnx_sampler`` and a flow are available), each with 0 and 2
DataLoader workers. Baseline, measured in the same run: drawing the same
number of float32 standard normals with numpy in the main process (the RNG
ceiling of one core). Target (issue 7): >= 2,000 NLF patches/s of 4x256x256
with 2 workers.

Usage: python benchmarks/dataloader.py [--patch 256] [--batch 16] [--batches 20] [--repeats 3] [--flow PATH.onnx]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def clean_sources(n: int, size: int) -> list[np.ndarray]:
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:size, 0:size] / size
    return [(0.05 + 0.9 * (a * xx + (1 - a) * yy)).astype(np.float32) for a in rng.random(n)]


def rate(loader, n_batches: int, batch: int) -> tuple[float, float]:
    """(patches per wall second, patches per CPU second of this process)."""
    it = iter(loader)
    next(it)  # warm-up: worker start-up is not throughput
    t0, c0 = time.perf_counter(), time.process_time()
    got = 0
    for _ in range(n_batches):
        b = next(it)
        got += b["noisy"].shape[0]
    return got / (time.perf_counter() - t0), got / max(time.process_time() - c0, 1e-9)


def baseline_rng(patch: int, n: int) -> tuple[float, float]:
    rng = np.random.default_rng(0)
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(n):
        rng.standard_normal((4, patch, patch), dtype=np.float32)
    return n / (time.perf_counter() - t0), n / max(time.process_time() - c0, 1e-9)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--patch", type=int, default=256)
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--batches", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--flow", type=str, default=None, help="ONNX Noise Flow file for the flow case")
    ap.add_argument("--flow-iso", type=float, default=800.0)
    ap.add_argument("--flow-camera", default="0", help="camera name or index of the flow")
    ap.add_argument("--cases", default="", help="comma-separated substrings: run only matching cases")
    args = ap.parse_args()

    import torch

    from simcam.dataset.noise_samplers import NLFNoise
    from simcam.dataset.torchdata import NoisyPatchDataset, make_loader

    torch.set_num_threads(1)
    p = args.patch
    srcs = clean_sources(4, 2 * p + 64)
    n = args.batch * (args.batches + 1) * 2
    cases = [("nlf (dataset.NLFNoise)", NLFNoise(beta1=(1e-4, 1e-2), beta2=(1e-6, 1e-4)))]
    try:
        from simcam.dataset.noise_samplers import ProfileNoise

        prof = Path(__file__).resolve().parent.parent / "profiles" / "sidd-gp.yaml"
        if prof.exists():
            cases.append(("nlf (profile sidd-gp, simcam.noise)", ProfileNoise(str(prof), isos=[100.0, 400.0, 800.0, 1600.0])))
    except ImportError:
        pass
    flow_note = None
    try:
        import simcam.noise.onnx_sampler  # noqa: F401
        from simcam.dataset.noise_samplers import OnnxFlowNoise

        if args.flow:
            cases.append(("noise-flow (onnx)", OnnxFlowNoise(args.flow, conds=[(float(args.flow_iso), args.flow_camera)])))
        else:
            flow_note = "noise-flow case skipped: pass --flow PATH.onnx"
    except ImportError:
        flow_note = "noise-flow case skipped: simcam.noise.onnx_sampler not available in this checkout"

    if args.cases:
        cases = [c for c in cases if any(k in c[0] for k in args.cases.split(","))]
    base = [baseline_rng(p, 50) for _ in range(args.repeats)]
    base_med = statistics.median(b[0] for b in base)
    base_cpu = statistics.median(b[1] for b in base)
    print(f"patch 4x{p}x{p} float32, batch {args.batch}, {args.batches} timed batches, median of {args.repeats}; "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}")
    print(f"baseline: numpy float32 standard_normal, main process: {base_med:,.0f} patches/s "
          f"({base_cpu:,.0f} per CPU-second)")
    print("| noise | workers | patches/s (median) | vs baseline | patches per main-process CPU-s |")
    print("|---|---|---|---|---|")
    for name, noise in cases:
        for workers in (0, 2):
            ds = NoisyPatchDataset(srcs, noise, length=n, patch_size=p, seed=0)
            rates = []
            for _ in range(args.repeats):
                loader = make_loader(ds, batch_size=args.batch, num_workers=workers)
                rates.append(rate(loader, args.batches, args.batch))
                del loader
            med = statistics.median(r[0] for r in rates)
            cpu = statistics.median(r[1] for r in rates)
            print(f"| {name} | {workers} | {med:,.0f} | {med / base_med:.2f}x | {cpu:,.0f} |")
    print("target: >= 2,000 NLF patches/s (4x256x256) with 2 workers")
    if flow_note:
        print(flow_note)


if __name__ == "__main__":
    main()
