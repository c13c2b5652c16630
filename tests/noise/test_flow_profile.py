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
from simcam.noise.onnx_sampler import NoiseFlowRuntime  # noqa: E402

PROFILES = Path(__file__).resolve().parents[2] / "profiles"


@pytest.mark.parametrize("iso", [100.0, 400.0, 1600.0])
@pytest.mark.parametrize("level", [0.02, 0.3])
def test_default_flow_matches_nlf(iso, level):
    flow = NoiseFlowRuntime(PROFILES / "noiseflow_sidd_gp.onnx", threads=1)
    b1, b2 = read_nlf_table(PROFILES / "sidd_pixel_nlf.csv")[("GP", iso)]
    clean = np.full((2, 4, 64, 64), level, np.float32)
    noise = flow.sample(clean, iso=iso, camera="GP", rng=np.random.default_rng(int(iso) + int(100 * level)))
    n = noise.size  # 32768 values; var estimate sd = var * sqrt(2/n) = 0.8 %; allow 4 sd
    ratio = noise.astype(np.float64).var() / (b1 * level + b2)
    assert abs(ratio - 1.0) < 4 * np.sqrt(2.0 / n)
    assert abs(noise.mean()) < 4 * np.sqrt((b1 * level + b2) / n)


def test_default_flow_metadata_and_continuous_iso():
    flow = NoiseFlowRuntime(PROFILES / "noiseflow_sidd_gp.onnx", threads=1)
    assert flow.cameras == ["GP"] and flow.iso_range == (100.0, 1600.0)
    assert flow.meta["packing_order"] == "(0,0),(0,1),(1,0),(1,1)"
    clean = np.full((1, 4, 64, 64), 0.3, np.float32)
    v = [flow.sample(clean, iso=i, camera="GP", rng=np.random.default_rng(1)).var() for i in (400.0, 566.0, 800.0)]
    assert v[0] < v[1] < v[2]  # ISO 566 (between knots) lies between its neighbours


# ------------------------------------------------------------------ noiseflow_onnx
def test_profile_yaml_and_pipeline_noise_stage():
    """profiles/noiseflow-sidd-gp.yaml -> noise stage -> variance of the NLF at that ISO."""
    from simcam.frame import CameraMeta, RawFrame
    from simcam.pipeline import Pipeline
    from simcam.profiles.schema import load_profile

    prof = load_profile(PROFILES / "noiseflow-sidd-gp.yaml")
    assert prof.model_for(566.0, "GP").type == "noiseflow_onnx"
    pipe = Pipeline.from_dict({"version": 1, "input": "raw", "stages": [
        {"type": "noise", "profile": str(PROFILES / "noiseflow-sidd-gp.yaml"), "iso": 400.0, "camera": "GP"}]})
    clean = np.full((128, 128), 0.3, np.float32)
    frame = RawFrame(clean.copy(), CameraMeta(cfa="RGGB"), kind="raw")
    a, b = pipe(frame, seed=1), pipe(frame, seed=1)
    assert a.data.tobytes() == b.data.tobytes()
    b1, b2 = read_nlf_table(PROFILES / "sidd_pixel_nlf.csv")[("GP", 400.0)]
    noise = (a.data - clean).astype(np.float64)
    assert abs(noise.var() / (b1 * 0.3 + b2) - 1) < 4 * np.sqrt(2.0 / noise.size)  # 4 sd of a variance estimate


def test_noiseflow_onnx_tiles_exact_and_log_prob():
    from simcam.noise import NoiseCondition, model_from_entry

    m = model_from_entry({"type": "noiseflow_onnx", "path": "noiseflow_sidd_gp.onnx"})
    clean = np.random.default_rng(0).random((200, 64), dtype=np.float32) * 0.5
    cond = NoiseCondition(iso=800.0, cfa="RGGB")
    a = m.sample(clean, cond, np.random.default_rng(3))
    b = m.model_copy(update={"tile_rows": 64}).sample(clean, cond, np.random.default_rng(3))
    assert a.tobytes() == b.tobytes()  # 32-row halos make tiling exact
    from simcam.cfa import pack

    lp = m.log_prob(a, clean, cond)
    ref = m.flow().log_prob(pack(a - clean)[None], clean=pack(clean)[None], iso=800.0, camera="GP")[0]
    assert lp.shape == clean.shape and np.isclose(lp.sum(), ref, rtol=1e-9)


@pytest.mark.parametrize(
    "clean,cond,match",
    [
        (np.zeros((10, 9), np.float32), dict(iso=400.0), "expected even mosaic height and width"),
        (np.zeros((10, 8), np.float32), dict(), "needs the frame's ISO"),
        (np.zeros((10, 8), np.float32), dict(iso=3200.0), "3200 is outside the trained range 100..1600"),
        (np.zeros((10, 8), np.float32), dict(iso=400.0, camera="S6"), "camera: 'S6' is not one of"),
    ],
)
def test_noiseflow_onnx_bad_input(clean, cond, match):
    from simcam.errors import NoiseModelError
    from simcam.noise import NoiseCondition, model_from_entry

    m = model_from_entry({"type": "noiseflow_onnx", "path": "noiseflow_sidd_gp.onnx"})
    with pytest.raises(NoiseModelError, match=match):
        m.sample(clean, NoiseCondition(cfa="RGGB", **cond), np.random.default_rng(0))
    with pytest.raises(NoiseModelError, match="not found"):
        model_from_entry({"type": "noiseflow_onnx", "path": "missing.onnx"}).sample(
            np.zeros((4, 4), np.float32), NoiseCondition(iso=400.0), np.random.default_rng(0))
