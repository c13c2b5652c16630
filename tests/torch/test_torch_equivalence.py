"""The torch samplers draw from the numpy models' laws, for every registered model and effect.

Independent reference: simcam's numpy samplers (``NoiseModel.sample``) on the same
clean frame, compared through statistics with tolerances from their standard errors:
per-pixel means (fixed patterns included: the torch composite must add the same
pattern), per-site variances, per-frame structure statistics (row / column
means, in-plane correlation, frame mean) and per-pixel two-sample KS tests.
"""

import numpy as np
import pytest
import torch
from scipy import stats

from torch_cases import EFFECT_CASES, EXPOSURE_S, MODEL_CASES, effect_entry
from simcam.noise import NoiseCondition, model_from_entry, model_types
from simcam.noise.effects import effect_types
from simcam.torch import EFFECTS, EFFECTS_NOT_SUPPORTED, NOT_SUPPORTED, SAMPLERS, add_noise, to_mosaic, to_packed

H, W, N = 32, 48, 400
COND = NoiseCondition(cfa="RGGB", exposure_s=EXPOSURE_S)


def _clean():
    y, x = np.mgrid[0:H, 0:W]
    return (0.02 + 0.53 * (x + W * y) / (H * W)).astype(np.float32)


def _numpy_frames(model, clean, n=N, seed=1):
    rng = np.random.default_rng(seed)
    return np.stack([model.sample(clean, COND, rng) for _ in range(n)]).astype(np.float64)


def _torch_frames(model, clean, layout, n=N, seed=2, device="cpu", dtype=torch.float32):
    c = torch.as_tensor(clean, device=device, dtype=dtype)[None, None].expand(n, 1, H, W).contiguous()
    if layout == "packed":
        c = to_packed(c)
    g = torch.Generator(device=device).manual_seed(seed)
    y = add_noise(c, model, generator=g, exposure_s=EXPOSURE_S)
    if layout == "packed":
        y = to_mosaic(y)
    return y[:, 0].double().cpu().numpy()


def _frame_stats(f):
    r = f - f.mean(axis=0)  # residual about each side's own per-pixel mean (fixed patterns removed)
    a, b = r[:, :, :-2].ravel(), r[:, :, 2:].ravel()

    def corr(lag):
        u, v = r[:, :, :-lag], r[:, :, lag:]
        return (u * v).mean(axis=(1, 2)) / np.sqrt((u * u).mean(axis=(1, 2)) * (v * v).mean(axis=(1, 2)))

    del a, b
    sites = {f"site_var_{dy}{dx}": (r[:, dy::2, dx::2] ** 2).mean(axis=(1, 2)) for dy in (0, 1) for dx in (0, 1)}
    return {**sites, "frame_mean": f.mean(axis=(1, 2)), "row_var": r.mean(axis=2).var(axis=1),
            "col_var": r.mean(axis=1).var(axis=1), "lag1_corr": corr(1), "lag2_corr": corr(2),
            "vlag2_corr": (r[:, :-2] * r[:, 2:]).mean(axis=(1, 2)) / (r * r).mean(axis=(1, 2))}


def assert_same_law(fn, ft):
    # 1. per-pixel means (the fixed pattern included)
    mn, mt = fn.mean(0), ft.mean(0)
    vn, vt = fn.var(0, ddof=1), ft.var(0, ddof=1)
    const = (vn + vt) == 0
    np.testing.assert_array_equal(mn[const], mt[const])  # stuck / dead pixels: identical constants
    z2 = (mt - mn)[~const] ** 2 / ((vn + vt)[~const] / fn.shape[0])
    se = z2.std() / np.sqrt(z2.size)
    assert abs(z2.mean() - 1.0) < 6 * se + 0.05, (z2.mean(), se)
    # 2. per-frame statistics (per-site variance, structure): Welch t-tests (frames are independent)
    sn, st = _frame_stats(fn), _frame_stats(ft)
    for k in sn:
        a, b = sn[k], st[k]
        se = np.sqrt(a.var(ddof=1) / a.size + b.var(ddof=1) / b.size)
        if se == 0:
            assert a.mean() == pytest.approx(b.mean(), abs=1e-12), k
            continue
        t = (a.mean() - b.mean()) / se
        assert abs(t) < 5.0, (k, a.mean(), b.mean(), t)
    # 3. per-pixel two-sample KS at one pixel per CFA site (frames are independent)
    for (r, c) in [(10, 20), (11, 31), (20, 7), (25, 41)]:
        if const[r, c]:
            continue
        p = stats.ks_2samp(fn[:, r, c], ft[:, r, c]).pvalue
        assert p > 1e-4, ((r, c), p)


def test_every_registered_model_has_a_torch_entry_or_a_reason():
    for t in model_types():
        if t in NOT_SUPPORTED:
            assert len(NOT_SUPPORTED[t]) > 20, t
            continue
        assert t in SAMPLERS, f"model type {t!r} has neither a torch sampler nor a NOT_SUPPORTED reason"
        assert t in MODEL_CASES, f"model type {t!r} has a torch sampler but no equivalence case"


def test_every_registered_effect_has_a_torch_entry_and_a_case():
    for t in effect_types():
        if t in EFFECTS_NOT_SUPPORTED:
            assert len(EFFECTS_NOT_SUPPORTED[t]) > 20, t
            continue
        assert t in EFFECTS, f"effect {t!r} has neither a torch implementation nor an EFFECTS_NOT_SUPPORTED reason"
        assert t in EFFECT_CASES, f"effect {t!r} has no equivalence case"


@pytest.mark.parametrize("layout", ["packed", "mosaic"])
@pytest.mark.parametrize("name", sorted(MODEL_CASES))
def test_model_law(name, layout):
    model = model_from_entry(MODEL_CASES[name])
    clean = _clean()
    assert_same_law(_numpy_frames(model, clean), _torch_frames(model, clean, layout))


@pytest.mark.parametrize("layout", ["packed", "mosaic"])
@pytest.mark.parametrize("name", sorted(EFFECT_CASES))
def test_effect_law(name, layout):
    model = model_from_entry(effect_entry(name))
    clean = _clean()
    assert_same_law(_numpy_frames(model, clean), _torch_frames(model, clean, layout))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("entry", [{"type": "nlf", "beta1": 2e-3, "beta2": 1e-5}, MODEL_CASES["poisson_gaussian"]],
                         ids=["nlf_scalar", "poisson_gaussian"])
def test_both_cpu_paths(entry, dtype):
    """float32 on the CPU takes simcam's compiled kernels (fused NLF, alias-table Poisson); float64 the torch
    operations (``torch.randn`` / ``torch.poisson``, as on CUDA): both draw from the numpy model's law."""
    model = model_from_entry(entry)
    clean = _clean()
    assert_same_law(_numpy_frames(model, clean), _torch_frames(model, clean, "packed", dtype=dtype))


def test_the_check_detects_a_different_fixed_pattern():
    """Power check of assert_same_law: another sensor_seed (another DSNU pattern) must fail it."""
    clean = _clean()
    a = model_from_entry(effect_entry("dsnu"))
    b = a.with_sensor_seed(12)
    with pytest.raises(AssertionError):
        assert_same_law(_numpy_frames(a, clean), _torch_frames(b, clean, "packed"))


def test_the_check_detects_swapped_cfa_sites():
    """Power check: the per-site parameters in another site order must fail it."""
    clean = _clean()
    e = dict(MODEL_CASES["nlf"])
    swapped = {**e, "beta1": e["beta1"][::-1], "beta2": e["beta2"][::-1]}
    with pytest.raises(AssertionError):
        assert_same_law(_numpy_frames(model_from_entry(e), clean),
                        _torch_frames(model_from_entry(swapped), clean, "packed"))


@pytest.mark.parametrize("name", ["nlf", "poisson_gaussian"])
def test_per_site_variance_is_the_nlf(name):
    """var(noisy) = beta1 * clean + beta2 per CFA site (closed form)."""
    e = MODEL_CASES[name]
    level, n = 0.3, 64
    c = torch.full((n, 4, 32, 32), level, dtype=torch.float64)
    y = add_noise(c, model_from_entry(e), generator=torch.Generator().manual_seed(3))
    var = (y - c).var(dim=(0, 2, 3)).numpy()
    ref = np.asarray(e["beta1"]) * level + np.asarray(e["beta2"])
    se = ref * np.sqrt(2.0 / (n * 32 * 32 - 1))  # Gaussian SE; the Poisson excess kurtosis is ~1e-2 here
    np.testing.assert_array_less(np.abs(var - ref), 5 * se * 1.1)


def _code_histogram_p(fn, ft, rng_dn, off_dn):
    cn = np.rint(fn * rng_dn + off_dn).astype(np.int64).ravel()
    ct = np.rint(ft * rng_dn + off_dn).astype(np.int64).ravel()
    np.testing.assert_allclose(ft * rng_dn + off_dn, np.rint(ft * rng_dn + off_dn), atol=1e-3)  # on the code grid
    lo = min(cn.min(), ct.min())
    hn, ht = np.bincount(cn - lo), np.bincount(ct - lo, minlength=0)
    n = max(hn.size, ht.size)
    table = np.stack([np.pad(hn, (0, n - hn.size)), np.pad(ht, (0, n - ht.size))])
    table = table[:, table.sum(0) >= 20]  # chi^2 needs populated cells
    return stats.chi2_contingency(table).pvalue


@pytest.mark.parametrize("name", ["quantization", "adc_dnl", "empirical_code"])
def test_code_effects_give_the_same_code_frequencies(name):
    """ADC effects: every torch value is a code, and the code histogram (which shows the code widths, DNL)
    matches numpy's (chi^2 two-sample test)."""
    m = model_from_entry(effect_entry(name))
    e = m.effects[-1]
    clean = _clean()
    p = _code_histogram_p(_numpy_frames(m, clean, n=200), _torch_frames(m, clean, "packed", n=200), e.range_dn,
                          e.offset_dn)
    assert p > 1e-4, p


def test_the_code_check_detects_missing_dnl():
    m = model_from_entry(effect_entry("adc_dnl"))
    e = m.effects[-1]
    plain = model_from_entry({**effect_entry("adc_dnl"), "effects": [
        {"type": "quantization", "range_dn": e.range_dn, "offset_dn": e.offset_dn}]})
    clean = _clean()
    p = _code_histogram_p(_numpy_frames(m, clean, n=200), _torch_frames(plain, clean, "packed", n=200), e.range_dn,
                          e.offset_dn)
    assert p < 1e-6, p
