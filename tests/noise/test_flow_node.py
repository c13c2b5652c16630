"""examples/node: onnxruntime-node output equals Python onnxruntime's within 1e-5."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from flow_helpers import small_onnx  # noqa: E402,F401  (fixtures)

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "node"


def _node_ready():
    if shutil.which("node") is None:
        return "node is not on PATH"
    if not (EXAMPLE / "node_modules" / "onnxruntime-node").is_dir():
        return f"onnxruntime-node not installed: run `npm install` in {EXAMPLE} (see its README)"
    return None


def test_node_matches_python(small_onnx, tmp_path):
    why = _node_ready()
    if why:
        pytest.skip(why)
    from simcam.noise.onnx_sampler import NoiseFlowRuntime

    rng = np.random.default_rng(11)
    clean = rng.random((2, 4, 12, 10), dtype=np.float32)
    z = rng.standard_normal(clean.shape).astype(np.float32)
    np.save(tmp_path / "clean.npy", clean)
    np.save(tmp_path / "z.npy", z)
    res = subprocess.run(
        ["node", str(EXAMPLE / "sample.js"), str(small_onnx[0]), str(tmp_path / "clean.npy"), str(tmp_path / "z.npy"),
         "640", "1", str(tmp_path / "noise.npy")],
        capture_output=True, text=True, timeout=120,
    )
    assert res.returncode == 0, res.stderr
    node = np.load(tmp_path / "noise.npy")
    py = NoiseFlowRuntime(small_onnx[0], threads=1).sample(clean, z=z, iso=640.0, camera=1)
    assert node.shape == py.shape and node.dtype == np.float32
    assert np.max(np.abs(node - py)) <= 1e-5 * float(np.max(np.abs(py)))


def test_node_reports_bad_input_in_one_line(small_onnx, tmp_path):
    why = _node_ready()
    if why:
        pytest.skip(why)
    np.save(tmp_path / "clean.npy", np.zeros((1, 4, 4, 4), np.float64))
    res = subprocess.run(
        ["node", str(EXAMPLE / "sample.js"), str(small_onnx[0]), str(tmp_path / "clean.npy"), str(tmp_path / "clean.npy"),
         "400", "0", str(tmp_path / "o.npy")],
        capture_output=True, text=True, timeout=60,
    )
    assert res.returncode == 2
    assert "dtype: expected '<f4'" in res.stderr and res.stderr.count("\n") == 1
