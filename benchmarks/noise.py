"""Noise sampling throughput (MP/s) against named baselines measured in the same run.

* NLF (``nlf`` model, exact Gaussian) vs the RNG floor: numpy
  ``Generator.standard_normal(size, dtype=float32)`` of the same size (and
  ``torch.randn`` when torch is installed). Target: NLF time <= 1.5x the floor.
* exact Poisson-Gaussian (``poisson_gaussian`` model, including its Gaussian
  part; alias tables + numba kernel, :mod:`simcam.noise.kernels.poisson`) vs
  numpy ``Generator.poisson`` over the same lambda = clean / beta1 (Poisson
  part only). Target: >= 4x faster. The steady-state rows reuse the cached
  tables (typical use: many frames with one profile); the one-time costs
  (numba kernel load/compile, table build on the first call) are printed in
  a second table.

Clean image: uniform random in [0, 1) (lambda spans 0 .. 1/beta1); beta from
the SIDD Google Pixel profile (ISO 800 and ISO 100). Median of 3 timed calls
per row after a small warm-up; single thread (numpy ufuncs and generators). Times are
process CPU time (``time.process_time``), so other load on the machine skews
them less than wall time would. The last two rows are wall clock, with the
sampler's row blocks on ``os.cpu_count()`` threads (byte-identical output).

Usage: ``python benchmarks/noise.py [--quick] [--mp 12]``
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from simcam.noise import NoiseCondition, model_from_entry  # noqa: E402


def _time(fn, repeats: int = 3):
    """Median CPU seconds of this process over ``repeats`` calls (robust on a
    shared machine; every sampler here runs on one thread except torch, see its row)."""
    ts = []
    for _ in range(repeats):
        t = time.process_time()
        fn()
        ts.append(time.process_time() - t)
    return float(np.median(ts))


def _wall(fn, repeats: int = 3):
    """Median wall-clock seconds over ``repeats`` calls."""
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return float(np.median(ts))


def run(h: int, w: int, seed: int = 0, with_torch: bool = True) -> list[tuple[str, float, str]]:
    rng = np.random.default_rng(seed)
    clean = rng.random((h, w), dtype=np.float32)
    cond = NoiseCondition(cfa="RGGB")
    mp = h * w / 1e6
    rows = []
    nlf = model_from_entry({"type": "nlf", "beta1": 1.764e-3, "beta2": 1.2e-5})
    nlf.sample(clean[:64], cond, rng)  # warm-up
    t_floor = _time(lambda: rng.standard_normal(h * w, dtype=np.float32))
    t_nlf = _time(lambda: nlf.sample(clean, cond, rng))
    rows.append(("RNG floor: numpy standard_normal float32", mp / t_floor, "1.00x (baseline)"))
    try:
        if not with_torch:
            raise ImportError
        import torch

        g = torch.Generator().manual_seed(0)
        torch.randn(1000, generator=g)
        t_torch = _time(lambda: torch.randn(h * w, generator=g, dtype=torch.float32))
        rows.append((f"RNG floor: torch.randn float32 ({torch.get_num_threads()} threads, CPU time summed)", mp / t_torch,
                     f"{t_torch / t_floor:.2f}x numpy floor time"))
    except ImportError:  # pragma: no cover
        pass
    rows.append(("simcam nlf sample", mp / t_nlf, f"{t_nlf / t_floor:.2f}x floor time (target <= 1.5x)"))
    from simcam.noise.kernels import poisson as poisson_table

    once = []
    t0, c0 = time.perf_counter(), time.process_time()
    model_from_entry({"type": "poisson_gaussian", "beta1": 1.0, "beta2": 0.0}).sample(clean[:2, :2], cond, rng)
    once.append(("numba kernel load (first call in the process, cache=True)", time.process_time() - c0,
                 time.perf_counter() - t0))
    for iso, b1, b2 in ((800, 1.764e-3, 1.2e-5), (100, 2.28e-4, 2.0e-6)):
        pg = model_from_entry({"type": "poisson_gaussian", "beta1": b1, "beta2": b2})
        poisson_table.build_tables.cache_clear()
        t0, c0 = time.perf_counter(), time.process_time()
        pg.sample(clean, cond, rng)  # first call: builds the tables
        once.append((f"first frame call incl. table build (ISO {iso}, lambda <= "
                     f"{poisson_table.A_STEP * poisson_table.coarse_count(1 / b1)})",
                     time.process_time() - c0, time.perf_counter() - t0))
        poisson_table.build_tables.cache_clear()
        t0, c0 = time.perf_counter(), time.process_time()
        poisson_table.tables_for(float(clean.max()) / b1)
        once.append((f"table build alone (ISO {iso})", time.process_time() - c0, time.perf_counter() - t0))
        lam = clean.astype(np.float64) / b1
        t_np = _time(lambda: rng.poisson(lam))
        t_pg = _time(lambda: pg.sample(clean, cond, rng))
        rows.append((f"numpy poisson, lambda = clean/beta1 (ISO {iso}, max {1 / b1:.0f})", mp / t_np, "1.00x (baseline)"))
        rows.append((f"simcam poisson_gaussian exact (ISO {iso})", mp / t_pg,
                     f"{t_np / t_pg:.2f}x faster than numpy poisson (one thread)"))
    # wall clock with row blocks on a thread pool (same bytes as one thread)
    n = os.cpu_count() or 1
    pg = model_from_entry({"type": "poisson_gaussian", "beta1": 1.764e-3, "beta2": 1.2e-5})
    lam = clean.astype(np.float64) / 1.764e-3
    w_np = _wall(lambda: rng.poisson(lam))
    w_pg = _wall(lambda: pg.sample(clean, cond, rng, threads=n))
    rows.append(("numpy poisson (ISO 800), wall clock", mp / w_np, "1.00x (baseline)"))
    rows.append((f"simcam poisson_gaussian exact (ISO 800), {n} threads, wall clock", mp / w_pg,
                 f"{w_np / w_pg:.2f}x faster than numpy poisson (target >= 4x, all cores vs numpy's one)"))
    return rows, once


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="256 x 256 smoke run (no torch row)")
    ap.add_argument("--mp", type=float, default=12.0, help="megapixels (4:3), default 12")
    a = ap.parse_args(argv)
    if a.quick:
        h, w = 256, 256
    else:
        w = int(round(np.sqrt(a.mp * 1e6 * 4 / 3) / 2)) * 2
        h = int(round(a.mp * 1e6 / w / 2)) * 2
    rows, once = run(h, w, with_torch=not a.quick)
    print(f"noise sampling, {h}x{w} ({h * w / 1e6:.1f} MP), median of 3, single-thread CPU time "
          f"(time.process_time) unless a row says wall clock, numpy {np.__version__}, {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.1f}\n")
    print("| sampler | MP/s | ratio |")
    print("|---|---:|---|")
    for name, mps, ratio in rows:
        print(f"| {name} | {mps:.1f} | {ratio} |")
    print("\none-time costs\n")
    print("| step | CPU s | wall s |")
    print("|---|---:|---:|")
    for name, cpu, wall in once:
        print(f"| {name} | {cpu:.3f} | {wall:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
