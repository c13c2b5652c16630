"""Cards that re-estimate the system gain K from the photon-transfer points (``nonlinearity``,
``channel_gain``) keep K the system gain when the model already has an effect on the shot term
(``charge_crosstalk``: a flat's shot variance is ``K f x`` with ``f = (1 - 4c)^2 + 4c^2``).

Noise-free PTC points are built from the closed forms (the charge-sharing variance factor; the
quadratic response ``y = x + c x^2 / s`` and its delta-method variance), not from the code under test.
"""

import numpy as np
import pytest

from simcam.calibration import diagnostics as dg
from simcam.calibration.effects import FitContext, card_for
from simcam.calibration.model import LoopModel, shot_factors

BLACK, WHITE = 256.0, 4095.0
S = WHITE - BLACK
K_TRUE, READ = 0.5, 2.0
C_SHARE = 0.05
F_SHARE = (1 - 4 * C_SHARE) ** 2 + 4 * C_SHARE ** 2


class PTC:
    """Stands in for the capture statistics: these fits read only the photon-transfer points."""

    def __init__(self, darks, flats):
        self._p = (darks, flats)
        self.cache = {}

    def ptc_points(self):
        return self._p

    def ptc_dof(self):  # every point from 16 frames of 64x64 per plane
        return tuple(np.full(len(points), 15.0 * 64 * 64) for points in self._p)

    flat_levels = dg.CaptureData.flat_levels  # (reads ptc_points only)


def model_with_sharing(K):
    return LoopModel("RGGB", np.full((2, 2), BLACK), WHITE, K, READ, READ ** 2 + 1 / 12,
                     effects={"charge_crosstalk": {"c": C_SHARE}})


def test_shot_factor_is_the_charge_sharing_variance_factor():
    m = model_with_sharing(K_TRUE)
    f = shot_factors(m, np.array([[400.0] * 4, [1800.0] * 4]))
    np.testing.assert_allclose(f, F_SHARE, rtol=1e-6)
    bare = LoopModel("RGGB", np.full((2, 2), BLACK), WHITE, K_TRUE, READ, READ ** 2 + 1 / 12)
    np.testing.assert_allclose(shot_factors(bare, np.array([[400.0] * 4])), 1.0, rtol=1e-9)


@pytest.mark.parametrize("c_nl", [-0.08, 0.05])
def test_nonlinearity_fit_beside_charge_sharing_keeps_the_system_gain(c_nl):
    r = READ ** 2 + 1 / 12
    darks = [np.column_stack([np.full(4, BLACK), np.full(4, r)])]
    flats = []
    for x in (0.15 * S, 0.35 * S, 0.55 * S):  # linear signal (DN above black)
        y = x + c_nl * x * x / S
        v = (1 + 2 * c_nl * x / S) ** 2 * (K_TRUE * F_SHARE * x + r)
        flats.append(np.column_stack([np.full(4, BLACK + y), np.full(4, v)]))
    model = model_with_sharing(1.3 * K_TRUE)  # the current K is off: the fit re-estimates it
    model.var_dark_dn2 = r
    fit = card_for("nonlinearity").fit(PTC(darks, flats), model, FitContext(diagnostic="ptc_curvature", value=0.0,
                                                                            sim_mean=0.0, shot_factors=shot_factors))
    assert fit.K == pytest.approx(K_TRUE, rel=1e-3)
    assert fit.params.c == pytest.approx(c_nl, abs=1e-3)


def test_channel_gain_fit_beside_charge_sharing_keeps_the_system_gain():
    r = READ ** 2 + 1 / 12
    g = np.array([1.05, 1.0, 0.98, 0.97])
    g = g / g.mean()
    darks = [np.column_stack([np.full(4, BLACK), np.full(4, r)])]
    # site c's mean is x g_c above black, its shot variance K g_c times that mean times the sharing factor
    flats = [np.column_stack([BLACK + x * g, K_TRUE * F_SHARE * g * (x * g) + r]) for x in (0.2 * S, 0.6 * S)]
    model = model_with_sharing(K_TRUE)
    fit = card_for("channel_gain").fit(PTC(darks, flats), model, FitContext(diagnostic="plane_gain_spread",
                                                                            value=0.0, sim_mean=0.0,
                                                                            shot_factors=shot_factors))
    assert fit.K == pytest.approx(K_TRUE, rel=1e-3)
    np.testing.assert_allclose(fit.params.gains, g, rtol=1e-3)
