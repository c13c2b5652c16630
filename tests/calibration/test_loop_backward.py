"""The loop's backward step (``Loop._backward``): an effect added early that a later one superseded is
taken out, one that still earns its held-out gain stays.

Frames from the repository's test generator: random telegraph pixels (1.5 % of the pixels, 20-DN steps,
high 40 % of the frames) and nothing else. The final model is given the generator's telegraph pixels
and, beside them, a heavy-tailed read noise (Tukey lambda -0.1) of the kind the loop once took for the
telegraph pixels' dark tail while their own candidate was refuted by a dark level the model lacked (the
independent simulator's RTN + DNL set at ``--seed 2036``)."""

import numpy as np
import pytest

from loop_generator import SensorSpec, capture_set
from loop_matrix import in_memory_capture
from simcam.calibration.fit import base_fit
from simcam.calibration.loop import Group, GroupResult, Loop, LoopConfig

RTN = {"fraction": 0.015, "amplitude_dn": 20.0, "log_sigma": 0.3, "p_high": 0.4}


@pytest.fixture(scope="module")
def loop():
    caps = capture_set(SensorSpec(effects={"rtn": RTN}), seed=7)
    cfg = LoopConfig(progress=False)
    group = Group(in_memory_capture(caps).group(800), cfg, [])
    return Loop(group, cfg, 800)


def _rtn_model(loop):
    base = base_fit(loop.g.fit_data)
    return base.with_effect("rtn", {"fraction": RTN["fraction"], "amplitude_dn": RTN["amplitude_dn"],
                                    "amplitude_log_sigma": RTN["log_sigma"], "p_high": RTN["p_high"]})


def test_a_superseded_effect_is_taken_out_and_the_right_one_stays(loop):
    model = _rtn_model(loop).with_effect("heavy_tail_read", {"lam": -0.1})
    held = loop.heldout(model, tuple(loop.applicable))
    res = GroupResult(800, model, model)
    out, _held, changed = loop._backward(model, held, {"rtn": True, "heavy_tail_read": True}, set(), res)
    assert changed and list(out.effects) == ["rtn"]
    tests = {b["effect"]: b for b in res.backward}
    assert set(tests) == {"rtn", "heavy_tail_read"}  # one round: a single effect left is not tested
    heavy, rtn = tests["heavy_tail_read"], tests["rtn"]
    assert heavy["removed"] and not rtn["removed"]
    assert heavy["keep_gain"] < 2 * heavy["keep_gain_sd"]  # keeping it does not beat its noise
    assert rtn["keep_gain"] > heavy["keep_gain"]  # the weaker of the two goes first
    # the read noise takes back the variance the heavy tail held (LoopModel.without_effect)
    assert out.read_dn == pytest.approx(_rtn_model(loop).read_dn)


def test_what_the_backward_step_may_not_take_out(loop):
    model = _rtn_model(loop).with_effect("heavy_tail_read", {"lam": -0.1})
    # an effect whose addition re-measured the system gain or the dark variance, or one the loop did not add
    assert not loop.removable(model, "rtn", {"rtn": False, "heavy_tail_read": True})
    assert not loop.removable(model, "rtn", {"heavy_tail_read": True})
    assert loop.removable(model, "rtn", {"rtn": True})
    # an effect another one left in the model is refitted after (column_fpn after empirical_lines)
    m = model.with_effect("column_fpn", {"sigma_dn": 1.0}).with_effect(
        "empirical_lines", {"lines_dn": [[0.125, 1.0]]})
    assert not loop.removable(m, "empirical_lines", {"empirical_lines": True})
    assert loop.removable(m, "column_fpn", {"column_fpn": True})


def test_the_last_addition_is_not_tested_in_the_first_round(loop):
    model = _rtn_model(loop).with_effect("heavy_tail_read", {"lam": -0.1})
    held = loop.heldout(model, tuple(loop.applicable))
    res = GroupResult(800, model, model)
    out, _h, _c = loop._backward(model, held, {"rtn": True, "heavy_tail_read": True}, {"heavy_tail_read", "rtn"}, res)
    assert not res.backward and list(out.effects) == list(model.effects)
    assert np.isfinite(held["kl_structured"])


def test_effects_that_earn_their_keep_stay():
    """Telegraph pixels beside a real DSNU (2 DN rms): both stay, each keeping gain beyond its noise."""
    caps = capture_set(SensorSpec(effects={"rtn": RTN, "dsnu": {"sigma_dn": 2.0}}), seed=8)
    cfg = LoopConfig(progress=False)
    lp = Loop(Group(in_memory_capture(caps).group(800), cfg, []), cfg, 800)
    model = _rtn_model(lp).with_effect("dsnu", {"sigma_dn": 2.0})
    res = GroupResult(800, model, model)
    out, _h, changed = lp._backward(model, lp.heldout(model, tuple(lp.applicable)), {"rtn": True, "dsnu": True},
                                    set(), res)
    assert not changed and list(out.effects) == list(model.effects)
    assert {b["effect"] for b in res.backward} == {"rtn", "dsnu"}
    for b in res.backward:
        assert not b["removed"] and b["keep_gain"] > 2 * b["keep_gain_sd"], b


def test_the_report_lists_every_test(loop):
    from simcam.calibration.report import _backward_table

    model = _rtn_model(loop).with_effect("heavy_tail_read", {"lam": -0.1})
    res = GroupResult(800, model, model)
    loop._backward(model, loop.heldout(model, tuple(loop.applicable)), {"rtn": True, "heavy_tail_read": True},
                   set(), res)
    page = _backward_table(res.backward)
    assert page.count("<tr>") == 1 + len(res.backward)
    assert "yes: keeping it does not beat its noise" in page and "<td class=l>no: " in page
    assert all(b["round"] == 1 for b in res.backward)
