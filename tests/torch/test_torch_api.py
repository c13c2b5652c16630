"""simcam.torch: log_prob against the numpy models, profiles per sample, randomness, gradients, errors, Noise Flow."""

from pathlib import Path

import numpy as np
import pytest
import torch

from torch_cases import MODEL_CASES, NLF4, PG4
from simcam.cfa import pack, unpack
from simcam.errors import NoiseModelError, SimcamError
from simcam.noise import NoiseCondition, model_from_entry
from simcam.profiles.schema import load_profile, profile_from_dict
from simcam.torch import AddNoise, add_noise, log_prob, to_mosaic, to_packed

ROOT = Path(__file__).resolve().parents[2]
COND = NoiseCondition(cfa="RGGB")

LOGPROB_CASES = {
    **{k: MODEL_CASES[k] for k in ("gaussian", "nlf", "poisson_gaussian", "poisson_mixture", "clipped")},
    "clipped_nlf": {"type": "clipped", "base": NLF4, "low": 0.0, "high": 0.5},
    "mixture_p1_0": {**MODEL_CASES["poisson_mixture"], "p1": 0.0},
    "composite": {"type": "composite", "base": PG4, "sensor_seed": 3, "effects": [
        {"type": "prnu", "sigma": 0.03}, {"type": "channel_gain", "gain": [1.1, 1.0, 0.95, 0.8]},
        {"type": "empirical_gain", "axis": "row", "quantiles": [0.95, 1.0, 1.05]},
        {"type": "nonlinearity", "strength": 0.2}, {"type": "dsnu", "sigma": 0.002},
        {"type": "column_fpn", "sigma": 0.002}, {"type": "black_level_offset", "offset": [0.01, 0.0, 0.005, 0.02]},
        {"type": "periodic_pattern", "amplitude": 0.003, "period_px": 6.0, "random_phase": False, "phase": 0.4}]},
}


def _clean(h=16, w=24, lo=0.0, hi=0.6):
    return np.linspace(lo, hi, h * w, dtype=np.float32).reshape(h, w)


@pytest.mark.parametrize("layout", ["packed", "mosaic"])
@pytest.mark.parametrize("name", sorted(LOGPROB_CASES))
def test_log_prob_equals_numpy(name, layout):
    model = model_from_entry(LOGPROB_CASES[name])
    rng = np.random.default_rng(4)
    clean = np.stack([_clean(), _clean(lo=0.05, hi=0.45)])
    noisy = np.stack([model.sample(c, COND, rng) for c in clean])
    ref = np.stack([model.log_prob(n, c, COND) for n, c in zip(noisy, clean)])
    if layout == "packed":
        got = unpack(log_prob(torch.as_tensor(pack(noisy)), torch.as_tensor(pack(clean)), model).numpy())
    else:
        got = log_prob(torch.as_tensor(noisy)[:, None], torch.as_tensor(clean)[:, None], model)[:, 0].numpy()
    assert got.dtype == np.float64
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-9)


def test_log_prob_refuses_an_intractable_composite():
    m = model_from_entry({"type": "composite", "base": PG4, "effects": [{"type": "row_noise", "sigma": 0.01}]})
    c = torch.full((1, 4, 4, 4), 0.2)
    with pytest.raises(NoiseModelError, match="row_noise"):
        log_prob(c, c, m)


def _two_iso_profile():
    return profile_from_dict({"schema_version": 1, "provenance": {"source": "test"}, "cameras": [{
        "id": "cam", "cfa": "RGGB", "entries": [
            {"iso": 100, "model": {"type": "nlf", "beta1": [1e-4, 2e-4, 2e-4, 3e-4], "beta2": 1e-6}},
            {"iso": 1600, "model": {"type": "nlf", "beta1": [1.6e-3, 3.2e-3, 3.2e-3, 4.8e-3], "beta2": 4e-5}}]}]},
        source="test.yaml")


def test_per_sample_iso_uses_each_samples_interpolated_model():
    prof = _two_iso_profile()
    isos = [100, 400, 1600, 283.0]
    n, level = 8, 0.4
    c = torch.full((len(isos) * n, 4, 32, 32), level, dtype=torch.float64)
    y = add_noise(c, prof, iso=np.repeat(isos, n), generator=torch.Generator().manual_seed(0))
    var = (y - c).reshape(len(isos), n, 4, -1).transpose(1, 2).reshape(len(isos), 4, -1).var(dim=2).numpy()
    m = n * 32 * 32
    for i, iso in enumerate(isos):
        ref = pack(prof.model_for(iso).variance(np.full((2, 2), level, np.float32), COND))[:, 0, 0]
        np.testing.assert_array_less(np.abs(var[i] - ref), 5 * ref * np.sqrt(2 / (m - 1)))


def test_a_loop_profile_with_different_effects_per_iso():
    """examples/data/loop_profile.yaml (written by simcam loop) has other effects at each ISO: each sample gets its
    ISO's model; the mean of noisy - clean is that model's black-level offset (DSNU, column FPN have mean ~0)."""
    prof = load_profile(ROOT / "examples/data/loop_profile.yaml")
    isos = [100, 3200, 800, 100]
    c = torch.full((4, 4, 64, 64), 0.2)
    y = add_noise(c, prof, iso=isos, generator=torch.Generator().manual_seed(1))
    d = (y - c).double()
    for i, iso in enumerate(isos):
        m = prof.model_for(iso)
        off = next(e for e in m.effects if e.type == "black_level_offset").offset
        sd = float(d[i].std())
        np.testing.assert_allclose(d[i].mean(dim=(1, 2)).numpy(), off, atol=6 * sd / 64 + 0.002)


def test_same_generator_state_same_bytes_and_new_state_new_noise():
    m = model_from_entry(MODEL_CASES["composite"])
    c = torch.rand((3, 4, 16, 16), generator=torch.Generator().manual_seed(9)) * 0.5
    a = add_noise(c, m, generator=torch.Generator().manual_seed(5))
    b = add_noise(c, m, generator=torch.Generator().manual_seed(5))
    d = add_noise(c, m, generator=torch.Generator().manual_seed(6))
    assert torch.equal(a, b) and not torch.equal(a, d)


@pytest.mark.parametrize("dtype", [torch.float64, torch.float16, torch.bfloat16])
def test_output_keeps_dtype_shape_and_layout(dtype):
    c = torch.full((2, 1, 8, 8), 0.25, dtype=dtype)
    for name in ("nlf", "poisson_gaussian", "composite"):
        y = add_noise(c, model_from_entry(MODEL_CASES[name]), generator=torch.Generator().manual_seed(0))
        assert y.dtype == dtype and y.shape == c.shape


def test_nlf_is_reparameterised_and_poisson_passes_no_gradient():
    m = model_from_entry({"type": "nlf", "beta1": 2e-3, "beta2": 1e-5})
    c = torch.full((2, 4, 8, 8), 0.3, dtype=torch.float64, requires_grad=True)
    y = add_noise(c, m, generator=torch.Generator().manual_seed(0))
    y.sum().backward()
    sd = torch.sqrt(2e-3 * c.detach() + 1e-5)
    z = (y.detach() - c.detach()) / sd
    torch.testing.assert_close(c.grad, 1 + 2e-3 * z / (2 * sd))  # d/dc [c + sqrt(b1 c + b2) z]
    c.grad = None
    y = add_noise(c, model_from_entry(PG4), generator=torch.Generator().manual_seed(0))
    assert not y.requires_grad  # the Poisson count has no gradient with respect to its rate


def test_exposure_scales_the_clean_signal():
    m = model_from_entry({"type": "gaussian", "sigma": 1e-4})
    c = torch.full((2, 4, 8, 8), 0.5, dtype=torch.float64)
    y = add_noise(c, m, exposure=[0.1, 1.0], generator=torch.Generator().manual_seed(0))
    assert y[0].mean().item() == pytest.approx(0.05, abs=1e-4) and y[1].mean().item() == pytest.approx(0.5, abs=1e-4)


def test_module_form_matches_the_function():
    prof = _two_iso_profile()
    mod = AddNoise(prof)
    c = torch.full((3, 4, 8, 8), 0.2)
    a = mod(c, iso=[100, 200, 800], generator=torch.Generator().manual_seed(2))
    b = add_noise(c, prof, iso=[100, 200, 800], generator=torch.Generator().manual_seed(2))
    assert torch.equal(a, b) and len(mod._memo) == 3


def test_layout_helpers_follow_simcam_cfa_pack():
    m = np.arange(4 * 6 * 8, dtype=np.float32).reshape(4, 1, 6, 8)
    np.testing.assert_array_equal(to_packed(torch.as_tensor(m)).numpy(), pack(m[:, 0]))
    np.testing.assert_array_equal(to_mosaic(torch.as_tensor(pack(m[:, 0]))).numpy(), m)


@pytest.mark.parametrize("bad, match", [
    (lambda: add_noise(torch.full((1, 3, 4, 4), 0.1), model_from_entry(NLF4)), "packed"),
    (lambda: add_noise(torch.full((1, 4, 4, 4), -0.1), model_from_entry(NLF4)), ">= 0"),
    (lambda: add_noise(torch.full((1, 4, 4, 4), 0.1), _two_iso_profile()), "ISO"),
    (lambda: add_noise(torch.full((1, 4, 4, 4), 0.1), _two_iso_profile(), iso=[100, 200]), "iso"),
    (lambda: add_noise(torch.full((1, 4, 4, 4), 0.1), {"type": "noiseflow_onnx", "path": "x.onnx"}), "ONNX"),
    (lambda: add_noise(torch.full((1, 4, 4, 4), 0.1), object()), "profile_or_model"),
])
def test_errors_are_simcam_errors_naming_the_field(bad, match):
    with pytest.raises(SimcamError, match=match):
        bad()


def test_noise_flow_runs_on_the_batch_device_with_the_given_generator():
    from simcam.noise.flow import FlowConfig, NoiseFlow

    flow = NoiseFlow(FlowConfig(cameras=["A"], iso_knots=[100.0, 800.0], steps=1), seed=0).double().eval()
    c = torch.full((2, 4, 8, 8), 0.2, dtype=torch.float64)
    with torch.no_grad():
        y = add_noise(c, flow, iso=[100, 400], generator=torch.Generator().manual_seed(3))
        z = torch.randn(c.shape, generator=torch.Generator().manual_seed(3), dtype=c.dtype)
        ref = flow.sample(z, clean=c, iso=torch.tensor([100.0, 400.0]), camera="A")
        torch.testing.assert_close(y - c, ref)
        ym = add_noise(to_mosaic(c), flow, iso=[100, 400], generator=torch.Generator().manual_seed(3))
        torch.testing.assert_close(to_packed(ym), y)


cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device (torch.cuda.is_available() is False)")


@cuda
def test_cuda_same_generator_state_same_tensor_and_same_law():
    from test_torch_equivalence import _clean as frame, _numpy_frames, _torch_frames, assert_same_law

    for name in ("nlf", "poisson_gaussian", "composite"):
        m = model_from_entry(MODEL_CASES[name])
        c = torch.full((2, 4, 16, 16), 0.3, device="cuda")
        a = add_noise(c, m, generator=torch.Generator(device="cuda").manual_seed(1))
        b = add_noise(c, m, generator=torch.Generator(device="cuda").manual_seed(1))
        assert a.device.type == "cuda" and torch.equal(a, b)
        assert_same_law(_numpy_frames(m, frame()), _torch_frames(m, frame(), "packed", device="cuda"))


@cuda
def test_cuda_consecutive_poisson_draws_are_independent():
    """Two Poisson draws in a row from one batch generator (shot noise, then dark charge), then normals: on
    CUDA each Poisson call has a generator of its own (torch 2.11's kernel gave +0.34 correlation between
    consecutive calls on one generator). 1e6 pairs: SE of a correlation 0.001."""
    from simcam.torch.context import Ctx

    g = torch.Generator(device="cuda").manual_seed(5)
    ctx = Ctx(torch.device("cuda"), torch.float64, "packed", (1000, 1000), g)
    lam = torch.full((1000, 1000), 30.0, device="cuda", dtype=torch.float64)
    a, b = ctx.poisson(lam), ctx.poisson(lam)
    z = ctx.randn((1000, 1000))
    for x, y in ((a, b), (b, z)):
        x, y = x - x.mean(), y - y.mean()
        assert abs(float((x * y).mean() / (x.std() * y.std()))) < 0.005
    assert float(a.var() / 30.0) == pytest.approx(1.0, abs=0.005)


@cuda
def test_cuda_generator_on_the_wrong_device_is_refused():
    with pytest.raises(NoiseModelError, match="generator"):
        add_noise(torch.full((1, 4, 4, 4), 0.1, device="cuda"), model_from_entry(NLF4),
                  generator=torch.Generator().manual_seed(0))


@pytest.mark.parametrize("layout", ["packed", "mosaic"])
def test_crops_of_a_full_frame_get_that_frames_fixed_patterns(layout):
    """With frame_shape and offsets, each patch gets the crop of the full frame's fixed pattern: with no temporal
    noise (gaussian sigma 0) the torch patch equals the same crop of the numpy full-frame sample, exactly."""
    m = model_from_entry({"type": "composite", "base": {"type": "gaussian", "sigma": 0.0}, "sensor_seed": 4,
                          "effects": [{"type": "prnu", "sigma": 0.05}, {"type": "column_fpn", "sigma": 0.01},
                                      {"type": "dsnu", "sigma": 0.01},
                                      {"type": "periodic_pattern", "amplitude": 0.01, "period_px": 5.0,
                                       "random_phase": False, "phase": 0.3},
                                      {"type": "hot_pixels", "hot_fraction": 0.05, "stuck_fraction": 0.02}]})
    fh, fw = 40, 64
    full = _clean(fh, fw, 0.1, 0.7)
    ref = m.sample(full, COND, np.random.default_rng(0))
    offs = [(0, 0), (8, 20), (24, 48)]
    crops = np.stack([full[y:y + 16, x:x + 16] for y, x in offs])
    c = torch.as_tensor(crops)[:, None]
    if layout == "packed":
        c = to_packed(c)
    y = add_noise(c, m, frame_shape=(fh, fw), offsets=offs, generator=torch.Generator().manual_seed(0))
    if layout == "packed":
        y = to_mosaic(y)
    want = np.stack([ref[oy:oy + 16, ox:ox + 16] for oy, ox in offs])
    np.testing.assert_allclose(y[:, 0].numpy(), want, rtol=0, atol=2e-7)


def test_offsets_must_be_even_and_inside_the_frame():
    m = model_from_entry(MODEL_CASES["composite"])
    c = torch.full((2, 1, 8, 8), 0.1)
    for offs in ([(1, 0), (0, 0)], [(0, 0), (0, 60)]):
        with pytest.raises(NoiseModelError, match="offsets"):
            add_noise(c, m, frame_shape=(16, 64), offsets=offs)


def test_a_list_of_models_mixes_types_in_one_batch():
    """Samples with models of different structure are noised group by group, each with its own law."""
    models = [model_from_entry({"type": "gaussian", "sigma": 0.01}), model_from_entry({"type": "gaussian", "sigma": 0.05}),
              model_from_entry({"type": "nlf", "beta1": 0.0, "beta2": 4e-4})]
    c = torch.full((3, 4, 64, 64), 0.3, dtype=torch.float64)
    y = add_noise(c, models, generator=torch.Generator().manual_seed(0))
    sd = (y - c).flatten(1).std(dim=1).numpy()
    np.testing.assert_allclose(sd, [0.01, 0.05, 0.02], rtol=5 * np.sqrt(1 / (2 * 4 * 64 * 64)))


def test_measured_maps_of_a_profile_are_applied_and_cropped(tmp_path):
    """Empirical effects carrying measured maps (FILE.npz#KEY): the torch composite adds the map itself, and with
    frame_shape/offsets each patch gets its crop of it."""
    rng = np.random.default_rng(0)
    offset = rng.normal(0, 0.01, (40, 64)).astype(np.float32)
    gain = (1 + rng.normal(0, 0.05, 64)).astype(np.float32)
    np.savez(tmp_path / "maps.npz", dsnu=offset, col_gain=gain)
    m = model_from_entry({"type": "composite", "base": {"type": "gaussian", "sigma": 0.0}, "effects": [
        {"type": "empirical_gain", "axis": "column", "map": f"{tmp_path}/maps.npz#col_gain"},
        {"type": "empirical_offset", "axis": "pixel", "map": f"{tmp_path}/maps.npz#dsnu"}]})
    full = _clean(40, 64, 0.1, 0.7)
    offs = [(0, 0), (8, 20), (24, 48)]
    c = torch.as_tensor(np.stack([full[y:y + 16, x:x + 16] for y, x in offs]))[:, None]
    y = add_noise(c, m, frame_shape=(40, 64), offsets=offs, generator=torch.Generator().manual_seed(0))
    want = np.stack([(full * gain[None, :] + offset)[oy:oy + 16, ox:ox + 16] for oy, ox in offs])
    np.testing.assert_allclose(y[:, 0].numpy(), want, rtol=0, atol=2e-7)


def test_exposure_dependent_effects_need_exposure_s():
    m = model_from_entry({"type": "composite", "base": PG4, "effects": [
        {"type": "dark_current", "rate": 10.0, "electron": 1e-3}]})
    with pytest.raises(NoiseModelError, match="exposure_s"):
        add_noise(torch.full((1, 4, 4, 4), 0.1), m)
