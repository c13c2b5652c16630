"""The photon-transfer curvature under a coarse ADC whose darks sit inside one code.

The capture sets are made here with numpy: a linear sensor (Poisson photo-electrons, Gaussian read
noise), an ADC of 10-DN codes (in one test with its transition levels displaced at random: a differential
non-linearity), the black level in the middle of a code. The darks then show no temporal variance at all,
while the flats, spread over a few codes, carry the extra variance of the uneven code widths: a quadratic
through the dark point and two flat levels bends although the response is linear, which is how an
independent simulator's quantisation + DNL set was once read as a non-linearity.
"""

import numpy as np
import pytest

from simcam.calibration import diagnostics as dg

BLACK, WHITE, STEP, K, READ = 260.0, 4095.0, 10.0, 0.32, 0.6
SHAPE, N = (48, 64), 16


def _adc(v: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Code ``k`` (value ``k * STEP``) for ``edges[k-1] <= v < edges[k]``."""
    return (np.searchsorted(edges, v.ravel(), side="right").reshape(v.shape) * STEP).astype(np.float32)


def _edges(dnl: float, rng) -> np.ndarray:
    k = np.arange(int(WHITE / STEP) + 2, dtype=np.float64)
    e = (k + 0.5 + rng.uniform(-dnl, dnl, k.size)) * STEP
    e[26] = 26.5 * STEP  # the black level's code (260 DN) keeps its edges: the darks stay inside it
    e[25] = 25.5 * STEP
    return np.maximum.accumulate(e)


def _capture(levels_e, *, dnl: float, read: float = READ, step_edges: bool = True, seed: int = 0):
    rng = np.random.default_rng(seed)
    edges = _edges(dnl, rng) if step_edges else None

    def frames(level_e):
        e = rng.poisson(level_e, (N, *SHAPE)) if level_e else 0.0
        v = BLACK + K * e + rng.normal(0.0, read, (N, *SHAPE))
        return _adc(v, edges) if edges is not None else np.round(v).astype(np.float32)

    return dg.CaptureData([frames(0.0)], [frames(x) for x in levels_e], [], np.full((2, 2), BLACK), WHITE, "RGGB")


def _curvature(d, with_darks: bool) -> float:
    """The curvature (quadratic coefficient times the highest level over the linear one, per plane, averaged)
    of variance against the mean above the darks' mean, through the dark point and every flat or through
    the flats alone: an independent transcription of ptc_curvature's docstring."""
    darks, flats = d.ptc_points()
    pts = np.array(darks + flats if with_darks else flats)
    mu0 = darks[0][:, 0]
    out = []
    for c in range(4):
        x, y = pts[:, c, 0] - mu0[c], pts[:, c, 1]
        c2, c1, _ = np.polyfit(x, y, 2)
        out.append(c2 * x.max() / c1)
    return float(np.mean(out))


def _three_point_curvature(d) -> float:
    return _curvature(d, with_darks=True)


def test_darks_inside_one_code_bend_the_curve_of_a_linear_sensor():
    """Even with even code widths the dark point (variance 0) lies off the flats' line (intercept
    read^2 + step^2/12): with it the linear sensor's curve bends; from three flat levels alone it does not.
    Tolerances: 4 standard errors of the mean over 8 sensors drawn here."""
    with_darks, flats_only = [], []
    for s in range(8):
        d = _capture([1500.0, 4000.0, 8000.0], dnl=0.0, seed=s)
        with_darks.append(_three_point_curvature(d))
        flats_only.append(dg.ptc_curvature(d))
    se = lambda v: np.std(v, ddof=1) / np.sqrt(len(v))  # noqa: E731
    assert np.mean(with_darks) < -4 * se(with_darks)
    assert abs(np.mean(flats_only)) < 4 * se(flats_only)


def test_two_flat_levels_and_darks_inside_one_code_are_not_applicable():
    d = _capture([2500.0, 7000.0], dnl=0.3)
    darks, _ = d.ptc_points()
    assert np.all(np.array(darks)[..., 1] == 0.0)  # every dark value on the black level's code
    with pytest.raises(dg.NotApplicable, match="quantisation-limited"):
        dg.ptc_curvature(d)


def test_darks_spread_over_codes_still_count():
    """A 1-DN ADC with a 1.5-DN read noise: the dark point is a point of the curve, as before."""
    d = _capture([2500.0, 7000.0], dnl=0.0, read=1.5, step_edges=False)
    assert dg.ptc_curvature(d) == pytest.approx(_three_point_curvature(d), rel=1e-9, abs=1e-12)


def _flats_only_curvature(d) -> float:
    return _curvature(d, with_darks=False)


def test_quantisation_limited_darks_above_one_twelfth_of_a_step_squared():
    """Darks over three codes (read noise 0.33 step) but under EMVA 1288's 0.24 DN^2 floor in units of the code
    width (~0.12 step^2, above step^2/12 = 0.083): their variance is set by where the code edges lie, so
    they are not a point of the curve. Two flat levels: not applicable; three: the flats' curvature."""
    for seed in range(3):
        rng = np.random.default_rng(seed)
        edges = _edges(0.3, rng)

        def frames(level_e, rng=rng, edges=edges):
            e = rng.poisson(level_e, (N, *SHAPE)) if level_e else 0.0
            return _adc(BLACK + K * e + rng.normal(0.0, 3.3, (N, *SHAPE)), edges)

        dark = frames(0.0)
        two = dg.CaptureData([dark], [frames(2500.0), frames(7000.0)], [], np.full((2, 2), BLACK), WHITE, "RGGB")
        dv = np.mean(np.array(two.ptc_points()[0])[..., 1]) / STEP ** 2
        assert 1.0 / 12.0 < dv < 0.24, dv
        with pytest.raises(dg.NotApplicable, match="quantisation-limited"):
            dg.ptc_curvature(two)
        three = dg.CaptureData([dark], [frames(x) for x in (1500.0, 4000.0, 8000.0)], [], np.full((2, 2), BLACK),
                               WHITE, "RGGB")
        assert dg.ptc_curvature(three) == pytest.approx(_flats_only_curvature(three), rel=1e-9, abs=1e-12)


def test_darks_at_half_a_code_of_read_noise_count():
    """Read noise 0.55 step (dark variance ~0.38 step^2, above the floor): the dark point is a point of the
    curve, on a coarse ADC too."""
    d = _capture([2500.0, 7000.0], dnl=0.0, read=5.5)
    dv = np.mean(np.array(d.ptc_points()[0])[..., 1]) / STEP ** 2
    assert dv > 0.24, dv
    assert dg.ptc_curvature(d) == pytest.approx(_three_point_curvature(d), rel=1e-9, abs=1e-12)
