"""The shipped default flow (profiles/noiseflow_sidd_gp.onnx) reproduces the SIDD GP NLF.

Reference: the measured NLF numbers in profiles/sidd_pixel_nlf.csv (the flow was trained
on pairs synthesised from them); sample variance on flat clean patches against
beta1 * clean + beta2, tolerance from the standard error of a variance estimate.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")

from simcam.noise.flow.data import read_nlf_table  # noqa: E402
from simcam.noise.onnx_sampler import OnnxNoiseFlow  # noqa: E402

PROFILES = Path(__file__).resolve().parents[2] / "profiles"


@pytest.mark.parametrize("iso", [100.0, 400.0, 1600.0])
@pytest.mark.parametrize("level", [0.02, 0.3])
def test_default_flow_matches_nlf(iso, level):
    flow = OnnxNoiseFlow(PROFILES / "noiseflow_sidd_gp.onnx", threads=1)
    b1, b2 = read_nlf_table(PROFILES / "sidd_pixel_nlf.csv")[("GP", iso)]
    clean = np.full((2, 4, 64, 64), level, np.float32)
    noise = flow.sample(clean, iso=iso, camera="GP", rng=np.random.default_rng(int(iso) + int(100 * level)))
    n = noise.size  # 32768 values; var estimate sd = var * sqrt(2/n) = 0.8 %; allow 4 sd
    ratio = noise.astype(np.float64).var() / (b1 * level + b2)
    assert abs(ratio - 1.0) < 4 * np.sqrt(2.0 / n)
    assert abs(noise.mean()) < 4 * np.sqrt((b1 * level + b2) / n)


def test_default_flow_metadata_and_continuous_iso():
    flow = OnnxNoiseFlow(PROFILES / "noiseflow_sidd_gp.onnx", threads=1)
    assert flow.cameras == ["GP"] and flow.iso_range == (100.0, 1600.0)
    assert flow.meta["packing_order"] == "(0,0),(0,1),(1,0),(1,1)"
    clean = np.full((1, 4, 64, 64), 0.3, np.float32)
    v = [flow.sample(clean, iso=i, camera="GP", rng=np.random.default_rng(1)).var() for i in (400.0, 566.0, 800.0)]
    assert v[0] < v[1] < v[2]  # ISO 566 (between knots) lies between its neighbours
