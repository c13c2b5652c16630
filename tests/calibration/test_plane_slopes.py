"""The per-plane photon-transfer slope (``plane_slopes``, behind ``plane_gain_spread`` and the ``channel_gain``
fit) against closed forms: unbiased, and as precise as the inverse-variance weighted least-squares line.

A flat's temporal variance V estimated from ``dof`` degrees of freedom has sampling variance ``2 V^2 / dof``
(chi-square), the same *relative* error at every level, so the least-squares line through the dark point with
weights ``1 / Var(V_i)`` has slope variance ``1 / sum_i(x_i^2 / Var(y_i))`` (dark point's error neglected: it
is the smallest). An unweighted line would give ``sum x_i^2 Var(y_i) / (sum x_i^2)^2``, 1.3x larger for flats
at 15 % and 55 % of full scale: the test tells the two apart with 300 replicates (the sample SD's relative
standard error is 1 / sqrt(2 * 300) = 4 %).
"""

from __future__ import annotations

import numpy as np
import pytest

from simcam.calibration import diagnostics as dg

K, READ, BLACK = 0.8, 2.0, 64.0  # DN per e-, read noise (DN), black level (DN)
LEVELS = (300.0, 1100.0)  # flat means above black (DN)
FRAMES, SIZE = 8, 32


def _capture(rng, gains):
    """Gaussian frames with each plane's Poisson-Gaussian variance: read^2 + K g_c x."""
    g = np.asarray(gains).reshape(2, 2)
    site_gain = np.tile(g, (SIZE // 2, SIZE // 2))

    def seq(x):
        sd = np.sqrt(READ ** 2 + K * site_gain * x)
        return (BLACK + x + sd * rng.standard_normal((FRAMES, SIZE, SIZE))).astype(np.float32)

    return dg.CaptureData([seq(0.0)], [seq(x) for x in LEVELS], [], np.full((2, 2), BLACK), 4095.0, "RGGB")


def _weighted_sd(gain: float) -> float:
    dof_flat = (FRAMES - 1) * (SIZE // 2) ** 2
    var_y = [2 * (READ ** 2 + K * gain * x) ** 2 / dof_flat for x in LEVELS]
    return 1.0 / np.sqrt(sum(x * x / v for x, v in zip(LEVELS, var_y)))


def test_plane_slopes_are_unbiased_and_as_precise_as_weighted_least_squares():
    gains = (1.04, 1.0, 0.97, 0.99)
    rng = np.random.default_rng(1729)
    k = np.array([dg.plane_slopes(_capture(rng, gains)) for _ in range(300)])  # (replicates, planes)
    sd_pred = np.array([_weighted_sd(g) for g in gains])
    # unbiased: the mean over replicates within 4 of its standard errors (each frame's mean is removed
    # before the variance, which takes 1 / (plane pixels) of every variance, the dark's too)
    expected = K * np.array(gains) * (1 - 1 / (SIZE // 2) ** 2)
    np.testing.assert_allclose(k.mean(0), expected, atol=float(4 * sd_pred.max() / np.sqrt(300)))
    # the spread is the weighted line's (4 SE of a sample SD: 16 %); the unweighted line's is 13 % above it
    sd = k.std(0, ddof=1)
    assert np.all(np.abs(sd / sd_pred - 1) < 0.16), sd / sd_pred
    assert float(np.mean(sd / sd_pred)) == pytest.approx(1.0, abs=0.08)  # pooled over 4 planes: SE 2 %


def test_plane_slopes_weight_each_flat_by_its_degrees_of_freedom():
    """A flat of many frames counts more than one of few: the closed form with the dof weights and the
    variances of the unweighted line (the dark point's dof so large that its error drops out)."""
    darks = [np.column_stack([np.full(4, BLACK), np.full(4, READ ** 2)])]
    flats = [np.column_stack([np.full(4, BLACK + x), np.full(4, READ ** 2 + K * x + e)])
             for x, e in zip(LEVELS, (30.0, -40.0))]

    class Points:
        def ptc_points(self):
            return darks, flats

        def ptc_dof(self):
            return np.array([1e9]), np.array([10.0, 1000.0])

    x = np.array(LEVELS)
    y = np.array([K * x_ + e for x_, e in zip(LEVELS, (30.0, -40.0))])
    k0 = (x * y).sum() / (x * x).sum()  # the unweighted line gives the variances the weights come from
    w = np.array([10.0, 1000.0]) / (READ ** 2 + k0 * x) ** 2
    np.testing.assert_allclose(dg.plane_slopes(Points()), np.full(4, (w * x * y).sum() / (w * x * x).sum()), rtol=1e-6)
