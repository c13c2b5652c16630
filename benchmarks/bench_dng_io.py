"""DNG I/O and lens-shading timings against named baselines (same run, same machine).

Baselines:
* read_dng  vs rawpy ``raw_image`` copy alone (LibRaw decode, no tags);
* write_dng vs ``tifffile.imwrite`` of the same uint16 array (no DNG tags);
* lens_shading (vectorised) vs a per-pixel Python loop of the DNG SDK formula,
  timed on 2,000 pixels and scaled to the frame.

Usage: python benchmarks/bench_dng_io.py [path/to/gopro_hero7_iso252.dng]
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # this checkout's simcam, not an installed one

def median_time(fn, repeat=5):
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts)


def main() -> None:
    import rawpy
    import tifffile

    from simcam.frame import RawFrame
    from simcam.io.dng import read_dng
    from simcam.io.dng_write import write_dng
    from simcam.stages.lens_shading import LensShading

    src = Path(sys.argv[1] if len(sys.argv) > 1 else REPO.parent / "shared/data/dng/gopro_hero7_iso252.dng")
    if not src.exists():
        sys.exit(f"{src}: not found (pass a GainMap DNG)")

    def rawpy_only():
        with rawpy.imread(str(src)) as r:
            return r.raw_image.copy()

    t_read, t_base = median_time(lambda: read_dng(src)), median_time(rawpy_only)
    print(f"read_dng          {t_read * 1e3:8.1f} ms   rawpy raw_image {t_base * 1e3:8.1f} ms   ratio {t_read / t_base:5.2f}")

    frame = read_dng(src)
    with tempfile.TemporaryDirectory() as d:
        out, base = Path(d) / "o.dng", Path(d) / "o.tif"
        u16 = frame.data.astype(np.uint16)
        t_w = median_time(lambda: write_dng(out, frame))
        t_tf = median_time(lambda: tifffile.imwrite(base, u16))
        print(f"write_dng         {t_w * 1e3:8.1f} ms   tifffile.imwrite {t_tf * 1e3:7.1f} ms   ratio {t_w / t_tf:5.2f}")

    raw = RawFrame(np.full(frame.data.shape, 0.25, np.float32), frame.meta, kind="raw")
    stage = LensShading()
    t_ls = median_time(lambda: stage(raw), repeat=3)
    sys.path.insert(0, str(REPO / "tests" / "stages"))  # the independent per-pixel reference
    from test_lens_shading import reference_gain

    rng = np.random.default_rng(0)
    pts = rng.integers(0, frame.data.shape, size=(2000, 2))
    t = time.perf_counter()
    for r, c in pts:
        reference_gain(raw.meta, int(r), int(c))
    t_loop = (time.perf_counter() - t) / len(pts) * frame.data.size
    mp = frame.data.size / 1e6
    print(f"lens_shading      {t_ls * 1e3:8.1f} ms ({t_ls / mp * 1e3:.1f} ms/MP)   per-pixel loop (scaled) "
          f"{t_loop:8.1f} s   speed-up {t_loop / t_ls:7.0f}x")


if __name__ == "__main__":
    main()
