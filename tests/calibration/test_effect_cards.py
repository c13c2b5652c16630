"""The loop's effect vocabulary is its cards (simcam.calibration.effects): every effect the loop can add,
propose, fit or write has one, and every card fits, converts to the noise stage's profile entry and
back, and formats its parameters. Adding an effect touches its card (and the registry's list) and its
example here, nothing else."""

import sys
from dataclasses import fields

import numpy as np
import pytest

from loop_generator import DEFAULT_EFFECTS, EFFECTS, SensorSpec, capture_set
from loop_matrix import in_memory_capture
from simcam.calibration import diagnostics as dg
from simcam.calibration.effects import CARDS, DIAGNOSTIC_EFFECT, EffectCard, EffectParams, Fit, FitContext, card_for
from simcam.calibration.effects.adc_dnl import AdcDnl
from simcam.calibration.effects.amp_glow import AmpGlow
from simcam.calibration.effects.black_level_offset import BlackLevelOffset
from simcam.calibration.effects.channel_gain import ChannelGain
from simcam.calibration.effects.charge_crosstalk import ChargeCrosstalk
from simcam.calibration.effects.column_fpn import ColumnFpn
from simcam.calibration.effects.dark_current import DarkCurrent
from simcam.calibration.effects.dead_pixels import DeadPixels
from simcam.calibration.effects.dsnu import Dsnu
from simcam.calibration.effects.empirical_lines import EmpiricalLines
from simcam.calibration.effects.empirical_response import EmpiricalResponse, measured_law
from simcam.calibration.effects.empirical_offset import EmpiricalOffset
from simcam.calibration.effects.empirical_spectrum import EmpiricalSpectrum
from simcam.calibration.effects.frame_flicker import FrameFlicker
from simcam.calibration.effects.heavy_tail_read import HeavyTailRead
from simcam.calibration.effects.hot_pixels import HotPixels
from simcam.calibration.effects.nonlinearity import Nonlinearity
from simcam.calibration.effects.periodic_pattern import PeriodicPattern
from simcam.calibration.effects.prnu import Prnu
from simcam.calibration.effects.quantization import Quantization
from simcam.calibration.effects.row_noise import RowNoise
from simcam.calibration.effects.rtn import Rtn
from simcam.calibration.effects.spatial_correlation import SpatialCorrelation
from simcam.calibration.model import LoopModel, marginal_variance, site_map
from simcam.calibration.profile import models_from_noise_profile, noise_entry, noise_profile
from simcam.calibration.report import format_parameters
from simcam.calibration.simulate import composite_entry

#: one example per card, typical magnitudes (in the loop's units)
EXAMPLES = {
    "prnu": Prnu(sigma=0.012),
    "channel_gain": ChannelGain(gains=[1.1, 1.0, 1.0, 0.9]),
    "frame_flicker": FrameFlicker(sigma=0.005),
    "heavy_tail_read": HeavyTailRead(lam=-0.2),
    "spatial_correlation": SpatialCorrelation(a=0.2),
    "row_noise": RowNoise(sigma_dn=1.5),
    "periodic_pattern": PeriodicPattern(amplitude_dn=2.0, period_px=8.0, axis="col"),
    "nonlinearity": Nonlinearity(c=-0.1),
    "dark_current": DarkCurrent(rate_e_per_s=40.0, log_sigma=0.3, gain_dn_per_e=2.0),
    "amp_glow": AmpGlow(rate_e_per_s=40.0, origin="top_right", scale=0.2, gain_dn_per_e=2.0),
    "column_fpn": ColumnFpn(sigma_dn=1.0),
    "dsnu": Dsnu(sigma_dn=2.0),
    "hot_pixels": HotPixels(fraction=0.004, log_mean=3.9, log_sigma=0.75, count=16),
    "dead_pixels": DeadPixels(dead_fraction=0.004, stuck_fraction=0.002, stuck_value_dn=959.0, count=24),
    "rtn": Rtn(fraction=0.008, amplitude_dn=20.0, amplitude_log_sigma=0.3, p_high=0.35, count=20),
    "black_level_offset": BlackLevelOffset(offset_dn=[6.0, 5.5, 6.5, 6.0]),
    "quantization": Quantization(step_dn=4.0),
    "adc_dnl": AdcDnl(dnl_sigma=0.2),
    "charge_crosstalk": ChargeCrosstalk(c=0.03),
    "empirical_offset": EmpiricalOffset(quantiles_dn=[float(x) for x in np.linspace(-3.0, 3.0, 33) ** 3 / 9]),
    "empirical_lines": EmpiricalLines(lines_dn=[[0.25, 1.4], [0.125, 0.5]]),
    "empirical_spectrum": EmpiricalSpectrum(frequencies=[0.0156, 0.05, 0.2, 0.45], power_dn2=[9.0, 2.5, 0.4, 0.1],
                                            dc_power_dn2=6.0),
    # a skewed law (every pixel compressing, some more): half-normal curvatures
    "empirical_response": EmpiricalResponse(
        c_mean=-0.04, c_sd=0.025,
        quantiles=measured_law(-np.abs(np.random.default_rng(3).standard_normal(4000)), 0.025)),
}
#: diagnostics that by design propose no effect (outside the vocabulary)
UNATTRIBUTED = {"dark_checker_jitter"}  # no effect of the vocabulary makes it
WHITE, BLACK = 1023.0, 64.0
FS = WHITE - BLACK


def _model(effects: dict) -> LoopModel:
    m = LoopModel("RGGB", np.full((2, 2), BLACK), WHITE, 2.0, 3.0, 0.0, effects=effects)
    m.set_dark_variance_from_read()
    return m


def _assert_close(params: EffectParams, want: dict) -> None:
    got = params.to_dict()
    assert list(got) == list(want)
    for k, v in want.items():
        if isinstance(v, list) and v and isinstance(v[0], list):  # a table (empirical_lines' lines)
            assert np.asarray(got[k]) == pytest.approx(np.asarray(v), rel=1e-12, abs=1e-12), k
            continue
        assert got[k] == (v if isinstance(v, str) else pytest.approx(v, rel=1e-12, abs=1e-12)), k


def test_every_effect_has_a_card():
    names = set(CARDS)
    assert set(EXAMPLES) == names, "every card needs an example here (and every example a card)"
    # every effect the loop can add is one a diagnostic proposes: all have cards, and every card is proposed
    assert set(DIAGNOSTIC_EFFECT) == set(dg.DIAGNOSTICS)
    assert {e for e in DIAGNOSTIC_EFFECT.values() if e is not None} == names
    assert {d for d, e in DIAGNOSTIC_EFFECT.items() if e is None} == UNATTRIBUTED
    # the hidden effects of the test generator are the named vocabulary (empirical components stand for
    # effects outside it: the generator's column_noise, interleaved_columns and row_wander)
    assert set(EFFECTS) == {n for n, c in CARDS.items() if c.family is None}
    assert {n for n, c in CARDS.items() if c.family is not None} == {"empirical_offset", "empirical_lines",
                                                                      "empirical_spectrum", "empirical_response"}
    # every effect type the loop writes to profile.yaml, and every one its bootstrap samples, has a card
    m = _model(dict(EXAMPLES))
    entry, _ = noise_entry(m)
    written = {e["type"] for e in entry["effects"]}
    assert written <= names and written == names - {"channel_gain"}  # channel_gain is the base's per-site beta1
    assert {e["type"] for e in composite_entry(m)["effects"]} <= names
    for name, c in CARDS.items():
        assert c.name == name and isinstance(c, EffectCard) and card_for(name) is c
        assert c.diagnostics and all(DIAGNOSTIC_EFFECT[d] == name for d in c.diagnostics)
        assert issubclass(c.params, EffectParams) and isinstance(EXAMPLES[name], c.params)
        # a fit, a profile conversion both ways, and the report's formatting of its own
        cls = type(c)
        assert cls.fit is not EffectCard.fit and cls.to_profile is not EffectCard.to_profile
        assert cls.from_profile is not EffectCard.from_profile
        text = c.format(EXAMPLES[name])
        assert all(f"{f} = " in text for f in EXAMPLES[name].to_dict())
        # typed parameters with a unit and a doc on every field
        for f in fields(c.params):
            assert "unit" in f.metadata and f.metadata.get("doc"), (name, f.name)
        # the physics docstring cites its sources
        doc = " ".join(sys.modules[cls.__module__].__doc__.split())
        assert "A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD dissertation, York University, 2020" in doc
        assert "EMVA 1288 Release 4.0, sec." in doc and "Physics." in doc and "Fit." in doc and "Profile." in doc


@pytest.mark.parametrize("name", list(CARDS))
def test_card_profile_round_trip(name):
    """params -> profile entry -> params (the card alone, then the whole profile document)."""
    c, p = CARDS[name], EXAMPLES[name]
    m = _model({name: p})
    term = c.to_profile(p, m)
    if term.effect is not None:
        assert term.effect["type"] == name
        back = c.from_profile(term.effect, FS)
    else:  # carried by the base: per-site beta1
        back = c.from_base(np.asarray(term.beta1))
    want = p.to_dict()
    if name in ("hot_pixels", "dead_pixels", "rtn"):  # the profile keeps the shares, not the count of the pixels fitted
        want.pop("count")
    _assert_close(back, want)
    # through profile.yaml's document and back to a LoopModel
    class _Res:
        model, iso = m, 800

    class _Cap:
        root = "/tmp/sensor"

    lm = models_from_noise_profile(noise_profile([_Res()], _Cap()), "profile.yaml")[800]
    assert list(lm.effects) == [name]
    _assert_close(lm.effects[name], want)
    assert lm.read_dn == pytest.approx(m.read_dn) and lm.var_dark_dn2 == pytest.approx(m.var_dark_dn2)
    assert lm.K == pytest.approx(m.K)
    # loop_model.yaml's dict and back (exact)
    assert c.params.from_dict(p.to_dict()) == p


def test_params_read_as_the_former_dicts():
    p = EXAMPLES["hot_pixels"]
    assert dict(p) == {"fraction": 0.004, "log_mean": 3.9, "log_sigma": 0.75, "count": 16} and p["count"] == 16
    no_count = HotPixels(fraction=0.004, log_mean=3.9, log_sigma=0.75)
    assert list(no_count) == ["fraction", "log_mean", "log_sigma"] and "count" not in no_count
    assert LoopModel("RGGB", np.full((2, 2), BLACK), WHITE, 2.0, 3.0, 9.0,
                     effects={"row_noise": {"sigma_dn": 1.5}}).effects["row_noise"] == RowNoise(sigma_dn=1.5)
    with pytest.raises(ValueError, match="row_noise: unknown parameter"):
        LoopModel("RGGB", np.full((2, 2), BLACK), WHITE, 2.0, 3.0, 9.0, effects={"row_noise": {"sigma": 1.5}})
    with pytest.raises(KeyError, match="unknown effect"):
        LoopModel("RGGB", np.full((2, 2), BLACK), WHITE, 2.0, 3.0, 9.0, effects={"column_noise": {"sigma_dn": 1.5}})


def test_report_formats_through_the_cards():
    assert format_parameters("row_noise", {"sigma_dn": 2.661862129850693}) == "sigma_dn = 2.66 DN"
    assert format_parameters("hot_pixels", EXAMPLES["hot_pixels"].to_dict()) == \
        "fraction = 0.4 %; log_mean = 3.9 ln DN; log_sigma = 0.75 ln DN; count = 16"


def test_read_noise_bookkeeping_and_marginal_variance():
    """refit_read and set_dark_variance_from_read are inverse; the marginal variance is the closed form of
    model.py's docstring: (K g x + read^2 + row^2 + A^2/2 + (flicker x)^2 + (prnu x)^2) slope^2 + dsnu^2 + col^2
    + q^2/12, x the linear signal; None with a non-Gaussian effect."""
    gaussian = {k: v for k, v in EXAMPLES.items()
                if CARDS[k].gaussian and k not in ("charge_crosstalk", "empirical_response")}
    m = _model(gaussian)
    read = m.read_dn
    m.refit_read()
    assert m.read_dn == pytest.approx(read)
    # the coloured row offsets' variance: their spectrum's mean over the 64 frequencies k / 64 of the 64 rows it
    # was measured on (1 / 0.0156), linear in log f between the bands, flat beyond them, its dc_power at f = 0
    sp = EXAMPLES["empirical_spectrum"]
    k = np.abs(np.fft.fftfreq(64))[1:]
    row2 = (sp.dc_power_dn2 + float(np.sum(np.interp(np.log(k), np.log(sp.frequencies), sp.power_dn2)))) / 64
    assert m.var_dark_dn2 == pytest.approx(read ** 2 + 16 / 12 + 1.5 ** 2 + 2.0 ** 2 / 2 + row2)
    y = np.linspace(0.0, 800.0, 64).reshape(8, 8)
    c = -0.1
    x = (np.sqrt(1 + 4 * c * y / FS) - 1) * FS / (2 * c)  # inverse of y = x + c x^2 / FS
    g = site_map([1.1, 1.0, 1.0, 0.9], y.shape)
    temporal = 2.0 * g * x + read ** 2 + 1.5 ** 2 + row2 + 2.0 ** 2 / 2 + (0.005 * x) ** 2
    slope2 = (1 + 2 * c * x / FS) ** 2
    want = (temporal + (0.012 * x) ** 2) * slope2 + 2.0 ** 2 + 1.0 ** 2 + 16 / 12
    assert marginal_variance(m, y) == pytest.approx(want, rel=1e-9)
    assert marginal_variance(m, y, fixed_in_clean=True) == pytest.approx(temporal * slope2 + 16 / 12, rel=1e-9)
    for name in ("hot_pixels", "heavy_tail_read"):
        assert marginal_variance(_model({name: EXAMPLES[name]}), y) is None
    # a per-pixel response curvature: the mean curvature's slope, and its spread's fixed pattern (sd(c) x^2 / s)^2
    er = EXAMPLES["empirical_response"]
    m = _model({"empirical_response": er})
    cm = er.c_mean
    x = (np.sqrt(1 + 4 * cm * y / FS) - 1) * FS / (2 * cm)
    want = (2.0 * x + m.read_dn ** 2) * (1 + 2 * cm * x / FS) ** 2 + (er.c_sd * x * x / FS) ** 2 + 1 / 12  # + the ADC step
    assert marginal_variance(m, y) == pytest.approx(want, rel=1e-9)


def test_charge_crosstalk_marginal_and_signal():
    """Charge sharing keeps a uniform signal and scales its shot-noise variance by (1 - 4c)^2 + 4c^2; the
    expected charge of a non-uniform image is the one whose sharing (the closed-form 5-point kernel, written out
    here) gives it back."""
    c = 0.03
    m = _model({"charge_crosstalk": ChargeCrosstalk(c=c)})
    y = np.full((6, 8), 300.0)
    f = (1 - 4 * c) ** 2 + 4 * c ** 2
    assert marginal_variance(m, y) == pytest.approx(2.0 * f * y + 9.0 + 1 / 12, rel=1e-12)
    yy = 200.0 + 100.0 * np.sin(np.arange(48).reshape(6, 8) / 5.0)
    from simcam.calibration.model import linear_signal

    x = linear_signal(m, yy)
    p = np.pad(x, 1, mode="reflect")
    shared = (1 - 4 * c) * x + c * (p[:-2, 1:-1] + p[2:, 1:-1] + p[1:-1, :-2] + p[1:-1, 2:])
    assert shared == pytest.approx(yy, rel=1e-5)


def _fit_data(name: str, seed: int = 3):
    from simcam.calibration.loop import Group, LoopConfig

    side = 64 if name == "adc_dnl" else 32  # the histogram test needs >= 8 codes holding >= 100 values
    # an empirical component is fitted on the generator's effect outside the vocabulary it stands for
    outside = {"empirical_offset": {"column_noise": {"sigma_dn": 1.5}},
               "empirical_lines": {"interleaved_columns": {"offset_dn": 3.0, "period_px": 4}},
               "empirical_spectrum": {"row_wander": {"sigma_dn": 2.0, "rho": 0.8}},
               "empirical_response": {"pixel_curvature": {"c_mean": -0.05, "c_sd": 0.1}}}
    effects = outside.get(name) or {name: DEFAULT_EFFECTS[name]}
    spec = SensorSpec(height=side, width=side, effects=effects)
    cs = in_memory_capture(capture_set(spec, n_frames=8, seed=seed))
    return Group(cs.group(800), LoopConfig(), [])


@pytest.mark.parametrize("name", list(CARDS))
def test_every_card_fits_its_effect(name):
    """Each card's fit on a small capture holding its effect alone (32 x 32, 4 fit frames per sequence) returns
    its typed parameters, not the identity, and the loop's fit adds them to the model."""
    from simcam.calibration.fit import base_fit, fit_effect
    from simcam.calibration.simulate import simulate_capture

    g = _fit_data(name)
    base = base_fit(g.fit_data)
    diagnostic = CARDS[name].diagnostics[0]
    ctx = FitContext(diagnostic=diagnostic, value=dg.STATISTICS[diagnostic](g.fit_data), sim_mean=0.0, seed=1,
                     dark_specs=[sp for sp in g.specs(base, g.fit) if sp.kind == "dark"], simulate=simulate_capture)
    fitted = CARDS[name].fit(g.fit_data, base, ctx)
    params = fitted.params if isinstance(fitted, Fit) else fitted
    assert isinstance(params, CARDS[name].params) and not CARDS[name].is_null(params)
    m = fit_effect(name, g.fit_data, base, ctx)
    assert list(m.effects) == [name] and isinstance(m.effects[name], CARDS[name].params)


def test_start_profile_with_an_unknown_effect_is_a_profile_error(tmp_path):
    from simcam.calibration.report import read_start_profile
    from simcam.errors import ProfileError

    doc = ("schema_version: 1\ncfa: RGGB\nblack_level: [64.0, 64.0, 64.0, 64.0]\nwhite_level: 1023.0\n"
           "isos:\n- iso: 800\n  K_dn_per_e: 2.0\n  read_dn: 3.0\n  effects:\n    {}\n")
    ok = tmp_path / "loop_model.yaml"
    ok.write_text(doc.format("row_noise: {sigma_dn: 1.5}"))
    m = read_start_profile(ok)[800]
    assert m.effects["row_noise"] == RowNoise(sigma_dn=1.5) and m.var_dark_dn2 == pytest.approx(9.0 + 1 / 12 + 2.25)
    for effects, what in (("column_noise: {sigma_dn: 1.5}", "unknown effect 'column_noise'"),
                          ("row_noise: {sigma: 1.5}", "row_noise: unknown parameter")):
        bad = tmp_path / "bad.yaml"
        bad.write_text(doc.format(effects))
        with pytest.raises(ProfileError, match=f"bad.yaml: isos\\[0\\].effects: {what}"):
            read_start_profile(bad)
