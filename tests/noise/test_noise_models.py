"""Noise models: per-intensity moments vs theory, log_prob vs scipy, normalisation, determinism."""

import numpy as np
import pytest
from scipy import integrate, stats

from simcam.errors import NoiseModelError
from simcam.noise import NoiseCondition, model_from_entry, model_types
from simcam.noise.base import BLOCK_ROWS

COND = NoiseCondition(cfa="RGGB")
LEVELS = np.array([0.0, 0.02, 0.1, 0.4, 0.9], np.float32)

ENTRIES = {
    "gaussian": {"type": "gaussian", "sigma": [0.01, 0.02, 0.015, 0.005]},
    "nlf": {"type": "nlf", "beta1": [2e-3, 1e-3, 1e-3, 3e-3], "beta2": 4e-5},
    "poisson_gaussian": {"type": "poisson_gaussian", "beta1": [2e-3, 1e-3, 1e-3, 5e-3], "beta2": 1e-5},
    "poisson_mixture": {"type": "poisson_mixture", "beta1": 1e-3, "beta2": 1e-5, "z1": 1.0, "z2": 3.0, "p1": 0.7},
    "clipped": {"type": "clipped", "base": {"type": "nlf", "beta1": 1e-3, "beta2": 1e-5}},
    "composite": {"type": "composite", "base": {"type": "nlf", "beta1": 1e-3, "beta2": 1e-5},
                  "effects": [{"type": "dsnu", "sigma": 1e-3}]},
    # the shipped default flow (tests/noise/test_flow_profile.py checks its statistics)
    "noiseflow_onnx": {"type": "noiseflow_onnx", "path": "noiseflow_sidd_gp.onnx", "camera": "GP"},
}


def test_every_registered_model_has_a_test_entry():
    # registry-driven: a new model type without an entry here fails
    assert set(model_types()) == set(ENTRIES)


@pytest.mark.parametrize("name", sorted(ENTRIES))
def test_entry_round_trip(name):
    m = model_from_entry(ENTRIES[name])
    again = model_from_entry(m.to_entry())
    assert again.to_entry() == m.to_entry()
    import yaml

    assert model_from_entry(yaml.safe_load(yaml.safe_dump(m.to_entry()))).to_entry() == m.to_entry()


def _level_image(h_per_level=64, w=256):
    return np.repeat(LEVELS, h_per_level)[:, None] * np.ones((1, w), np.float32)


def _theory_var(name, clean, site):
    e = ENTRIES[name]
    if name == "gaussian":
        return e["sigma"][site] ** 2 * np.ones_like(clean)
    if name in ("nlf", "poisson_gaussian"):
        b1 = e["beta1"][site] if isinstance(e["beta1"], list) else e["beta1"]
        return b1 * clean + e["beta2"]
    if name == "poisson_mixture":
        zbar = e["p1"] * e["z1"] + (1 - e["p1"]) * e["z2"]
        return e["beta1"] * zbar * clean + e["beta2"]


@pytest.mark.parametrize("name", ["gaussian", "nlf", "poisson_gaussian", "poisson_mixture"])
def test_per_intensity_mean_and_variance(name):
    """Per level and CFA site: sample mean and variance of noisy - clean vs theory.

    Tolerances: 5 standard errors. Mean SE = sqrt(var / n). Variance SE =
    sqrt((m4 - s^4) / n) (delta method for the sample variance, with m4 the
    sample fourth central moment, valid for any law with finite 4th moment).
    """
    m = model_from_entry(ENTRIES[name])
    clean = _level_image()
    noisy = m.sample(clean, COND, np.random.default_rng(11))
    assert noisy.dtype == np.float32 and noisy.shape == clean.shape
    for li, level in enumerate(LEVELS):
        rows = slice(li * 64, (li + 1) * 64)
        for site, (dy, dx) in enumerate([(0, 0), (0, 1), (1, 0), (1, 1)]):
            c = clean[rows][dy::2, dx::2].astype(np.float64)
            n = noisy[rows][dy::2, dx::2].astype(np.float64) - c
            v_th = float(_theory_var(name, c, site).mean())
            cnt = n.size
            mean, var = n.mean(), n.var(ddof=1)
            m4 = np.mean((n - mean) ** 4)
            assert abs(mean) < 5 * np.sqrt(v_th / cnt) + 1e-7, (level, site, mean)
            assert abs(var - v_th) < 5 * np.sqrt(max(m4 - var**2, 0) / cnt) + 1e-9, (level, site, var, v_th)
    th = m.variance(clean, COND)
    assert th.shape == clean.shape


def test_gaussian_and_nlf_log_prob_equal_scipy_norm():
    rng = np.random.default_rng(3)
    clean = rng.random((6, 8), dtype=np.float32)
    noisy = clean + rng.normal(0, 0.03, clean.shape).astype(np.float32)
    m = model_from_entry(ENTRIES["nlf"])
    b1 = np.tile(np.array([[2e-3, 1e-3], [1e-3, 3e-3]]), (3, 4))
    ref = stats.norm.logpdf(noisy.astype(np.float64), clean.astype(np.float64), np.sqrt(b1 * clean + 4e-5))
    np.testing.assert_allclose(m.log_prob(noisy, clean, COND), ref, rtol=1e-5, atol=1e-6)
    g = model_from_entry({"type": "gaussian", "sigma": 0.02})
    ref = stats.norm.logpdf(noisy.astype(np.float64), clean.astype(np.float64), 0.02)
    np.testing.assert_allclose(g.log_prob(noisy, clean, COND), ref, rtol=1e-5, atol=1e-6)


def test_clipped_log_prob_is_censored_normal():
    m = model_from_entry({"type": "clipped", "base": {"type": "nlf", "beta1": 1e-2, "beta2": 1e-3}})
    clean = np.array([[0.01, 0.5, 0.98, 0.3]], np.float32)
    noisy = np.array([[0.0, 0.52, 1.0, 0.1]], np.float32)
    sd = np.sqrt(1e-2 * clean.astype(np.float64) + 1e-3)
    c = clean.astype(np.float64)
    ref = [stats.norm.logcdf(0, c[0, 0], sd[0, 0]), stats.norm.logpdf(0.52, c[0, 1], sd[0, 1]),
           stats.norm.logsf(1, c[0, 2], sd[0, 2]), stats.norm.logpdf(0.1, c[0, 3], sd[0, 3])]
    np.testing.assert_allclose(m.log_prob(noisy, clean, COND)[0], ref, rtol=1e-6)
    out = m.sample(np.full((4, 4), 0.99, np.float32), COND, np.random.default_rng(0))
    assert out.max() <= 1.0 and out.min() >= 0.0


def _mass(m, c, lo=-0.3, hi=1.3):
    """Integral of exp(log_prob) over noisy on a fine grid (+ atoms of censored models)."""
    x = np.linspace(lo, hi, 40001, dtype=np.float64)
    clean = np.full((1, x.size), c, np.float32)
    if m.type == "clipped":
        # interior: the clipped density equals the base one on (low, high);
        # the grid includes the end points (the density's limits there)
        xi = np.linspace(m.low, m.high, 40001)
        inner = np.exp(m.log_prob(xi[None, 1:-1], clean[:, : xi.size - 2], COND))[0]
        ends = np.exp(m.base.log_prob(xi[None, [0, -1]], clean[:, :2], COND))[0]
        dens = np.concatenate([[ends[0]], inner, [ends[1]]])
        atoms = np.exp(m.log_prob(np.array([[m.low, m.high]]), clean[:, :2], COND))[0].sum()
        return integrate.trapezoid(dens, xi) + atoms
    return integrate.trapezoid(np.exp(m.log_prob(x[None], clean, COND))[0], x)


@pytest.mark.parametrize("name,c", [("poisson_gaussian", 0.0), ("poisson_gaussian", 0.004), ("poisson_gaussian", 0.5),
                                    ("poisson_mixture", 0.05), ("clipped", 0.002), ("clipped", 0.999),
                                    ("nlf", 0.3)])
def test_log_prob_integrates_to_one(name, c):
    entry = dict(ENTRIES[name])
    if name == "poisson_gaussian":
        entry = {"type": "poisson_gaussian", "beta1": 2e-3, "beta2": 1e-5}
    m = model_from_entry(entry)
    # trapezoid on a grid of step 4e-5 resolves densities of width >= 3e-3 to < 1e-4
    assert _mass(m, c) == pytest.approx(1.0, abs=2e-4)


def test_poisson_gaussian_log_prob_matches_brute_force_sum():
    """log sum_k Pois(k) N(x; b1 k, b2) over all k = 0..3000 (scipy densities) vs the windowed sum."""
    b1, b2 = 2e-3, 1e-5
    m = model_from_entry({"type": "poisson_gaussian", "beta1": b1, "beta2": b2})
    clean = np.array([[0.0, 0.001, 0.02, 0.3, 0.7, 0.7]], np.float32)
    noisy = np.array([[-0.01, 0.004, 0.015, 0.33, 0.71, 0.9]], np.float32)
    k = np.arange(3001)[None, :]
    lam = clean.astype(np.float64)[0, :, None] / b1
    ref = np.log(np.sum(stats.poisson.pmf(k, lam) * stats.norm.pdf(noisy.astype(np.float64)[0, :, None], b1 * k, np.sqrt(b2)),
                        axis=1))
    np.testing.assert_allclose(m.log_prob(noisy, clean, COND)[0], ref, rtol=1e-9, atol=1e-9)


def test_poisson_gaussian_low_lambda_counts_chi_square():
    """With beta2 = 0 the noisy values are beta1 * counts: chi-square against scipy's Poisson."""
    b1 = 0.01
    m = model_from_entry({"type": "poisson_gaussian", "beta1": b1, "beta2": 0.0})
    clean = np.full((256, 256), 0.03, np.float32)  # lambda = 3
    k = np.round(m.sample(clean, COND, np.random.default_rng(9)) / b1).astype(int).ravel()
    obs = np.bincount(k, minlength=12)
    e = stats.poisson.pmf(np.arange(12), 3.0) * k.size
    o = np.concatenate([obs[:11], [obs[11:].sum()]])
    e = np.concatenate([e[:11], [k.size - e[:11].sum()]])
    assert stats.chi2.sf(((o - e) ** 2 / e).sum(), len(o) - 1) > 1e-3


@pytest.mark.parametrize("name", sorted(ENTRIES))
def test_same_seed_same_bytes_any_chunking(name):
    m = model_from_entry(ENTRIES[name])
    cond = NoiseCondition(cfa="RGGB", iso=400.0) if name == "noiseflow_onnx" else COND  # the flow needs an ISO
    clean = np.random.default_rng(0).random((3 * BLOCK_ROWS + 6, 50), dtype=np.float32)
    a = m.sample(clean, cond, np.random.default_rng(42))
    for chunk, threads in ((1, 1), (BLOCK_ROWS, 1), (45, 3), (1000, 2)):
        b = m.sample(clean, cond, np.random.default_rng(42), chunk_rows=chunk, threads=threads)
        assert a.tobytes() == b.tobytes()
    c = m.sample(clean, cond, np.random.default_rng(43))
    assert not np.array_equal(a, c)


def test_sample_rows_reproduces_frame_rows():
    from simcam.noise.base import frame_key

    m = model_from_entry(ENTRIES["poisson_gaussian"])
    clean = np.random.default_rng(0).random((4 * BLOCK_ROWS, 20), dtype=np.float32)
    full = m.sample(clean, COND, np.random.default_rng(5))
    key = frame_key(np.random.default_rng(5))
    part = m.sample_rows(clean[2 * BLOCK_ROWS:], COND, key, 2 * BLOCK_ROWS)
    assert part.tobytes() == full[2 * BLOCK_ROWS:].tobytes()


@pytest.mark.parametrize("bad,msg", [
    (np.array([[0.1, np.nan]], np.float32), "NaN"),
    (np.array([[0.1, -0.01]], np.float32), ">= 0"),
    (np.zeros((2, 2, 3), np.float32), "H x W"),
])
def test_bad_clean_values(bad, msg):
    m = model_from_entry(ENTRIES["nlf"])
    with pytest.raises(NoiseModelError, match=msg) as ei:
        m.sample(bad, COND, np.random.default_rng(0))
    assert "\n" not in str(ei.value)


def test_shape_mismatch_and_unknown_cfa():
    m = model_from_entry(ENTRIES["nlf"])
    with pytest.raises(NoiseModelError, match="shape"):
        m.log_prob(np.zeros((4, 4)), np.zeros((4, 6), np.float32), COND)
    with pytest.raises(NoiseModelError, match="CFA"):
        m.sample(np.zeros((4, 4), np.float32), NoiseCondition(cfa=None), np.random.default_rng(0))


@pytest.mark.parametrize("entry,msg", [
    ({"type": "nlf", "beta1": -1e-3, "beta2": 1e-5}, "beta1"),
    ({"type": "nlf", "beta1": [1e-3, 1e-3], "beta2": 1e-5}, "4 per-site"),
    ({"type": "nlf", "beta1": 1e-3}, "beta2"),
    ({"type": "nlf", "beta1": 1e-3, "beta2": 1e-5, "gain": 2}, "unknown parameter"),
    ({"type": "poisson_gaussian", "beta1": 0.0, "beta2": 1e-5}, "> 0"),
    ({"type": "warp"}, "unknown noise model"),
])
def test_bad_entries(entry, msg):
    with pytest.raises(NoiseModelError, match=msg):
        model_from_entry(entry)


def test_clipped_per_intensity_mean_and_variance():
    """Clipped NLF near the ends: sample moments vs the censored-normal moments (scipy quad).

    E[clip(X)] and Var[clip(X)] with X ~ N(c, b1 c + b2) computed by
    integrating clip(x) against scipy.stats.norm; 5-SE bands as above.
    """
    from scipy import integrate

    b1, b2 = 2e-3, 1e-4
    m = model_from_entry({"type": "clipped", "base": {"type": "nlf", "beta1": b1, "beta2": b2}})
    levels = np.array([0.0, 0.01, 0.5, 0.98, 1.0], np.float32)
    clean = np.repeat(levels, 64)[:, None] * np.ones((1, 256), np.float32)
    noisy = m.sample(clean, COND, np.random.default_rng(21)).astype(np.float64)
    for i, c in enumerate(levels.astype(np.float64)):
        x = noisy[i * 64:(i + 1) * 64].ravel()
        sd = np.sqrt(b1 * c + b2)
        d = stats.norm(c, sd)
        m1 = integrate.quad(lambda t: t * d.pdf(t), 0, 1)[0] + d.sf(1)
        m2 = integrate.quad(lambda t: t * t * d.pdf(t), 0, 1)[0] + d.sf(1)
        var = m2 - m1 * m1
        n = x.size
        assert abs(x.mean() - m1) < 5 * np.sqrt(var / n), c
        m4 = np.mean((x - x.mean()) ** 4)
        assert abs(x.var(ddof=1) - var) < 5 * np.sqrt(max(m4 - var * var, 0) / n) + 1e-12, c
