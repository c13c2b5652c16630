"""A periodic column *gain* pattern (interleaved column ADCs with a gain mismatch) is seen in the flats
and fitted by ``empirical_lines`` with its gain part; frames are drawn here with numpy. Closed forms:
the column pattern ``+s, +s, -s, -s`` (period 4) is the cosine ``sqrt(2) s cos(pi i / 2 - pi / 4)``, so
an offset mismatch ``o`` (columns at +-o/2) is a line of amplitude ``o / sqrt(2)`` at 1/4 cycle per
pixel, a gain mismatch ``g`` one of relative amplitude ``g / sqrt(2)`` in phase with it (both the same
sign pattern) or opposite (signs swapped). Tolerances from the spread of repeated draws."""

import numpy as np
import pytest

from simcam.calibration import diagnostics as dg
from simcam.calibration.effects import card_for

BLACK, WHITE, K, READ, PRNU = 256.0, 4095.0, 0.6, 2.5, 0.01
H, W = 96, 128


def frames(rng, n, level_dn, offset_dn, gain_rel, prnu_map):
    """n frames: signal ``level_dn`` above black through a per-pixel PRNU, Poisson shot noise at K DN per
    electron, Gaussian read noise, and an interleaved-ADC pattern (columns in pairs alternating between
    two converters: offset mismatch ``offset_dn``, gain mismatch ``gain_rel``)."""
    sgn = np.where((np.arange(W) // 2) % 2 == 0, 0.5, -0.5)[None, :]
    out = []
    for _ in range(n):
        e = rng.poisson(level_dn * prnu_map / K) * K if level_dn > 0 else np.zeros((H, W))
        v = e + rng.normal(0, READ, (H, W))
        out.append(BLACK + v + sgn * offset_dn + sgn * gain_rel * v)
    return np.round(np.array(out)).astype(np.float32)


def capture(rng, offset_dn, gain_rel):
    prnu = 1 + PRNU * rng.standard_normal((H, W))
    darks = [frames(rng, 8, 0.0, offset_dn, gain_rel, prnu)]
    flats = [frames(rng, 8, lv, offset_dn, gain_rel, prnu) for lv in (600.0, 2200.0)]
    return dg.CaptureData(darks, flats, [], np.full((2, 2), BLACK), WHITE, "RGGB")


class Model:  # what the card's fit reads of the current model
    effects: dict = {}
    full_scale_dn = WHITE - BLACK


def test_flat_col_spectrum_peak_is_white_noise_without_a_gain_pattern_and_far_out_with_one():
    null = np.array([dg.flat_col_spectrum_peak(capture(np.random.default_rng(s), 3.0, 0.0)) for s in range(16)])
    # an offset pattern alone (the same in darks and flats) drops out: the statistic is the normal quantile
    # of the largest white bin's tail, about N(0, 1) (40 draws here: mean -0.11, sd 1.14)
    assert abs(null.mean()) < 4 * null.std(ddof=1) / np.sqrt(null.size) and 0.6 < null.std(ddof=1) < 1.6
    hit = dg.flat_col_spectrum_peak(capture(np.random.default_rng(99), 3.0, 0.004))
    assert hit > 6.0


@pytest.mark.parametrize("gain_rel", [0.006, -0.006])
def test_empirical_lines_fits_the_gain_part_with_its_phase(gain_rel):
    card = card_for("empirical_lines")
    a_fit, g_fit, d_fit = [], [], []
    for s in range(6):
        p = card.fit(capture(np.random.default_rng(s), 3.0, gain_rel), Model(), None)
        (line,) = [x for x in p.lines_dn if abs(x[0] - 0.25) < 1e-9]
        assert len(line) == 4
        a_fit.append(line[1])
        g_fit.append(line[2])
        d_fit.append(line[3])
    a_fit, g_fit = np.array(a_fit), np.array(g_fit)
    se_a = a_fit.std(ddof=1) / np.sqrt(a_fit.size)
    se_g = g_fit.std(ddof=1) / np.sqrt(g_fit.size)
    assert abs(a_fit.mean() - 3.0 / np.sqrt(2)) < 4 * se_a + 0.02
    assert abs(g_fit.mean() - abs(gain_rel) / np.sqrt(2)) < 4 * se_g + 2e-4
    # in phase for a gain mismatch of the offset's sign, opposite for the other sign
    want = 0.0 if gain_rel > 0 else np.pi
    assert all(abs(np.angle(np.exp(1j * (d - want)))) < 0.2 for d in d_fit)


def test_empirical_lines_without_a_gain_pattern_fits_the_offset_lines_only():
    p = card_for("empirical_lines").fit(capture(np.random.default_rng(5), 3.0, 0.0), Model(), None)
    assert p.lines_dn and all(len(line) == 2 for line in p.lines_dn)


def test_a_card_proposed_by_the_flats_does_not_take_the_darks_strongest_bin():
    """A gain mismatch alone (no offset mismatch): proposed by the flats' statistic, the card's lines are the
    gain line's bin only; the darks' strongest bin (white noise there) is a line only where the darks'
    statistic proposed the card."""
    from simcam.calibration.effects.card import FitContext

    card = card_for("empirical_lines")
    for s in range(4):
        d = capture(np.random.default_rng(40 + s), 0.0, 0.008)
        by_flats = card.fit(d, Model(), FitContext(diagnostic="flat_col_spectrum_peak"))
        assert [line[0] for line in by_flats.lines_dn] == [0.25]
        assert len(by_flats.lines_dn[0]) == 4 and by_flats.lines_dn[0][2] > 0
        by_darks = card.fit(d, Model(), FitContext(diagnostic="col_fpn_spectrum_peak"))
        assert len(by_darks.lines_dn) >= len(by_flats.lines_dn)
