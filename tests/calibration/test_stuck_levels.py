"""Stuck pixels at several levels, and hot pixels clipped at white (``dead_pixels`` and ``hot_pixels`` cards,
``simcam/noise/effects/defects.py``). Captures are made with numpy here (Gaussian read noise, Poisson dark
charge), not with simcam's noise code; references are the planted pixels and closed forms."""

import numpy as np
import pytest

from simcam.calibration import diagnostics as dg
from simcam.calibration.effects import FitContext
from simcam.calibration.effects.dead_pixels import DeadPixelsCard
from simcam.calibration.effects.hot_pixels import HotPixelsCard, censored_lognormal
from simcam.calibration.model import LoopModel
from simcam.noise.effects.defects import DeadPixels

BLACK, WHITE, READ, H, W = 64.0, 1023.0, 2.0, 64, 96
STUCK = {(5, 7): 0.0, (20, 30): 500.0, (40, 11): WHITE, (33, 70): WHITE}   # code 0, mid-level, white x 2
HOT = {(10, 50): 300.0, (50, 20): 450.0}  # DN above black in the short dark; doubles in the long one
CLIPPED_IN_FLAT = (60, 90)  # a hot pixel that reaches white in the flat only


def _capture(seed=0):
    rng = np.random.default_rng(seed)

    def frames(n, level, hot_scale):
        f = BLACK + level + rng.normal(0.0, READ, (n, H, W))
        for (y, x), off in HOT.items():
            f[:, y, x] += rng.poisson(off * hot_scale, n)
        f[:, CLIPPED_IN_FLAT[0], CLIPPED_IN_FLAT[1]] += 700.0 * hot_scale + rng.normal(0, 5.0, n)
        f = np.clip(np.round(f), 0, WHITE)
        for (y, x), v in STUCK.items():
            f[:, y, x] = v
        return f.astype(np.float32)

    darks = [frames(8, 0.0, 1.0)]
    long_darks = frames(8, 0.0, 2.0)
    flats = [frames(8, 400.0, 1.0)]
    black = np.full((2, 2), BLACK)
    return dg.CaptureData(darks, flats, [], black, WHITE, "RGGB",
                          dark_series=[(0.01, darks[0]), (1.0, long_darks)])


def _model():
    return LoopModel(cfa="RGGB", black_dn=np.full((2, 2), BLACK), white_dn=WHITE, K=1.0, read_dn=READ,
                     var_dark_dn2=READ ** 2)


def test_stuck_pixels_are_constant_in_every_frame_and_hot_ones_are_not():
    d = _capture()
    dead, stuck = dg.defect_masks(d)
    assert {tuple(p) for p in np.argwhere(stuck)} == set(STUCK)  # not the hot pixel clipped in the flat only
    hot = dg.hot_pixel_mask(d)
    assert {tuple(p) for p in np.argwhere(hot)} == set(HOT) | {CLIPPED_IN_FLAT}
    clipped = dg.clipped_constant_pixels(d)
    assert {tuple(p) for p in np.argwhere(clipped)} == {(40, 11), (33, 70)}


def test_dead_pixels_card_keeps_every_stuck_level():
    d = _capture()
    p = DeadPixelsCard().fit(d, _model(), FitContext())
    assert p.stuck_fraction == pytest.approx(len(STUCK) / (H * W))
    assert p.stuck_values_dn == sorted(v - BLACK for v in STUCK.values())
    entry = DeadPixelsCard().to_profile(p, _model()).effect
    back = DeadPixelsCard().from_profile(entry, WHITE - BLACK)
    assert back.stuck_values_dn == pytest.approx(p.stuck_values_dn)


def test_hot_pixels_card_fits_both_forms():
    d = _capture()
    card = HotPixelsCard()
    assert len(card.variants(["hot_pixel_tail"])) == 2
    plain = card.fit(d, _model(), FitContext())
    assert plain.count == len(HOT) + 1
    clipped = card.fit(d, _model(), FitContext(form="clipped"))
    assert clipped.count == len(HOT) + 1 + 2
    # the two white stuck pixels enter as offsets beyond white: the log-normal moves up
    assert clipped.log_mean > plain.log_mean


def test_no_clipped_form_without_pixels_at_white():
    d = _capture()
    for k, (y, x) in enumerate(((40, 11), (33, 70))):
        for seq in d.darks + d.flats:
            seq[:, y, x] = 200.0 + k  # stuck below white now
    d.cache.clear()
    assert HotPixelsCard().fit(d, _model(), FitContext(form="clipped")).fraction == 0.0


@pytest.mark.parametrize("mu,sigma,c", [(7.5, 0.5, 8.0), (3.0, 1.0, 3.5), (5.0, 0.3, 4.8)])
def test_censored_lognormal_recovers_the_parameters(mu, sigma, c):
    """Tobit maximum likelihood in log space against the normal it was drawn from (4 standard errors;
    the SEs of a censored normal's MLE are below sigma sqrt(2 / n_observed) for both parameters)."""
    rng = np.random.default_rng(11)
    x = rng.normal(mu, sigma, 4000)
    obs = x[x < c]
    m, s = censored_lognormal(float(obs.mean()), float(obs.std()), obs.size, c, int((x >= c).sum()))
    se = sigma * np.sqrt(2.0 / obs.size)
    assert abs(m - mu) < 4 * se and abs(s - sigma) < 4 * se
    # the naive moments of the observed ones are off by far more
    assert abs(obs.mean() - mu) > 4 * se or abs(obs.std() - sigma) > 4 * se


def test_noise_stage_draws_each_stuck_level():
    levels = [-0.05, 0.4, 1.0]
    eff = DeadPixels(stuck_fraction=0.05, stuck_values=levels)
    fx = eff.fixed((200, 300), np.random.default_rng(3))
    v = fx["stuck_value"]
    n = v.size
    assert n == fx["stuck"].size and n > 2000
    for lv in levels:  # uniform over the levels: binomial SE
        share = float(np.mean(np.isclose(v, lv)))
        assert abs(share - 1 / 3) < 4 * np.sqrt((1 / 3) * (2 / 3) / n)
    # the defect map is the one of a single level (the levels are drawn after it)
    one = DeadPixels(stuck_fraction=0.05).fixed((200, 300), np.random.default_rng(3))
    np.testing.assert_array_equal(one["stuck"], fx["stuck"])
    assert "stuck_values" not in DeadPixels(stuck_fraction=0.05).to_entry()
    assert DeadPixels(stuck_fraction=0.05, stuck_values=levels).to_entry()["stuck_values"] == levels


@pytest.mark.parametrize("frames", [8, 3])
def test_hot_pixel_mask_is_a_boolean_mask_without_flats(frames):
    """Darks only (no pixel can be called stuck) and, with 3 frames, no telegraph split either: the mask
    stays boolean (``~False`` is -1 in Python, which once made it an integer index of rows 0 and 1)."""
    full = _capture()
    darks = [full.darks[0][:frames]]
    d = dg.CaptureData(darks, [], [], full.black_dn, WHITE, "RGGB")
    hot = dg.hot_pixel_mask(d)
    assert hot.dtype == bool and hot.shape == (H, W)
    # the stuck pixels are dark outliers too when no flat tells them apart
    assert {tuple(p) for p in np.argwhere(hot)} == set(HOT) | {CLIPPED_IN_FLAT, (20, 30), (40, 11), (33, 70)}
    assert not dg.clipped_constant_pixels(d).any()
