"""Write SIDD-format benchmark blocks from the hidden-effect sensor (for ``simcam bench`` demos).

Same sensor and held-out scenes as ``table63_cpu.py``: N images x M blocks of
256x256, noisy (one frame) and ground truth (mean of 32 frames), as
``[N, M, 256, 256]`` float32 in MATLAB v7.3 (noisy) and v5 (ground truth) files.

Usage: python experiments/make_bench_blocks.py OUT_DIR [--images 4] [--blocks 2]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from table63_cpu import SENSOR, TEST_DNGS, capture, scenes  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--images", type=int, default=4)
    ap.add_argument("--blocks", type=int, default=2)
    args = ap.parse_args()
    from loop_generator import HiddenEffectSensor, SensorSpec

    from simcam.io.sidd_blocks import write_blocks

    rng = np.random.default_rng(7)
    spec = SensorSpec(**SENSOR)
    sensor = HiddenEffectSensor(spec)
    pairs = [capture(sensor, spec, s, 1, 32, rng) for s in scenes(TEST_DNGS, args.images * args.blocks, rng)]
    noisy = np.stack([f[0] for f, _ in pairs]).reshape(args.images, args.blocks, 256, 256)
    gt = np.stack([g for _, g in pairs]).reshape(args.images, args.blocks, 256, 256)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_blocks(out / "NoisyBlocksRaw.mat", noisy, "ValidationNoisyBlocksRaw", format="v7.3")
    write_blocks(out / "GtBlocksRaw.mat", gt, "ValidationGtBlocksRaw", format="v5")
    print(f"wrote {out}/NoisyBlocksRaw.mat (v7.3) and GtBlocksRaw.mat (v5), shape {noisy.shape}")


if __name__ == "__main__":
    main()
