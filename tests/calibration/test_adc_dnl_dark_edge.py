"""The transition a coarse ADC's darks straddle: the diagnostic ``dark_code_split``, the ``adc_dnl`` fit's
measured ``edge_dn`` and the noise stage's ``edges_dn``. Made with numpy: a 256-DN black, a 1-DN read
noise and 11-DN codes (multiples of 11) whose transition between codes 253 and 264 is displaced from
258.5 DN; the fit's analogue darks come from a stand-in bootstrap (Gaussian darks on 1-DN codes, as the
loop's simulator draws a model without its ADC), so the edge is checked against the closed form."""

import numpy as np
import pytest
from scipy.stats import norm

from simcam.calibration import diagnostics as dg
from simcam.calibration.effects import CARDS, FitContext, effect_for
from simcam.calibration.effects.adc_dnl import AdcDnl
from simcam.calibration.model import LoopModel
from simcam.noise.effects.adc import AdcDnl as AdcDnlEffect

BLACK, STEP, READ = 256.0, 11.0, 1.0


def _split_darks(edge: float, read: float = READ, seed: int = 1) -> dg.CaptureData:
    """Darks through 11-DN codes whose transition around the black lies at ``edge`` DN, the others ideal."""
    rng = np.random.default_rng(seed)
    v = BLACK + rng.normal(0.0, read, (16, 32, 48))
    lo = np.floor(edge / STEP) * STEP
    codes = np.where(v < edge, lo, lo + STEP)
    far = (v < lo - STEP / 2) | (v >= lo + 1.5 * STEP)
    codes = np.where(far, np.round(v / STEP) * STEP, codes).astype(np.float32)
    flat = (np.round((600.0 + rng.normal(0.0, 20.0, (4, 32, 48))) / STEP) * STEP).astype(np.float32)  # the codes' grid
    return dg.CaptureData([codes], [flat], [], np.full((2, 2), BLACK), 4095.0, "RGGB")


def _model() -> LoopModel:
    m = LoopModel("RGGB", np.full((2, 2), BLACK), 4095.0, 0.0, READ, READ ** 2).with_effect("quantization",
                                                                                          {"step_dn": STEP})
    m.read_dn = READ  # as the quantiser's indirect fit of the read noise would give it (quantization.py)
    return m


def _analogue_bootstrap(model, specs, rng):
    """The loop's bootstrap of a model without its ADC, for these darks: Gaussian, on 1-DN codes."""
    assert "quantization" not in model.effects and "adc_dnl" not in model.effects
    return [np.round(BLACK + rng.normal(0.0, model.read_dn, (16, 32, 48))) for _ in specs]


def test_the_diagnostic_is_the_share_off_the_blacks_code_and_proposes_adc_dnl():
    assert effect_for("dark_code_split") == "adc_dnl"
    up = _split_darks(255.5)  # about 70 % on 264
    assert dg.dark_code_split(up) == pytest.approx(float(np.mean(up.darks[0] == 264.0)))
    assert 0.6 < dg.dark_code_split(up) < 0.8
    down = _split_darks(248.0 + STEP)  # 259: the transition above the black's code, a few on 264 only
    assert 0.0 < dg.dark_code_split(down) < 0.02
    low = _split_darks(BLACK - 1.0, seed=2)  # 255: about 16 % on the black's code 253, the rest on 264
    assert dg.dark_code_split(low) == pytest.approx(float(np.mean(low.darks[0] == 264.0)))
    # codes 1 DN apart, or darks spread over several codes: not applicable, with the reason
    fine = dg.CaptureData([np.round(BLACK + np.random.default_rng(3).normal(0, 1.0, (4, 16, 16)))], [], [],
                          np.full((2, 2), BLACK), 4095.0, "RGGB")
    value, why = dg.statistic("dark_code_split", fine)
    assert value is None and "not a coarse ADC" in why
    wide = _split_darks(255.5, read=8.0)
    value, why = dg.statistic("dark_code_split", wide)
    assert value is None and "do not sit on the black's code" in why


@pytest.mark.parametrize("edge", [255.5, 257.0, 259.5])
def test_the_fit_measures_the_transition_the_darks_straddle(edge):
    """Closed form: with the model's read noise right, the transition is where the analogue darks hold
    the lower code's share; its SE here ~0.02 DN (24 576 values, two bootstrap sensors)."""
    d = _split_darks(edge)
    card = CARDS["adc_dnl"]
    ctx = FitContext(diagnostic="dark_code_split", value=dg.dark_code_split(d), sim_mean=0.0, seed=5,
                     simulate=_analogue_bootstrap, dark_specs=[object()])
    fit = card.fit(d, _model(), ctx)
    p = fit.params
    assert fit.read_dn == READ and p.dnl_sigma == 0.0 and not card.is_null(p)
    share = float(np.mean(d.darks[0] < 258.5))
    assert p.edge_dn == pytest.approx(BLACK + READ * norm.ppf(share), abs=0.08)
    assert p.edge_dn == pytest.approx(edge, abs=0.1)
    entry = card.to_profile(p, _model()).effect
    assert entry["edges_dn"] == [p.edge_dn] and card.from_profile(entry, 3839.0).edge_dn == p.edge_dn


def test_no_edge_without_a_coarse_step_or_a_split():
    card = CARDS["adc_dnl"]
    ctx = FitContext(diagnostic="dark_code_split", simulate=_analogue_bootstrap, dark_specs=[object()])
    plain = LoopModel("RGGB", np.full((2, 2), BLACK), 4095.0, 0.0, READ, READ ** 2)
    assert card.is_null(card.fit(_split_darks(255.5), plain, ctx))  # the model's codes are 1 DN
    assert card.is_null(card.fit(_split_darks(255.5, read=8.0), _model(), ctx))  # darks over many codes
    assert card.is_null(AdcDnl(dnl_sigma=0.0)) and not card.is_null(AdcDnl(dnl_sigma=0.0, edge_dn=256.0))


def test_a_read_noise_too_large_for_split_darks_is_taken_down_with_the_edge():
    """A quantiser's read-noise fit from split darks' temporal variance under ideal transitions (here 5.7 DN
    under 11-DN codes) would spread the model's darks over three codes: the edge comes with a quarter code."""
    d = _split_darks(255.5)
    m = _model()
    m.read_dn = 5.7
    ctx = FitContext(diagnostic="dark_code_split", seed=5, simulate=_analogue_bootstrap, dark_specs=[object()])
    fit = CARDS["adc_dnl"].fit(d, m, ctx)
    assert fit.read_dn == pytest.approx(0.25 * STEP)
    share = float(np.mean(d.darks[0] < 258.5))
    assert fit.params.edge_dn == pytest.approx(BLACK + 0.25 * STEP * norm.ppf(share), abs=0.15)
    # the diagnostic on a simulated capture: the same share, whether or not its darks sit on two codes
    sim = dg.CaptureData([np.round((BLACK + np.random.default_rng(4).normal(0, 5.7, (4, 32, 48))) / STEP) * STEP],
                         d.flats, [], d.black_dn, 4095.0, "RGGB", simulated=True)
    expected = norm.sf(2.5 / 5.7) - norm.cdf(-8.5 / 5.7)  # above 258.5 minus below 247.5
    assert dg.dark_code_split(sim) == pytest.approx(expected, abs=0.02)


def test_the_noise_stage_puts_a_measured_transition_where_it_was_measured():
    fx = AdcDnlEffect(range_dn=3839.0, offset_dn=BLACK, bits=9, dnl_sigma=0.3, step_dn=STEP, edges_dn=[255.5])
    edges = fx.fixed((4, 4), np.random.default_rng(0))["edges"] * STEP
    assert np.any(np.isclose(edges, 255.5)) and not np.any((edges > 258.5 - 2) & (edges < 258.5 + 2))
    exact = AdcDnlEffect(range_dn=3839.0, offset_dn=BLACK, bits=9, dnl_sigma=0.0, step_dn=STEP, edges_dn=[255.5])
    dn = np.array([255.4, 255.6, 250.0, 262.0, 248.0, 269.0])
    codes = exact.codes((dn - BLACK) / 3839.0, exact.fixed((4, 4), np.random.default_rng(0))["edges"]) * STEP
    assert codes.tolist() == [253.0, 264.0, 253.0, 264.0, 253.0, 264.0]
