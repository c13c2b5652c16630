"""Random-telegraph pixels are not read off darks that sit inside one ADC code.

The darks are made here with numpy. Under a 4-DN ADC with a 0.55-DN read noise and the black level on a
code, almost every value is that code; a pixel whose analogue level lies a little closer to an edge steps
to the next code now and then, four DN and many read-noise sigmas away, which looked like a telegraph
pixel's second level (an independent simulator's quantisation + DNL set got ``rtn`` that way). Under a
1-DN ADC real two-level pixels are still found.
"""

import numpy as np
import pytest

from simcam.calibration import diagnostics as dg

BLACK, WHITE = 256.0, 4095.0
SHAPE, N = (64, 96), 32


def _darks(step: float, read: float, rtn_pixels: int = 0, seed: int = 0) -> dg.CaptureData:
    rng = np.random.default_rng(seed)
    offset = rng.normal(0.0, 0.6, SHAPE)  # a small DSNU: some pixels nearer the code edges than others
    v = BLACK + offset + rng.normal(0.0, read, (N, *SHAPE))
    if rtn_pixels:
        idx = rng.choice(v[0].size, rtn_pixels, replace=False)
        high = rng.random((N, rtn_pixels)) < 0.4
        v.reshape(N, -1)[:, idx] += 20.0 * high
    flat = BLACK + 0.3 * rng.poisson(3000.0, (4, *SHAPE)) + rng.normal(0.0, read, (4, *SHAPE))

    def adc(a):
        return (np.floor(a / step + 0.5) * step).astype(np.float32)

    # the flat spreads over many codes: the ADC's lattice is read off it where the darks show one code
    return dg.CaptureData([adc(v)], [adc(flat)], [], np.full((2, 2), BLACK), WHITE, "RGGB")


def test_darks_inside_one_code_have_no_telegraph_statistic():
    d = _darks(step=4.0, read=0.55)
    assert dg.adc_step(d) == 4.0
    on_black = float(np.mean(d.darks[0] == BLACK))
    assert 0.9 < on_black < 1.0  # nearly all on the black level's code, some on the next ones
    with pytest.raises(dg.NotApplicable, match="inside one ADC code"):
        dg.telegraph_split(d)
    value, reason = dg.statistic("telegraph_pixels", d)
    assert value is None and "inside one ADC code" in reason


def test_two_level_pixels_are_still_found_under_a_fine_adc():
    """60 pixels switching by 20 DN (10 read-noise sigmas) in 40 % of the frames: at least 90 % of them are
    flagged, and at most 1 % of the others."""
    d = _darks(step=1.0, read=2.0, rtn_pixels=60)
    share = dg.telegraph_pixels(d)
    n = SHAPE[0] * SHAPE[1]
    assert 0.9 * 60 / n <= share <= (60 + 0.01 * n) / n
