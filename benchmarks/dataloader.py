"""Throughput of on-the-fly training data: packed noisy/clean patch pairs per second.

Cases, each with 0 workers, 2 process workers (PyTorch's ``DataLoader``) and 2 thread
workers (:class:`simcam.training.loader.ThreadLoader`), all through
``simcam.training.patches.make_loader``:

* ``nlf kernel``: :class:`NLFNoise` with its default fused numba kernel (Abdelhamed 2020, eq. 5.2/5.3);
* ``nlf numpy``: the same sampler with ``normals="numpy"`` -- the hand-written numpy code
  (``rng.standard_normal`` then three array passes), the named baseline;
* ``nlf profile``: noise from a calibration profile through ``simcam.noise`` (sidd-gp);
* ``noise-flow (onnx)``: the shipped ONNX Noise Flow (``profiles/noiseflow_sidd_gp.onnx``).

Ceilings measured in the same run: numpy's float32 ``standard_normal`` for one patch in
the main process (the RNG floor of one core), and the DataLoader's transfer of a
ready-made noisy/clean pair from 2 workers (``transfer only``: no noise, no crop; what
remains is the shared-memory hand-over of 2 x 4 x p x p float32 per patch).

Target (issue 7): >= 2,000 NLF patches/s with 2 workers for "256x256 packed" patches,
measured here for both readings: a 256 x 256 raw crop packed to 4 x 128 x 128 (SIDD's
block size) and a 4 x 256 x 256 packed patch (a 512 x 512 crop).

Usage: python benchmarks/dataloader.py [--patches 128,256] [--batch 16] [--batches 40] [--repeats 3] [--flow PATH.onnx]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def clean_sources(n: int, size: int) -> list[np.ndarray]:
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:size, 0:size] / size
    return [(0.05 + 0.9 * (a * xx + (1 - a) * yy)).astype(np.float32) for a in rng.random(n)]


def rate(loader, n_batches: int, batch: int) -> tuple[float, float]:
    """(patches per wall second, patches per CPU second of this process)."""
    it = iter(loader)
    for _ in range(2):  # warm-up: worker start-up and the first prefetched batches are not throughput
        next(it)
    t0, c0 = time.perf_counter(), time.process_time()
    got = 0
    for _ in range(n_batches):
        b = next(it)
        got += b["noisy"].shape[0]
    out = got / (time.perf_counter() - t0), got / max(time.process_time() - c0, 1e-9)
    for _ in it:  # finish the epoch: shutting spawn workers down mid-epoch can make torch's worker
        pass  # abort at exit ("terminate called without an active exception"), harmless but noisy
    return out


def baseline_rng(patch: int, n: int) -> tuple[float, float]:
    rng = np.random.default_rng(0)
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(n):
        rng.standard_normal((4, patch, patch), dtype=np.float32)
    return n / (time.perf_counter() - t0), n / max(time.process_time() - c0, 1e-9)


class TransferOnly:
    """Dataset of one ready-made noisy/clean pair per index (the DataLoader hand-over alone)."""

    def __init__(self, n: int, p: int):
        self.n, self.p = n, p

    def __len__(self):
        return self.n

    def __getitem__(self, i):
        import torch

        if not hasattr(self, "_pair"):
            self._pair = torch.rand(2, 4, self.p, self.p)
        return {"noisy": self._pair[0].clone(), "clean": self._pair[1].clone(), "meta": {"index": i}}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--patches", default="128,256", help="packed patch sides to measure")
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--batches", type=int, default=40)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--flow", type=str, default=str(ROOT / "profiles" / "noiseflow_sidd_gp.onnx"),
                    help="ONNX Noise Flow file for the flow case ('' to skip)")
    ap.add_argument("--flow-iso", type=float, default=800.0)
    ap.add_argument("--flow-camera", default="0", help="camera name or index of the flow")
    ap.add_argument("--cases", default="", help="comma-separated substrings: run only matching cases")
    args = ap.parse_args()

    import torch

    from simcam.training.samplers import NLFNoise, ProfileNoise
    from simcam.training.patches import NoisyPatchDataset, make_loader

    torch.set_num_threads(1)
    nlf = dict(beta1=(1e-4, 1e-2), beta2=(1e-6, 1e-4))
    cases = [("nlf numpy (baseline)", NLFNoise(**nlf, normals="numpy")), ("nlf kernel", NLFNoise(**nlf)),
             ("nlf profile sidd-gp", ProfileNoise(str(ROOT / "profiles" / "sidd-gp.yaml"), isos=[100.0, 400.0, 800.0, 1600.0]))]
    flow_note = None
    if args.flow and Path(args.flow).exists():
        from simcam.training.samplers import FlowNoise

        cam = int(args.flow_camera) if args.flow_camera.isdigit() else args.flow_camera
        cases.append(("noise-flow (onnx)", FlowNoise(args.flow, conds=[(float(args.flow_iso), cam)])))
    else:
        flow_note = f"noise-flow case skipped: no flow at {args.flow!r}"
    if args.cases:
        cases = [c for c in cases if any(k in c[0] for k in args.cases.split(","))]

    print(f"batch {args.batch}, {args.batches} timed batches, median of {args.repeats}; "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}")
    print("| patch | case | workers | patches/s (median) | vs nlf numpy, same workers | main-process CPU-s per 1k patches |")
    print("|---|---|---|---:|---:|---:|")
    for p in [int(x) for x in args.patches.split(",")]:
        size = f"4x{p}x{p}"
        base = [baseline_rng(p, 50) for _ in range(args.repeats)]
        print(f"| {size} | numpy standard_normal, one patch, main process | - | "
              f"{statistics.median(b[0] for b in base):,.0f} | | |")
        n = args.batch * (args.batches + 2)
        rates = [rate(make_loader(TransferOnly(n, p), batch_size=args.batch, num_workers=2), args.batches, args.batch)
                 for _ in range(args.repeats)]
        print(f"| {size} | transfer only (ready-made pair) | 2 processes | {statistics.median(r[0] for r in rates):,.0f} | | |")
        srcs = clean_sources(4, 2 * p + 64)
        ref = {}
        for name, noise in cases:
            for workers, kind in ((0, "process"), (2, "process"), (2, "thread")):
                ds = NoisyPatchDataset(srcs, noise, length=n, patch_size=p, seed=0)
                rates = []
                for _ in range(args.repeats):
                    loader = make_loader(ds, batch_size=args.batch, num_workers=workers, workers=kind)
                    rates.append(rate(loader, args.batches, args.batch))
                    del loader
                med = statistics.median(r[0] for r in rates)
                cpu = statistics.median(r[1] for r in rates)
                key = (workers, kind)
                if name.startswith("nlf numpy"):
                    ref[key] = med
                vs = f"{med / ref[key]:.2f}x" if key in ref else ""
                wname = f"{workers} {kind}{'es' if kind == 'process' else 's'}" if workers else "0"
                main_cpu = f"{1000 / cpu:.2f}" if kind == "process" else "(all work)"
                print(f"| {size} | {name} | {wname} | {med:,.0f} | {vs} | {main_cpu} |", flush=True)
    print("target: >= 2,000 NLF patches/s with 2 workers ('256x256 packed'). Thread workers' rows: all the work "
          "is in this process, so its CPU time is not a hand-over cost and is not shown.")
    if flow_note:
        print(flow_note)


if __name__ == "__main__":
    main()
