"""Noise Flow layers: invertibility and log-determinants against a numerical Jacobian.

Reference: ``torch.autograd.functional.jacobian`` of the noise -> latent map in
float64 on tiny inputs, ``slogdet`` of that dense matrix (independent of the
layers' own closed-form log-determinants).
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from flow_helpers import randomise  # noqa: E402

from simcam.errors import NoiseModelError  # noqa: E402


def _flow(arch, per_iso=False):
    from simcam.noise.flow.model import FlowConfig, NoiseFlow

    cfg = FlowConfig(arch=arch, cameras=["A", "B"], iso_knots=[100.0, 400.0, 1600.0], sdn_per_iso=per_iso)
    flow = randomise(NoiseFlow(cfg, seed=3), seed=1).double().eval()
    g = torch.Generator().manual_seed(5)
    for m in flow.modules():  # non-trivial batch-norm statistics
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.copy_(0.1 * torch.randn(m.running_mean.shape, generator=g, dtype=torch.float64))
            m.running_var.copy_(0.5 + torch.rand(m.running_var.shape, generator=g, dtype=torch.float64))
    return flow


def _inputs(b=2, h=3, w=2, seed=0):
    g = torch.Generator().manual_seed(seed)
    clean = torch.rand(b, 4, h, w, generator=g, dtype=torch.float64)
    noise = 0.05 * torch.randn(b, 4, h, w, generator=g, dtype=torch.float64)
    return noise, clean


CONFIGS = [("published", False), ("paper", False), ("paper", True)]


@pytest.mark.parametrize("arch,per_iso", CONFIGS)
def test_composite_logdet_matches_numerical_jacobian(arch, per_iso):
    flow = _flow(arch, per_iso)
    noise, clean = _inputs(b=2)
    iso = torch.tensor([250.0, 1600.0], dtype=torch.float64)
    cam = torch.tensor([1, 0])
    with torch.no_grad():
        _, logdet = flow.to_latent(noise, clean=clean, iso=iso, camera=cam)
        # scale of the sum: per-layer log-determinants cancel (e.g. +240 - 238), so the
        # float64 rounding of both sides is relative to sum |layer logdet|, not to the total
        cond, h, scale = flow.condition(noise, clean, iso, cam), noise, torch.zeros(2, dtype=torch.float64)
        for layer in flow.layers:
            h, ld = layer.to_latent(h, cond)
            scale += ld.abs()
    for i in range(2):
        def f(x, i=i):
            return flow.to_latent(x[None], clean=clean[i : i + 1], iso=iso[i : i + 1], camera=cam[i : i + 1])[0][0]

        jac = torch.autograd.functional.jacobian(f, noise[i]).reshape(noise[i].numel(), -1)
        sign, ref = torch.linalg.slogdet(jac)
        assert abs(float(logdet[i]) - float(ref)) <= 1e-10 * max(1.0, float(scale[i]))


@pytest.mark.parametrize("arch,per_iso", CONFIGS)
def test_each_layer_logdet_and_inverse(arch, per_iso):
    flow = _flow(arch, per_iso)
    noise, clean = _inputs(b=1, h=2, w=3, seed=2)
    cond = flow.condition(noise, clean, 700.0, 1)
    for layer in flow.layers:
        def f(x, layer=layer):
            return layer.to_latent(x[None], cond)[0][0]

        jac = torch.autograd.functional.jacobian(f, noise[0]).reshape(noise.numel(), -1)
        _, ref = torch.linalg.slogdet(jac)
        with torch.no_grad():
            out, ld = layer.to_latent(noise, cond)
            back = layer.from_latent(out, cond)
        assert ld.shape == (1,)
        assert abs(float(ld[0]) - float(ref)) <= 1e-9 * max(1.0, abs(float(ref))), type(layer).__name__
        assert float((back - noise).abs().max()) <= 1e-12, type(layer).__name__


def test_round_trip_float64_and_frozen_inverse():
    flow = _flow("paper", True)
    noise, clean = _inputs(b=3, h=8, w=6, seed=4)
    with torch.no_grad():
        z, _ = flow.to_latent(noise, clean=clean, iso=400.0, camera="B")
        x = flow.sample(z, clean=clean, iso=400.0, camera="B")
        flow.freeze()
        x2 = flow.sample(z, clean=clean, iso=400.0, camera="B")
    assert float((x - noise).abs().max()) <= 1e-9 * float(noise.abs().max())
    assert float((x2 - x).abs().max()) <= 1e-12


def test_log_prob_is_change_of_variables():
    """log p(x) = log N(z; 0, I) + logdet, checked against scipy's normal log-pdf."""
    from scipy.stats import norm

    flow = _flow("paper")
    noise, clean = _inputs(b=2, h=4, w=4)
    with torch.no_grad():
        z, logdet = flow.to_latent(noise, clean=clean, iso=100.0, camera=0)
        ll = flow.log_prob(noise, clean=clean, iso=100.0, camera=0)
    ref = norm.logpdf(z.numpy()).reshape(2, -1).sum(1) + logdet.numpy()
    np.testing.assert_allclose(ll.numpy(), ref, rtol=1e-12)


def test_iso_weights_piecewise_linear_in_log_iso():
    from simcam.noise.flow.layers import iso_weights

    knots = torch.tensor([100.0, 400.0, 1600.0], dtype=torch.float64)
    iso = torch.tensor([100.0, 200.0, 400.0, 800.0, 1600.0, 1000.0], dtype=torch.float64)
    w = iso_weights(iso, knots).numpy()
    np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-12)
    expect_100_400 = np.interp(np.log(200.0), np.log([100.0, 400.0]), [1.0, 0.0])
    np.testing.assert_allclose(w[1], [expect_100_400, 1 - expect_100_400, 0.0], atol=1e-12)
    np.testing.assert_allclose(w[[0, 2, 4]], np.eye(3), atol=1e-12)
    t = (np.log(1000.0) - np.log(400.0)) / (np.log(1600.0) - np.log(400.0))
    np.testing.assert_allclose(w[5], [0.0, 1 - t, t], atol=1e-12)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(iso=50.0), "iso: 50 is outside the trained range 100..1600"),
        (dict(camera="Z"), "camera: 'Z' is not one of"),
        (dict(camera=7), "camera: index 7 outside"),
        (dict(iso=[100.0, 200.0, 300.0]), "iso: expected a scalar or 2 values"),
    ],
)
def test_bad_conditioning(kwargs, match):
    flow = _flow("paper")
    noise, clean = _inputs()
    args = dict(clean=clean, iso=400.0, camera=0) | kwargs
    with pytest.raises(NoiseModelError, match=match):
        flow.to_latent(noise, **args)


def test_bad_shapes():
    flow = _flow("paper")
    noise, clean = _inputs()
    with pytest.raises(NoiseModelError, match=r"noise: expected shape \(B, 4, H, W\)"):
        flow.to_latent(noise[:, :3], clean=clean, iso=400.0, camera=0)
    with pytest.raises(NoiseModelError, match="clean: shape"):
        flow.to_latent(noise, clean=clean[:, :, :2], iso=400.0, camera=0)
