"""Per-pixel statistics over frames of the residual battery as numba kernels: the two-level split of a
pixel's series, its median, and a running median over a window of the map.

Two-level split (the 1-D 2-means that finds random-telegraph pixels)
--------------------------------------------------------------------

A random-telegraph (RTN) pixel switches between two discrete levels from frame to frame (a charge
trap in the source-follower gate filling and emptying; J. Janesick, *Scientific Charge-Coupled
Devices*, SPIE 2001, ch. 5; A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD
dissertation, York University, 2020, ch. 2). Sorting one pixel's ``n`` values and trying every cut
into a low level of ``k`` and a high level of ``n - k`` values gives the split with the least
within-level sum of squares (optimal 1-D 2-means, since the levels of an optimal split are
contiguous in sorted order).

Medians
-------
:func:`temporal_median` equals ``np.median(x, axis=0)`` and :func:`median_box` scipy's
``median_filter(..., mode="nearest")`` (the same order statistics, bit for bit;
tests/calibration/test_pixelwise.py); :func:`two_level_split` gives the bits of the numpy version it
replaced (the same additions in the same order).

Why kernels: the loop computes the whole battery on every bootstrap and held-out replicate (a few
hundred per ISO); ``benchmarks/pixelwise.py`` times each kernel against its numpy form (16 frames x
196 k pixels, AMD EPYC: median 60 ms against 90 ms, two-level split 80 ms against 190-290 ms).
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: a random-telegraph pixel's two levels are at least this many read-noise sigma apart ...
RTN_GAP_SIGMA = 5.0
#: ... and each is about as tight as the read noise: pooled within-level variance <= this x the read variance
RTN_LEVEL_VAR = 2.0


@njit(cache=True, nogil=True)
def _insert(buf, k, x):
    """Insert ``x`` into the sorted ``buf[:k]`` (insertion sort step)."""
    t = k
    while t > 0 and buf[t - 1] > x:
        buf[t] = buf[t - 1]
        t -= 1
    buf[t] = x


@njit(cache=True, nogil=True)
def _split(v, min_levels):
    """``v``: (pixels, n) C-contiguous, one pixel's series per row; the best split for each least level
    size in ``min_levels`` (one sort per pixel for all of them). Returns (L, pixels) arrays."""
    m, n = v.shape
    nl = min_levels.size
    best_w = np.full((nl, m), np.inf)
    gap = np.zeros((nl, m))
    high = np.zeros((nl, m), np.int64)
    s = np.empty(n)
    cs = np.empty(n)
    cs2 = np.empty(n)
    for j in range(m):
        for i in range(n):  # insertion sort: n is a few tens of frames
            _insert(s, i, v[j, i])
        a = 0.0
        a2 = 0.0
        for i in range(n):
            a += s[i]
            a2 += s[i] * s[i]
            cs[i] = a
            cs2[i] = a2
        tot, tot2 = cs[n - 1], cs2[n - 1]
        for k in range(1, n):
            a, a2 = cs[k - 1], cs2[k - 1]
            b, b2 = tot - a, tot2 - a2
            w = (a2 - a * a / k) + (b2 - b * b / (n - k))
            for q in range(nl):
                if min_levels[q] <= k <= n - min_levels[q] and w < best_w[q, j]:
                    best_w[q, j] = w
                    gap[q, j] = b / (n - k) - a / k
                    high[q, j] = n - k
    return best_w, gap, high


@njit(cache=True, nogil=True)
def _temporal_median(v):
    m, n = v.shape
    out = np.empty(m)
    buf = np.empty(n)
    h = n // 2
    for j in range(m):
        for i in range(n):
            _insert(buf, i, v[j, i])
        out[j] = buf[h] if n % 2 else (buf[h - 1] + buf[h]) / 2.0
    return out


def temporal_median(x: np.ndarray) -> np.ndarray:
    """Median over the first axis (frames) of ``x`` (n, H, W), float64: ``np.median(x, axis=0)``."""
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[0]
    return _temporal_median(np.ascontiguousarray(x.reshape(n, -1).T)).reshape(x.shape[1:])


def batcher_network(n: int) -> list[tuple[int, int]]:
    """The comparators ``(i, j)``, i < j, of Batcher's odd-even merge sort of ``n`` values (a power of two),
    in order: after each, position i holds the smaller value (K. E. Batcher, "Sorting networks and their
    applications", AFIPS Spring Joint Computer Conference 1968; D. E. Knuth, *The Art of Computer
    Programming* vol. 3, sec. 5.3.4)."""
    out = []
    p = 1
    while p < n:
        k = p
        while k >= 1:
            for j in range(k % p, n - k, 2 * k):
                for i in range(min(k, n - j - k)):
                    if (i + j) // (2 * p) == (i + j + k) // (2 * p):
                        out.append((i + j, i + j + k))
            k //= 2
        p *= 2
    return out


def selection_network(m: int, kth: int) -> np.ndarray:
    """(comparators, 2) of a network that puts the ``kth`` smallest of ``m`` values at position ``kth``:
    Batcher's network for the next power of two, less the comparators that touch the padding (``+inf``
    values above position ``m - 1``, which no comparator moves) and those that cannot reach position
    ``kth`` (113 of 191 for the median of 25)."""
    n = 1
    while n < m:
        n *= 2
    net = [(a, b) for a, b in batcher_network(n) if b < m]
    need, keep = {kth}, []
    for a, b in reversed(net):
        if a in need or b in need:
            keep.append((a, b))
            need |= {a, b}
    return np.array(keep[::-1], dtype=np.int64).reshape(-1, 2)


_NETWORKS: dict[int, np.ndarray] = {}


@njit(cache=True, nogil=True)
def _median_box(p, r, pairs):
    h, w = p.shape
    k = 2 * r + 1
    out = np.empty((h, w))
    st = np.empty((k * k, w))  # one output row's windows, value c of every window in row c
    for i in range(h):
        c = 0
        for di in range(-r, r + 1):
            ii = min(max(i + di, 0), h - 1)
            for dj in range(-r, r + 1):
                for j in range(w):
                    st[c, j] = p[ii, min(max(j + dj, 0), w - 1)]
                c += 1
        for q in range(pairs.shape[0]):  # branch-free compare-exchanges along the row (vectorised)
            a = pairs[q, 0]
            b = pairs[q, 1]
            for t in range(w):
                u = st[a, t]
                v = st[b, t]
                st[a, t] = min(u, v)
                st[b, t] = max(u, v)
        out[i] = st[k * k // 2]
    return out


def median_box(p: np.ndarray, size: int = 5) -> np.ndarray:
    """Running median of ``p`` (H, W) over ``size`` x ``size`` windows (odd ``size``), edges extended by
    their nearest value: ``scipy.ndimage.median_filter(p, size=size, mode="nearest")`` (the same order
    statistic, bit for bit; tests/calibration/test_pixelwise.py), as float64, without NaNs. Each window's
    median comes out of a selection network (:func:`selection_network`) applied to a whole row of windows
    at once: 2.8 ms against scipy's 24 ms for a 192 x 256 map at size 5 (``benchmarks/pixelwise.py``)."""
    if size % 2 != 1:
        raise ValueError(f"median_box: size must be odd, got {size}")
    m = size * size
    if m not in _NETWORKS:
        _NETWORKS[m] = selection_network(m, m // 2)
    return _median_box(np.ascontiguousarray(p, dtype=np.float64), size // 2, _NETWORKS[m])


def two_level_split(v: np.ndarray, sigma2: float, min_level: int = 2, gap_sigma: float = RTN_GAP_SIGMA,
                    level_var: float = RTN_LEVEL_VAR) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per column of ``v`` (the n values of one pixel over frames, n >= 2 ``min_level``): the split of its
    sorted values into a low and a high level of >= ``min_level`` values each with the least
    within-level sum of squares (1-D 2-means), as (two-level mask, gap between the level means,
    number of values on the high level).
    Two-level: the gap is >= ``gap_sigma`` x sqrt(``sigma2``) and the pooled within-level variance
    <= ``level_var`` x ``sigma2`` (a pixel with a wide unimodal spread, such as a hot
    pixel's dark-charge shot noise, has a gap too, but wide levels; one heavy-tailed outlier is one frame)."""
    return two_level_splits(v, sigma2, [(min_level, gap_sigma, level_var)])[0]


def two_level_splits(v: np.ndarray, sigma2: float, rules) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """:func:`two_level_split` for several ``(min_level, gap_sigma, level_var)`` rules at once (each
    pixel's series sorted once for all of them)."""
    v = np.asarray(v, dtype=np.float64)
    shape = v.shape[1:]
    n = v.shape[0]
    levels = np.array([int(r[0]) for r in rules], np.int64)
    best_w, gap, high = _split(np.ascontiguousarray(v.reshape(n, -1).T), levels)
    out = []
    for q, (_lvl, gap_sigma, level_var) in enumerate(rules):
        mask = (gap[q] >= gap_sigma * np.sqrt(sigma2)) & (best_w[q] / max(n - 2, 1) <= level_var * sigma2)
        out.append((mask.reshape(shape), gap[q].reshape(shape), high[q].reshape(shape)))
    return out
