"""Colour/display stages throughput vs colour-science on the same data.

Prints median seconds per megapixel (5 runs) of simcam's camera_to_xyz + xyz_to_srgb +
gamma(srgb) chain and of the colour-science baseline computing the same thing
(``colour.XYZ_to_RGB`` with Bradford from D50 plus ``colour.cctf_encoding``) on a
camera-RGB image, and their ratio. Usage: ``python benchmarks/bench_colour_stages.py [--mp 4]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this checkout's simcam


def median_time(fn, runs: int = 5) -> float:
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main() -> None:
    import colour

    from simcam.frame import CameraMeta, RawFrame
    from simcam.stages.camera_to_xyz import CameraToXYZ
    from simcam.stages.gamma import Gamma
    from simcam.stages.xyz_to_srgb import XYZToSRGB

    ap = argparse.ArgumentParser()
    ap.add_argument("--mp", type=float, default=4.0, help="image size in megapixels")
    args = ap.parse_args()
    side = int(np.sqrt(args.mp * 1e6))
    rgb = np.random.default_rng(0).uniform(0, 1, (side, side, 3)).astype(np.float32)
    meta = CameraMeta(cfa="RGGB", color_matrix1=np.array([[0.6461, -0.1164, -0.0857], [-0.3825, 1.1597, 0.2534],
                                                          [-0.0416, 0.1540, 0.6039]]),
                      as_shot_neutral=np.array([0.5, 1.0, 0.7]), source="bench")
    frame = RawFrame(rgb, meta, "camera_rgb")
    stages = [CameraToXYZ(), XYZToSRGB(), Gamma()]

    def ours():
        f = frame
        for s in stages:
            f = s(f)
        return f.data

    m = CameraToXYZ().matrix(meta)

    def baseline():
        xyz = np.einsum("ij,hwj->hwi", m, rgb)
        lin = colour.XYZ_to_RGB(xyz, "sRGB", illuminant=np.array([0.3457, 0.3585]),
                                chromatic_adaptation_transform="Bradford")
        return colour.cctf_encoding(lin, function="sRGB")

    mp = side * side / 1e6
    t_ours, t_base = median_time(ours), median_time(baseline)
    err = float(np.abs(ours() - baseline()).max())
    print(f"image {side}x{side} ({mp:.1f} MP), median of 5 runs")
    print(f"simcam camera_to_xyz+xyz_to_srgb+gamma : {t_ours / mp:.4f} s/MP")
    print(f"colour-science (float64) baseline      : {t_base / mp:.4f} s/MP")
    print(f"speed-up vs baseline: {t_base / t_ours:.2f}x   max |difference|: {err:.2e}")


if __name__ == "__main__":
    main()
