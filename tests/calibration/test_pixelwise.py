"""The battery's numba kernels against the numpy forms they replace."""

import numpy as np
import pytest

from scipy.ndimage import median_filter

from simcam.calibration.pixelwise import (batcher_network, median_box, selection_network, temporal_median,
                                          two_level_split, two_level_splits)


@pytest.mark.parametrize("n", [2, 3, 8, 15, 16])
def test_temporal_median_is_numpy_median(n):
    rng = np.random.default_rng(n)
    x = np.round(rng.normal(100, 3, (n, 17, 23)))  # integer codes: many ties
    x[:, 0, 0] = 7.0  # a constant pixel
    assert np.array_equal(temporal_median(x.astype(np.float32)), np.median(x, axis=0))


def _two_level_numpy(v, sigma2, min_level=2, gap_sigma=5.0, level_var=2.0):
    """The closed form written out with numpy: every cut of the sorted series, least within-level SS."""
    n = v.shape[0]
    s = np.sort(v, axis=0)
    best = np.full(v.shape[1:], np.inf)
    gap = np.zeros(v.shape[1:])
    high = np.zeros(v.shape[1:], np.int64)
    for k in range(min_level, n - min_level + 1):
        lo, hi = s[:k], s[k:]
        w = ((lo - lo.mean(0)) ** 2).sum(0) + ((hi - hi.mean(0)) ** 2).sum(0)
        better = w < best
        best = np.where(better, w, best)
        gap = np.where(better, hi.mean(0) - lo.mean(0), gap)
        high = np.where(better, n - k, high)
    mask = (gap >= gap_sigma * np.sqrt(sigma2)) & (best / max(n - 2, 1) <= level_var * sigma2)
    return mask, gap, high


def test_two_level_split_finds_telegraph_pixels():
    rng = np.random.default_rng(5)
    v = rng.normal(0, 1, (16, 4000))
    tele = rng.random(4000) < 0.1
    v[:, tele] += 9.0 * (rng.random((16, tele.sum())) < 0.4)
    mask, gap, high = two_level_split(v, 1.0)
    want = _two_level_numpy(v, 1.0)
    assert np.array_equal(mask, want[0]) and np.allclose(gap, want[1]) and np.array_equal(high, want[2])
    # pixels that did switch (>= 2 frames on each level) are found; white-noise pixels are not
    switched = tele & (np.sum(v > 4.5, axis=0) >= 2) & (np.sum(v > 4.5, axis=0) <= 14)
    assert mask[switched].mean() > 0.95 and mask[~tele].mean() < 0.001


def test_several_rules_at_once_match_each_rule_alone():
    """One sort per pixel for two rules (the strict telegraph rule and the looser one that keeps telegraph
    pixels out of the hot ones): each result is the numpy closed form of its own rule."""
    rng = np.random.default_rng(6)
    v = rng.normal(0, 1, (16, 3000))
    tele = rng.random(3000) < 0.2
    v[:, tele] += 6.0 * (rng.random((16, tele.sum())) < 0.1)  # many pixels with a single frame up
    strict, loose = two_level_splits(v, 1.0, [(2, 5.0, 2.0), (1, 4.0, 3.0)])
    for got, want in ((strict, _two_level_numpy(v, 1.0)), (loose, _two_level_numpy(v, 1.0, 1, 4.0, 3.0))):
        assert np.array_equal(got[0], want[0]) and np.allclose(got[1], want[1]) and np.array_equal(got[2], want[2])
    assert loose[0].sum() > strict[0].sum()  # the single-frame pixels only count for the loose rule


def _apply(net, rows):
    """The comparator network ``net`` applied to each row of ``rows`` (a copy), with numpy."""
    v = rows.copy()
    for a, b in net:
        lo, hi = np.minimum(v[:, a], v[:, b]), np.maximum(v[:, a], v[:, b])
        v[:, a], v[:, b] = lo, hi
    return v


@pytest.mark.parametrize("n", [2, 4, 8, 16, 32])
def test_batcher_network_sorts_every_zero_one_input(n):
    """The 0-1 principle (Knuth, TAOCP vol. 3, sec. 5.3.4, ex. 36): a comparator network sorts every input iff
    it sorts every sequence of 0s and 1s; all 2^n of them for n <= 16, 20 000 random ones for 32."""
    net = batcher_network(n)
    rng = np.random.default_rng(n)
    rows = (np.arange(2 ** n)[:, None] >> np.arange(n)) & 1 if n <= 16 else rng.integers(0, 2, (20000, n))
    assert np.array_equal(_apply(net, rows), np.sort(rows, axis=1))


@pytest.mark.parametrize("m", [9, 25, 49])
def test_selection_network_places_the_median(m):
    rng = np.random.default_rng(m)
    x = np.round(rng.normal(0, 2, (5000, m)))  # ties
    assert np.array_equal(_apply(selection_network(m, m // 2), x)[:, m // 2], np.median(x, axis=1))


@pytest.mark.parametrize("shape", [(64, 80), (7, 9), (1, 5), (6, 1), (2, 2), (1, 1)])
@pytest.mark.parametrize("size", [3, 5, 7])
def test_median_box_is_scipy_median_filter(shape, size):
    rng = np.random.default_rng(size * 100 + shape[0])
    x = rng.normal(0, 1, shape)
    x[rng.random(shape) < 0.3] = 0.5  # ties
    x.flat[0] = 40.0  # an outlier
    ref = median_filter(x, size=size, mode="nearest")
    assert np.array_equal(median_box(x, size), ref)
    assert np.array_equal(median_box(x.astype(np.float32), size), median_filter(x.astype(np.float32), size=size,
                                                                                   mode="nearest").astype(np.float64))


def test_median_box_refuses_an_even_window():
    with pytest.raises(ValueError, match="odd"):
        median_box(np.zeros((4, 4)), 4)
