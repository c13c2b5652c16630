"""simcam.noise.onnx_sampler: runs without torch and rejects bad input with one clear line."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")

from simcam.errors import NoiseModelError  # noqa: E402
from simcam.noise.onnx_sampler import NoiseFlowRuntime  # noqa: E402
from flow_helpers import small_onnx  # noqa: E402,F401  (fixtures)

REPO = Path(__file__).resolve().parents[2]


def test_runs_with_torch_absent(small_onnx, tmp_path):
    """Import and sample in a fresh interpreter where ``import torch`` fails."""
    out = tmp_path / "noise.npy"
    code = f"""
import sys
sys.modules['torch'] = None
import numpy as np
from simcam.noise.onnx_sampler import NoiseFlowRuntime
s = NoiseFlowRuntime({str(small_onnx[0])!r}, threads=1)
rng = np.random.default_rng(0)
clean = rng.random((1, 4, 8, 8), dtype=np.float32)
x = s.sample(clean, iso=300.0, camera='B', rng=rng)
ll = s.log_prob(x, clean=clean, iso=300.0, camera='B')
import simcam.cli, simcam.noise.flow, simcam.noise.flow.data, simcam.noise.metrics  # torch-free modules
assert 'torch' not in [m for m in sys.modules if sys.modules[m] is not None]
from simcam.errors import OptionalDependencyError
try:
    import simcam.noise.flow.model
    raise SystemExit('importing the torch model without torch must fail clearly')
except OptionalDependencyError as exc:
    assert "pip install 'simcam[torch]'" in str(exc), exc
np.save({str(out)!r}, x)
"""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    res = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    x = np.load(out)
    assert x.shape == (1, 4, 8, 8) and np.all(np.isfinite(x))


def test_same_seed_same_bytes(small_onnx):
    s = NoiseFlowRuntime(small_onnx[0], threads=1)
    clean = np.full((2, 4, 6, 6), 0.3, np.float32)
    a = s.sample(clean, iso=400.0, camera="A", rng=np.random.default_rng(5))
    b = s.sample(clean, iso=400.0, camera="A", rng=np.random.default_rng(5))
    assert a.tobytes() == b.tobytes()


def test_sample_mosaic_round_trips_packing(small_onnx):
    from simcam.cfa import pack

    s = NoiseFlowRuntime(small_onnx[0], threads=1)
    rng = np.random.default_rng(1)
    mosaic = rng.random((12, 10), dtype=np.float32)
    noise = s.sample_mosaic(mosaic, iso=100.0, camera=0, rng=np.random.default_rng(2))
    z = np.random.default_rng(2).standard_normal((1, 4, 6, 5)).astype(np.float32)
    ref = s.sample(pack(mosaic)[None], z=z, iso=100.0, camera=0)[0]
    assert noise.shape == (12, 10)
    np.testing.assert_array_equal(pack(noise), ref)


CLEAN = np.full((2, 4, 8, 8), 0.2, np.float32)


@pytest.mark.parametrize(
    "call,match",
    [
        (lambda s: s.sample(CLEAN, iso=3200.0, camera=0, rng=np.random.default_rng()),
         r"model.onnx: iso: 3200 is outside the trained range 100..1600"),
        (lambda s: s.sample(CLEAN, iso=99.0, camera=0, rng=np.random.default_rng()), "outside the trained range"),
        (lambda s: s.sample(CLEAN, iso=400.0, camera="Pixel", rng=np.random.default_rng()),
         r"camera: 'Pixel' is not one of \['A', 'B'\]"),
        (lambda s: s.sample(CLEAN, iso=400.0, camera=2, rng=np.random.default_rng()), r"camera: index 2 outside 0..1"),
        (lambda s: s.sample(CLEAN.astype(np.float64), iso=400.0, camera=0, rng=np.random.default_rng()),
         "clean: expected dtype float32, got float64"),
        (lambda s: s.sample(CLEAN[:, :3], iso=400.0, camera=0, rng=np.random.default_rng()),
         r"clean: expected shape \(B, 4, H, W\)"),
        (lambda s: s.sample(CLEAN, z=CLEAN[:, :, :4], iso=400.0, camera=0), "z: shape"),
        (lambda s: s.sample(CLEAN, iso=400.0, camera=0), "give either z or rng"),
        (lambda s: s.sample_mosaic(np.zeros((11, 8), np.float32), iso=400.0, camera=0, rng=np.random.default_rng()),
         "mosaic height and width must be even, got 11x8"),
        (lambda s: s.log_prob(CLEAN, clean=CLEAN, iso=[100.0, 5000.0], camera=0), "5000 is outside"),
    ],
)
def test_bad_input_one_line(small_onnx, call, match):
    s = NoiseFlowRuntime(small_onnx[0], threads=1)
    with pytest.raises(NoiseModelError, match=match) as info:
        call(s)
    assert "\n" not in str(info.value)


def test_onnx_without_simcam_metadata(tmp_path):
    import onnx
    from onnx import TensorProto, helper

    x = helper.make_tensor_value_info("x", TensorProto.FLOAT, [1])
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, [1])
    graph = helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "g", [x], [y])
    path = tmp_path / "plain.onnx"
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=8), str(path))
    with pytest.raises(NoiseModelError, match=r"plain.onnx: metadata_props: missing 'simcam_format'"):
        NoiseFlowRuntime(path)


def test_missing_and_garbage_files(tmp_path):
    with pytest.raises(NoiseModelError, match="ONNX file not found"):
        NoiseFlowRuntime(tmp_path / "nope.onnx")
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"not a model")
    with pytest.raises(NoiseModelError, match="bad.onnx: not a loadable ONNX model"):
        NoiseFlowRuntime(bad)


def test_loglik_file_must_be_the_likelihood_graph(small_onnx, tmp_path):
    import shutil

    shutil.copy(small_onnx[0], tmp_path / "m.onnx")
    shutil.copy(small_onnx[0], tmp_path / "m.loglik.onnx")  # wrong graph under the loglik name
    s = NoiseFlowRuntime(tmp_path / "m.onnx")
    with pytest.raises(NoiseModelError, match="simcam_role: 'sampler', expected 'loglik'"):
        s.log_prob(CLEAN, clean=CLEAN, iso=400.0, camera=0)
