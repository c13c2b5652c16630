"""The held-out KLs' one-pass histogram against ``np.histogram`` (the reference)."""

import numpy as np
import pytest

from simcam.calibration.binning import hist_uniform
from simcam.calibration.heldout import KL_EDGES


@pytest.mark.parametrize("scale", [1.0, 0.37, 41.0])
def test_counts_are_numpys_on_open_and_closed_outer_bins(scale):
    rng = np.random.default_rng(int(scale * 100))
    x = rng.standard_t(3, (6, 40, 50)) * 0.03
    x[0, 0, :4] = [np.inf, -np.inf, np.nan, 5000.0]
    open_edges = np.concatenate([[-np.inf], np.linspace(-0.05, 0.08, 25), [np.inf]])
    for edges in (open_edges, KL_EDGES):
        want = np.histogram(x.ravel() * scale, edges)[0]
        assert np.array_equal(hist_uniform(x, edges, scale), want)
    # a strided CFA plane read in place, and counts added to ``out``
    plane = x[:, 1::2, 0::2]
    out = hist_uniform(plane, open_edges, scale)
    hist_uniform(plane[0], open_edges, scale, out)
    want = np.histogram(plane.ravel() * scale, open_edges)[0] + np.histogram(plane[0].ravel() * scale, open_edges)[0]
    assert np.array_equal(out, want)


def test_values_outside_the_closed_outer_edges_are_not_counted():
    got = hist_uniform(np.array([-1000.0, -1000.5, 999.0, 1000.0, 1000.5]), KL_EDGES)
    assert got[0] == 1 and got[-1] == 2 and got.sum() == 3
