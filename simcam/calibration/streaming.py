"""One-pass per-pixel accumulators for reading capture sets frame by frame (numba).

Reading a capture set updates, for every frame, a per-pixel sum and sum of squares (the loop's
whole-frame summary, :class:`simcam.calibration.capture.FrameAccumulator`) and per CFA plane a running
mean and sum of squared deviations (Welford's update, B. P. Welford, "Note on a method for calculating
corrected sums of squares and products", Technometrics 4(3), 1962; the EMVA 1288 point statistics,
:class:`simcam.calibration.emva1288.PointAccumulator`). Written with numpy each takes several passes
over the frame and float64 temporaries of its size (0.33 s and 0.11 s per 12 MP frame on the 2-core
AMD EPYC machine, about a fifth of ``simcam loop``'s time on the 12 MP benchmark set); these kernels
read each pixel once, with the same float64 operations in the same order, so the maps are the same
bytes. The frame sums are plain running sums: exact for integer codes (below 2**53), as numpy's
pairwise sums are.
"""

from __future__ import annotations

import numpy as np
from numba import njit


def kernel_input(a: np.ndarray) -> np.ndarray:
    """``a`` as the kernels read it: native-order integers or float32/float64 as they are, anything else
    (big-endian ``.npy`` data, float16, booleans) converted to float64 first."""
    a = np.asarray(a)
    if a.dtype.isnative and (a.dtype.kind in "ui" or a.dtype in (np.float32, np.float64)):
        return a
    return a.astype(np.float64)


@njit(cache=True, nogil=True)
def moments_add(frame, s1, s2, white):
    """``s1 += f``, ``s2 += f * f`` (``f`` the frame in float64); returns (sum of ``f``, pixels >= ``white``)."""
    tot = 0.0
    sat = 0
    for i in range(frame.shape[0]):
        for j in range(frame.shape[1]):
            f = np.float64(frame[i, j])
            s1[i, j] += f
            s2[i, j] += f * f
            tot += f
            if f >= white:
                sat += 1
    return tot, sat


@njit(cache=True, nogil=True)
def welford_add(x, mean, m2, n):
    """Welford's update with the ``n``-th frame's values ``x`` (a plane, strided views read in place):
    ``d = x - mean``, ``mean += d / n``, ``m2 += (x - mean) * d``; returns the sum of ``x``."""
    tot = 0.0
    for i in range(x.shape[0]):
        for j in range(x.shape[1]):
            v = np.float64(x[i, j])
            d = v - mean[i, j]
            mu = mean[i, j] + d / n
            mean[i, j] = mu
            m2[i, j] += (v - mu) * d
            tot += v
    return tot
