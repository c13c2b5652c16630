"""ONNX export: onnxruntime against torch eager, graph rules, golden vectors through ONNX.

References: the eager torch model (already proven against the TF golden vectors),
and ``golden.npz`` directly for the published weights.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")
onnx = pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

from flow_helpers import nhwc_latent_to_nchw, nhwc_released_to_nchw, published_onnx, published_onnx_legacy, small_flow, small_onnx  # noqa: E402,F401  (helpers, fixtures)

from simcam.noise.onnx_sampler import NoiseFlowRuntime  # noqa: E402


def _inputs(b, h, w, seed):
    rng = np.random.default_rng(seed)
    clean = rng.random((b, 4, h, w), dtype=np.float32)
    z = rng.standard_normal((b, 4, h, w)).astype(np.float32)
    return clean, z


@pytest.mark.parametrize("size", [(3, 16, 16), (2, 40, 24)])
def test_onnxruntime_matches_torch(small_flow, small_onnx, size):
    b, h, w = size
    clean, z = _inputs(b, h, w, seed=h)
    iso = np.array([100.0, 250.0, 1600.0][:b], dtype=np.float32)
    cam = np.array([0, 1, 1][:b], dtype=np.int64)
    sampler = NoiseFlowRuntime(small_onnx[0], threads=1)
    noise = sampler.sample(clean, z=z, iso=iso, camera=cam)
    ll = sampler.log_prob(noise, clean=clean, iso=iso, camera=cam)
    with torch.no_grad():
        args = dict(clean=torch.from_numpy(clean), iso=torch.from_numpy(iso), camera=torch.from_numpy(cam))
        ref = small_flow.sample(torch.from_numpy(z), **args).numpy()
        ll_ref = small_flow.log_prob(torch.from_numpy(noise), **args).numpy()
    assert noise.shape == clean.shape and noise.dtype == np.float32
    assert np.max(np.abs(noise - ref)) <= 1e-4 * np.max(np.abs(ref))
    assert ll.shape == (b,) and ll.dtype == np.float32
    # a sum of 4HW float32 terms: relative to max(|loglik|, D) as in the golden README
    assert np.all(np.abs(ll - ll_ref) <= 1e-4 * np.maximum(np.abs(ll_ref), clean[0].size))


def test_graph_rules_and_metadata(small_onnx):
    for path, role in zip(small_onnx, ("sampler", "loglik")):
        m = onnx.load(str(path))
        assert max(o.version for o in m.opset_import if o.domain in ("", "ai.onnx")) >= 17
        ops = {n.op_type for n in m.graph.node}
        forbidden = {"Inverse", "RandomNormal", "RandomNormalLike", "RandomUniform", "RandomUniformLike",
                     "Multinomial", "Bernoulli", "NonZero", "Compress", "Loop", "If"}
        assert not ops & forbidden, ops & forbidden
        meta = {p.key: p.value for p in m.metadata_props}
        assert meta["simcam_role"] == role
        assert meta["packing_order"] == "(0,0),(0,1),(1,0),(1,1)"
        assert json.loads(meta["cameras"]) == ["A", "B"]
        assert (float(meta["iso_min"]), float(meta["iso_max"])) == (100.0, 1600.0)
        assert float(meta["default_temperature"]) == 1.0
        assert meta["simcam_version"]
        dims = [[d.dim_param or d.dim_value for d in i.type.tensor_type.shape.dim] for i in m.graph.input]
        assert all(isinstance(d[0], str) for d in dims)  # dynamic batch
        assert all(isinstance(x, str) for d in dims if len(d) == 4 for x in (d[0], d[2], d[3]))


@pytest.mark.shared_data
def test_golden_vectors_through_onnx(published_onnx, published_onnx_legacy):
    """All 8 cases; case 7 (ISO 200, not one of the released five) needs the export made with
    --legacy-iso, which reproduces the released code's factor-1 fallback."""
    from shared_data import shared_path

    g = np.load(shared_path("noiseflow/golden.npz"))
    default = NoiseFlowRuntime(published_onnx[0], threads=1)
    legacy = NoiseFlowRuntime(published_onnx_legacy[0], threads=1)
    assert legacy.meta["iso_mode"] == "legacy-released" and default.meta["iso_mode"] == "log-interpolated"
    assert (~g["iso_supported"].astype(bool)).sum() == 1
    for k in range(8):
        sampler = default if g["iso_supported"][k] else legacy
        clean = nhwc_released_to_nchw(g["clean"][k])
        noise = nhwc_released_to_nchw(g["noise"][k])
        lat = nhwc_latent_to_nchw(g["latent"][k])
        kw = dict(iso=float(g["iso"][k]), camera=int(g["cam"][k]))
        x = sampler.sample(clean, z=lat, **kw)
        ref = nhwc_released_to_nchw(g["x_sample_eval"][k])
        assert np.max(np.abs(x - ref)) <= 1e-4 * np.max(np.abs(ref)), k
        ll = sampler.log_prob(noise, clean=clean, **kw)
        ref_ll = g["loglik_eval"][k]
        assert np.all(np.abs(ll - ref_ll) <= 5e-5 * np.maximum(np.abs(ref_ll), 4096)), k
