"""The simcam Noise Flow with the released weights equals the original TF graph.

Reference: ``golden.npz`` (inputs and outputs of the authors' TF graph, float32)
from ../shared/data/noiseflow; tolerances from its README: z and samples within
1e-4 of the largest |value|, log-likelihood within 5e-5 of max(|loglik|, 4096).
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from flow_helpers import nhwc_latent_to_nchw, nhwc_released_to_nchw, published_flow  # noqa: E402,F401  (helpers, fixtures)
from shared_data import shared_path  # noqa: E402

pytestmark = pytest.mark.shared_data


@pytest.fixture(scope="module")
def golden():
    return dict(np.load(shared_path("noiseflow/golden.npz")))


@pytest.fixture(scope="module")
def weights():
    return shared_path("noiseflow/noiseflow_weights.npz")


def _load(weights, **kw):
    from simcam.noise.flow.published import load_published

    return load_published(weights, **kw)


def _case(golden, k):
    t = torch.from_numpy
    return dict(
        noise=t(nhwc_released_to_nchw(golden["noise"][k])),
        clean=t(nhwc_released_to_nchw(golden["clean"][k])),
        latent=t(nhwc_latent_to_nchw(golden["latent"][k])),
        iso=float(golden["iso"][k]),
        camera=int(golden["cam"][k]),
    )


def _rel(a, ref):
    return float(np.max(np.abs(np.asarray(a) - ref)) / np.max(np.abs(ref)))


@pytest.mark.parametrize("mode", ["eval", "train"])
@pytest.mark.parametrize("k", range(8))
def test_golden_vectors(golden, weights, published_flow, k, mode):
    # case 7 (ISO 200) documents the released code's silent factor exp(0): reproduce it
    # with legacy_iso; every other case runs with the default (log-ISO interpolation).
    legacy = not bool(golden["iso_supported"][k])
    flow = _load(weights, legacy_iso=True) if legacy else copy.deepcopy(published_flow)
    if mode == "train":  # batch norm with the statistics of the 2-patch batch
        flow.train()
    c = _case(golden, k)
    with torch.no_grad():
        z, logdet = flow.to_latent(c["noise"], clean=c["clean"], iso=c["iso"], camera=c["camera"])
        loglik = flow.log_prob(c["noise"], clean=c["clean"], iso=c["iso"], camera=c["camera"])
        x = flow.sample(c["latent"], clean=c["clean"], iso=c["iso"], camera=c["camera"])
    assert logdet.shape == (2,)
    assert _rel(z, nhwc_latent_to_nchw(golden[f"z_{mode}"][k])) <= 1e-4
    assert _rel(x, nhwc_released_to_nchw(golden[f"x_sample_{mode}"][k])) <= 1e-4
    ref = golden[f"loglik_{mode}"][k]
    assert np.all(np.abs(loglik.numpy() - ref) <= 5e-5 * np.maximum(np.abs(ref), 4096))
    np.testing.assert_allclose(logdet.numpy(), golden[f"logdet_{mode}"][k], rtol=0, atol=5e-5 * 4096 * 4)


def test_released_wrapper_bug_is_not_reproduced(golden, published_flow):
    """The authors' sampler (reversed networks) differs from ours by far more than the tolerance."""
    flow = copy.deepcopy(published_flow).train()
    c = _case(golden, 0)
    with torch.no_grad():
        x = flow.sample(c["latent"], clean=c["clean"], iso=c["iso"], camera=c["camera"])
    bug = nhwc_released_to_nchw(golden["released_wrapper_x_sample_train"][0])
    assert _rel(x, bug) > 1e-2


def test_iso_interpolation_between_knots(golden, weights, published_flow):
    """ISO 200 interpolates in log-ISO; legacy mode falls back to factor 1 (a different model)."""
    c = _case(golden, 7)
    interp, legacy = published_flow, _load(weights, legacy_iso=True)
    with torch.no_grad():
        ll = {iso: interp.log_prob(c["noise"], clean=c["clean"], iso=iso, camera=0) for iso in (100.0, 200.0, 400.0)}
        ll_legacy = legacy.log_prob(c["noise"], clean=c["clean"], iso=200.0, camera=0)
    # the per-ISO gain parameter at ISO 200 lies between its ISO-100 and ISO-400 values
    sdn = interp.layers[0]
    from simcam.noise.flow.layers import iso_weights

    w = iso_weights(torch.tensor([200.0]), interp.iso_knots)
    g200 = float(w @ sdn.gain_params.detach())
    g = sdn.gain_params.detach().numpy()
    assert min(g[0], g[1]) < g200 < max(g[0], g[1])
    assert np.isclose(g200, g[0] + 0.5 * (g[1] - g[0]), rtol=1e-6)  # log 200 is halfway in log
    assert np.all(np.isfinite(ll[200.0].numpy()))
    assert not np.allclose(ll[200.0].numpy(), ll_legacy.numpy(), rtol=1e-3)


def test_float64_round_trip(golden, weights):
    flow = _load(weights, dtype=torch.float64)
    c = _case(golden, 1)
    lat = c["latent"].double()
    with torch.no_grad():
        x = flow.sample(lat, clean=c["clean"].double(), iso=c["iso"], camera=c["camera"])
        z, _ = flow.to_latent(x, clean=c["clean"].double(), iso=c["iso"], camera=c["camera"])
    assert float((z - lat).abs().max()) <= 1e-9


def test_iso_outside_range_refused(published_flow):
    from simcam.errors import NoiseModelError

    flow = published_flow
    x = torch.zeros(1, 4, 4, 4)
    with pytest.raises(NoiseModelError, match="outside the trained range 100..3200"):
        flow.to_latent(x, clean=x, iso=6400.0, camera=0)


def test_published_logdet_matches_numerical_jacobian(golden, published_flow):
    """log-determinant of the released model against slogdet of its float64 Jacobian (3x3 patch)."""
    flow = copy.deepcopy(published_flow).double()
    c = _case(golden, 4)
    noise, clean = c["noise"][:1, :, :3, :3].double(), c["clean"][:1, :, :3, :3].double()
    kw = dict(clean=clean, iso=c["iso"], camera=c["camera"])
    with torch.no_grad():
        _, logdet = flow.to_latent(noise, **kw)
    jac = torch.autograd.functional.jacobian(lambda x: flow.to_latent(x[None], **kw)[0][0], noise[0])
    _, ref = torch.linalg.slogdet(jac.reshape(36, 36))
    assert abs(float(logdet[0]) - float(ref)) <= 1e-9 * abs(float(ref))
