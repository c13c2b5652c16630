"""PRNU beside charge crosstalk: the photo-electrons are shared with the adjacent pixels before read-out,
``(1 - 4c) q_p + c (4 adjacent q)``, and with them the photo-response pattern, so a flat's fixed-pattern
variance is ``f sigma^2``, ``f = (1 - 4c)^2 + 4c^2`` (A. Abdelhamed, *Noise Modelling for Smartphone
Cameras*, PhD dissertation, York University, 2020, ch. 2, crosstalk). The ``prnu`` card divides it out
when the model has the crosstalk, so the noise stage (PRNU, then the sharing) makes the measured spread.

The flats are made here with numpy, not with simcam's noise code or the loop's generators.
"""

import numpy as np
import pytest

from simcam.calibration import diagnostics as dg
from simcam.calibration.effects import CARDS, FitContext
from simcam.calibration.effects.charge_crosstalk import ChargeCrosstalk, variance_factor
from simcam.calibration.model import LoopModel

H, W, N = 128, 128, 8
K, READ, BLACK, SIGNAL_E = 0.5, 2.0, 64.0, 4000.0
SIGMA, C = 0.02, 0.04


def _share(q: np.ndarray, c: float) -> np.ndarray:
    """(1 - 4c) q + c (sum of the 4 adjacent pixels), rows/columns reflected at the borders."""
    p = np.pad(q, [(0, 0)] * (q.ndim - 2) + [(1, 1), (1, 1)], mode="reflect")
    adj = p[..., :-2, 1:-1] + p[..., 2:, 1:-1] + p[..., 1:-1, :-2] + p[..., 1:-1, 2:]
    return (1 - 4 * c) * q + c * adj


def _capture(seed: int = 5) -> dg.CaptureData:
    rng = np.random.default_rng(seed)
    n = rng.normal(0.0, SIGMA, (H, W))
    electrons = rng.poisson(np.broadcast_to(SIGNAL_E * (1 + n), (N, H, W))).astype(np.float64)
    flat = np.round(BLACK + K * _share(electrons, C) + rng.normal(0.0, READ, (N, H, W)))
    dark = np.round(BLACK + rng.normal(0.0, READ, (N, H, W)))
    return dg.CaptureData([dark], [flat], [], np.full((2, 2), BLACK), 4095.0, "RGGB")


def _model(with_crosstalk: bool) -> LoopModel:
    m = LoopModel("RGGB", np.full((2, 2), BLACK), 4095.0, K, READ, READ ** 2 + 1 / 12)
    return m.with_effect("charge_crosstalk", ChargeCrosstalk(c=C)) if with_crosstalk else m


def test_prnu_fitted_beside_charge_crosstalk_is_the_pattern_before_the_sharing():
    d = _capture()
    with_x = CARDS["prnu"].fit(d, _model(True), FitContext()).sigma
    without = CARDS["prnu"].fit(d, _model(False), FitContext()).sigma
    # the sample SD of H W normals is within 3 sqrt(1 / (2 H W)) ~ 1.9 % of sigma; the even/odd-frame
    # covariance adds the shot noise's share (~ sqrt(2 / (H W)) var_shot / (N/2) / (sigma^2 S^2)): ~1 %
    assert with_x == pytest.approx(SIGMA, rel=0.04)
    assert without == pytest.approx(SIGMA * np.sqrt(variance_factor(C)), rel=0.04)  # 15.6 % lower
    assert with_x / without == pytest.approx(1 / np.sqrt(variance_factor(C)), rel=1e-9)
