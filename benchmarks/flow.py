"""Noise Flow sampling throughput: torch eager vs onnxruntime, same run, same threads.

Usage: python benchmarks/flow.py [--threads 2] [--size 512] [--repeats 5] [--onnx PATH]

Prints the median time and megapixels (mosaic pixels = 4 * packed pixels) per second
of the latent -> noise pass on a [1, 4, size, size] packed patch, for torch eager
(float32, no grad, 1x1 inverses precomputed) and onnxruntime (CPU EP) running the same
model. Targets (issue 4): onnxruntime >= 20 MP/s and >= 1.5x torch eager at 2 threads.
The model is a simcam paper-configuration flow (default: an export of it built here;
the compute does not depend on the weights' values).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _median_time(fn, repeats):
    fn()  # warm-up
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--size", type=int, default=512, help="packed side (mosaic is 2x)")
    ap.add_argument("--batch", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)

    import torch

    from simcam.noise.flow.export import export_onnx
    from simcam.noise.flow.model import FlowConfig, NoiseFlow
    from simcam.noise.onnx_sampler import NoiseFlowRuntime

    torch.set_num_threads(args.threads)
    flow = NoiseFlow(FlowConfig(arch="paper", cameras=["GP"], iso_knots=[100.0, 1600.0], sdn_per_iso=True)).eval()
    flow.freeze()
    rng = np.random.default_rng(0)
    shape = (args.batch, 4, args.size, args.size)
    clean = rng.random(shape, dtype=np.float32)
    z = rng.standard_normal(shape).astype(np.float32)
    mp = 4 * np.prod(shape[0:1] + shape[2:]) / 1e6
    with tempfile.TemporaryDirectory() as tmp:
        path, _ = export_onnx(flow, Path(tmp) / "model.onnx")
        sampler = NoiseFlowRuntime(path, threads=args.threads)
        ct, zt = torch.from_numpy(clean), torch.from_numpy(z)

        def run_torch():
            with torch.no_grad():
                flow.sample(zt, clean=ct, iso=400.0, camera=0)

        def run_ort():
            sampler.sample(clean, z=z, iso=400.0, camera=0)

        t_torch = _median_time(run_torch, args.repeats)
        t_ort = _median_time(run_ort, args.repeats)
    import os

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"Noise Flow sampling, packed {shape}, {mp:.2f} MP mosaic, {args.threads} threads, median of {args.repeats}; "
          f"{os.cpu_count()} CPUs, load average {load:.1f} (other processes share them)")
    print(f"{'backend':<22}{'s/call':>10}{'MP/s':>10}{'vs torch':>10}")
    print(f"{'torch eager ' + torch.__version__:<22}{t_torch:>10.4f}{mp / t_torch:>10.2f}{1.0:>10.2f}")
    import onnxruntime

    print(f"{'onnxruntime ' + onnxruntime.__version__:<22}{t_ort:>10.4f}{mp / t_ort:>10.2f}{t_torch / t_ort:>10.2f}")
    ok = mp / t_ort >= 20 and t_torch / t_ort >= 1.5
    print(f"targets (ONNX >= 20 MP/s and >= 1.5x torch): {'met' if ok else 'NOT met'}")


if __name__ == "__main__":
    main()
