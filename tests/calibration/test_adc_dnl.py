"""The ADC's differential non-linearity: the histogram-test diagnostic against its closed form, the card's
fit, and the noise stage's ``adc_dnl`` law (IEEE Std 1241-2010, sec. 4.1.3)."""

import numpy as np
import pytest

from simcam.calibration import diagnostics as dg
from simcam.calibration.effects import excluded_by
from simcam.calibration.effects.adc_dnl import WIDTH_VARIANCE_PER_SIGMA2


def _capture(frames):
    return dg.CaptureData([frames], [], [], np.full((2, 2), 0.0), 4095.0, "RGGB")


def _frames(dnl_sigma, rng, n=8, shape=(256, 256)):
    """A broad smooth signal (sd 40 DN) through an ADC with transition levels k + 1/2 + u_k."""
    v = 2000.0 + 40.0 * rng.standard_normal((n,) + shape)
    if dnl_sigma == 0:
        return np.round(v).astype(np.float32)
    edges = np.sort(np.arange(4095) + 0.5 + dnl_sigma * rng.standard_normal(4095))
    return np.searchsorted(edges, v, side="right").astype(np.float32)


def test_uniform_adc_reads_near_zero_and_dnl_reads_its_closed_form():
    """Counts per code ~ 5,000 over ~150 codes: the statistic's Poisson-removed mean has SE ~ 1e-4 per
    code set; a local quadratic's bias on a 40-DN-wide Gaussian over +-3 codes is ~ (3/40)^4: negligible. With
    dnl_sigma = 0.2 LSB the statistic is (219/49) sigma^2 = 0.179 (first order in sigma, independent offsets);
    the realisation's spread over ~150 codes gives an SE of ~ 12 %."""
    rng = np.random.default_rng(3)
    flat = dg.code_width_spread(_capture(_frames(0.0, rng)))
    assert abs(flat) < 2e-3
    vals = [dg.code_width_spread(_capture(_frames(0.2, rng))) for _ in range(4)]
    assert np.mean(vals) == pytest.approx(WIDTH_VARIANCE_PER_SIGMA2 * 0.04, rel=0.15)


def test_coarse_adc_uses_its_lattice():
    """A 4-DN ADC: the histogram is read on the used codes' lattice, so a uniform step reads as no DNL
    (a signal 160 DN wide: 40 lattice codes, as wide on the lattice as the 1-DN case above)."""
    rng = np.random.default_rng(4)
    v = np.round((2000.0 + 160.0 * rng.standard_normal((8, 256, 256))) / 4) * 4
    d = _capture(v.astype(np.float32))
    assert dg.code_histogram(d)[1] == 4.0
    assert abs(dg.code_width_spread(d)) < 2e-3


def test_a_brighter_flat_shows_the_codes_the_darks_and_dimmest_flat_cannot():
    """A coarse ADC (8-DN codes) with DNL 0.25 of a code: darks on one code and a dim flat 1.5 codes wide say
    nothing about the widths; a brighter flat 8 codes wide does (its shot noise spreads it), and the histogram
    test reads it there: the statistic near its first-order closed form (219/49) sigma^2 = 0.28 instead of
    n/a (~46 codes counted: relative SE ~ sqrt(2/46) = 0.21; seeds 6-11 gave 0.60-1.04 of it, the first-order
    form a little high at sigma = 0.25)."""
    rng = np.random.default_rng(6)
    edges = np.sort(np.arange(511) + 0.5 + 0.25 * rng.standard_normal(511))

    def adc(v):
        return (np.searchsorted(edges, v / 8.0, side="right") * 8).astype(np.float32)

    dark = np.full((8, 128, 128), 64.0, np.float32)
    dim = adc(600.0 + 12.0 * rng.standard_normal((8, 128, 128)))
    bright = adc(2000.0 + 64.0 * rng.standard_normal((8, 128, 128)))
    only_dim = dg.CaptureData([dark], [dim], [], np.full((2, 2), 64.0), 4095.0, "RGGB")
    assert dg.statistic("code_width_spread", only_dim)[0] is None
    both = dg.CaptureData([dark], [dim, bright], [], np.full((2, 2), 64.0), 4095.0, "RGGB")
    assert dg.code_histogram(both)[1] == 8.0
    assert 0.5 < dg.code_width_spread(both) / (WIDTH_VARIANCE_PER_SIGMA2 * 0.25 ** 2) < 1.4


def test_too_few_codes_is_not_applicable():
    d = _capture(np.round(100.0 + 0.3 * np.random.default_rng(5).standard_normal((4, 32, 32))).astype(np.float32))
    value, reason = dg.statistic("code_width_spread", d)
    assert value is None and "ADC codes" in reason


def test_adc_dnl_sits_beside_the_quantiser_on_its_grid():
    """A coarse ADC has unequal codes too: the loop may hold both, the noise stage's ``adc_dnl`` of step 8
    puts every value on the 8-DN grid (the quantiser after it changes nothing), and its codes' counts follow
    unequal widths (equal widths are refuted by the counts, binomial around the Gaussian density)."""
    from scipy.stats import norm

    from simcam.noise.base import NoiseCondition, model_from_entry

    assert excluded_by("adc_dnl", ["dsnu", "quantization"]) is None
    assert excluded_by("quantization", ["adc_dnl"]) is None
    fs, off, step = 4000.0, 64.0, 8.0
    dnl = {"type": "adc_dnl", "range_dn": fs, "offset_dn": off, "bits": 10, "dnl_sigma": 0.25, "step_dn": step}
    quant = {"type": "quantization", "range_dn": fs, "step_dn": step, "offset_dn": off}
    x = np.full((256, 256), 0.3, np.float32)
    cond = NoiseCondition(cfa="RGGB", source="test")
    out = {}
    for name, effects in (("dnl", [dnl]), ("both", [dnl, quant])):
        m = model_from_entry({"type": "composite", "base": {"type": "gaussian", "sigma": 0.01}, "effects": effects,
                              "sensor_seed": 3}, where="test")
        out[name] = m.sample_frames(x, cond, np.random.default_rng(1), 4).astype(np.float64) * fs + off
    np.testing.assert_array_equal(out["dnl"], out["both"])
    codes = np.round(out["dnl"] / step)
    np.testing.assert_allclose(codes * step, out["dnl"], atol=1e-6)
    mu, sd = (0.3 * fs + off) / step, 0.01 * fs / step  # in codes
    k = np.arange(int(mu - 1.5 * sd), int(mu + 1.5 * sd) + 1)
    counts = np.array([(codes == c).sum() for c in k])
    ideal = codes.size * (norm.cdf(k + 0.5, mu, sd) - norm.cdf(k - 0.5, mu, sd))
    assert np.abs((counts - ideal) / np.sqrt(ideal)).max() > 6  # the widths are unequal


def test_loop_fits_the_dnl_of_the_test_generator():
    """The test-owned generator's ADC (dnl_sigma 0.2 LSB, its own transition levels): named alone and its
    size recovered (over seeds 7-9 the fit gave 0.196-0.209; realisation spread of ~ 100 codes ~ 10 %)."""
    from loop_matrix import run_case

    r = run_case(("adc_dnl",))
    assert list(r.model.effects) == ["adc_dnl"] and not r.unexplained
    assert r.model.effects["adc_dnl"].dnl_sigma == pytest.approx(0.2, rel=0.2)


def test_the_fit_waits_for_the_quantisers_step():
    """On a coarse ADC (8-DN codes, unequal widths) the step is the card's prerequisite while the model's
    codes are 1 DN, and a fit without it is null and says why (its widths would be relative to codes the
    data does not have); once the model has the step, it is fitted from the statistic's excess as usual."""
    from simcam.calibration.effects import CARDS, FitContext
    from simcam.calibration.model import LoopModel

    rng = np.random.default_rng(5)
    k = np.arange(600)
    edges = np.sort((k + 0.5 + 0.25 * rng.standard_normal(k.size)) * 8.0)
    v = 2000.0 + 160.0 * rng.standard_normal((8, 256, 256))
    d = _capture((np.searchsorted(edges, v, side="right") * 8.0).astype(np.float32))
    assert dg.adc_step(d) == 8.0
    ctx = FitContext(diagnostic="code_width_spread", value=dg.code_width_spread(d), sim_mean=0.0)
    card = CARDS["adc_dnl"]
    fine = LoopModel("RGGB", np.full((2, 2), 0.0), 4095.0, 1.0, 2.0, 4.0)
    p = card.fit(d, fine, ctx)
    assert card.is_null(p) and p.coarser_codes_dn == 8.0 and "quantization" in card.null_reason(p)
    assert card.prerequisite(d, fine) == "quantization"  # the loop fits the step first, the candidate adds both
    coarse = LoopModel("RGGB", np.full((2, 2), 0.0), 4095.0, 1.0, 2.0, 4.0, effects={
        "quantization": CARDS["quantization"].params(step_dn=8.0)})
    assert card.prerequisite(d, coarse) is None
    p = card.fit(d, coarse, ctx)
    assert p.coarser_codes_dn is None and p.dnl_sigma == pytest.approx(0.25, rel=0.3)
