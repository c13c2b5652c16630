"""The read noise under a coarse quantiser without dither: measured through the quantiser, not by
subtracting step^2 / 12 (Sheppard's correction, which holds only when the signal before the ADC spans
many codes). The capture set is made here with numpy (mid-tread quantiser of step 10 DN on a Gaussian
read noise, Poisson photo-electrons), not with simcam's noise code."""

import numpy as np
import pytest

from simcam.calibration.capture import CaptureSet, Sequence
from simcam.calibration.effects import FitContext
from simcam.calibration.effects.quantization import dark_temporal_variance
from simcam.calibration.fit import base_fit, fit_effect
from simcam.calibration.loop import Group, LoopConfig
from simcam.calibration.simulate import simulate_capture

BLACK, WHITE, STEP, K = 256.0, 4095.0, 10.0, 0.32


def _quantise(v):
    return np.floor(v / STEP + 0.5) * STEP


def _capture(read_dn: float, seed: int = 0) -> CaptureSet:
    rng = np.random.default_rng(seed)
    shape, n = (48, 64), 8
    seqs = []
    for name, exposure, level_e in (("dark_a", 0.02, 0.0), ("dark_b", 2.0, 0.0), ("flat_lo", 0.02, 2500.0),
                                    ("flat_hi", 0.02, 7000.0)):
        e = rng.poisson(level_e, (n, *shape)) if level_e else 0.0
        fr = _quantise(BLACK + K * e + rng.normal(0.0, read_dn, (n, *shape))).astype(np.float32)
        kind = "dark" if name.startswith("dark") else "flat"
        seqs.append(Sequence(name, kind, fr, 100, exposure, "RGGB", np.full((2, 2), BLACK), WHITE))
    return CaptureSet("memory", "directory", seqs)


@pytest.mark.parametrize("read_dn", [0.6, 0.9, 1.5])
def test_quantizer_fit_recovers_the_read_noise_below_the_step(read_dn):
    g = Group(_capture(read_dn).group(100), LoopConfig(), [])
    base = base_fit(g.fit_data)
    ctx = FitContext(diagnostic="code_occupancy", seed=1, simulate=simulate_capture,
                     dark_specs=[sp for sp in g.specs(base, g.fit) if sp.kind == "dark"])
    m = fit_effect("quantization", g.fit_data, base, ctx)
    assert m.q == STEP
    # the additive bookkeeping, read backwards from the dark variance, is far off (closed form below)
    naive = np.sqrt(max(dark_temporal_variance(g.fit_data.darks) - STEP ** 2 / 12, 0.0))
    # tolerance: the dark variance of 2 x 4 frames x 3072 pixels has a relative SE of ~1 %; through the
    # quantiser's steep response near 1 DN that is a few % of the read noise, the grid interpolation 2 %
    assert m.read_dn == pytest.approx(read_dn, rel=0.08)
    assert abs(naive - read_dn) > 3 * abs(m.read_dn - read_dn)


def test_closed_form_dark_variance_of_the_quantised_gaussian():
    """The statistic the fit matches, on the darks above, against its closed form: every pixel at 256 DN,
    codes 250 and 260 (and rarely 240, 270), P(code) from the normal law of the read noise; tolerance 4
    standard errors of the mean of the per-pixel variances (pixels independent)."""
    from scipy.stats import norm

    read = 0.9
    darks = [s.frames for s in _capture(read, seed=4).sequences if s.kind == "dark"]
    codes = np.arange(200.0, 320.0, STEP)
    p = norm.cdf((codes + STEP / 2 - BLACK) / read) - norm.cdf((codes - STEP / 2 - BLACK) / read)
    var = float(np.sum(p * codes ** 2) - np.sum(p * codes) ** 2)
    per_pixel = np.concatenate([np.var(a, axis=0, ddof=1).ravel() for a in darks])
    se = per_pixel.std() / np.sqrt(per_pixel.size)
    assert abs(dark_temporal_variance(darks) - var) < 4 * se
