"""Intensity alignment of a burst (Abdelhamed 2020, section 5.3.2, eq. 5.4).

Frames whose mean lies outside the central ``confidence`` interval of the
distribution of frame means are dropped; the rest are shifted to the common mean.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from ..errors import DatasetError


@dataclass
class IntensityOutliers:
    """Frame-mean statistics: which frames are kept and the common mean ``mu_a``."""

    means: np.ndarray
    keep: np.ndarray
    mu_a: float
    sigma_a: float
    z: np.ndarray
    limit: float

    def summary(self) -> dict:
        return {"mu_a": self.mu_a, "sigma_a": self.sigma_a, "z_limit": self.limit,
                "dropped": [int(i) for i in np.nonzero(~self.keep)[0]],
                "dropped_z": [float(v) for v in self.z[~self.keep]]}


def frame_outliers(means: np.ndarray, *, confidence: float = 0.999, robust: bool = True) -> IntensityOutliers:
    """Flag frames whose mean lies outside the central ``confidence`` interval.

    Parameters
    ----------
    means : ndarray, (N,)
        Mean intensity of each frame (normalised raw).
    confidence : float
        Abdelhamed 2020 (section 5.3.2): 0.999, i.e. |mu_i - mu_a| > 3.29 sigma_a drops frame i.
    robust : bool
        Estimate the centre and spread by median and 1.4826 MAD instead of the
        dissertation's mean and standard deviation. With the plain estimates one outlier
        among N <= 12 frames can never exceed 3.29 sigma (its z is at most
        (N-1)/sqrt(N)), so the robust form is the default.

    ``mu_a`` is recomputed over the kept frames (Abdelhamed 2020: "re-calculate mu_a").

    Returns
    -------
    IntensityOutliers
        ``keep`` (bool per frame), the common mean ``mu_a``, spread ``sigma_a``, ``z`` and the limit.

    Examples
    --------
    >>> import numpy as np
    >>> out = frame_outliers(np.array([0.5, 0.5, 0.51, 0.49, 0.8, 0.5]))
    >>> out.keep.tolist(), out.mu_a
    ([True, True, True, True, False, True], 0.5)
    """
    m = np.asarray(means, dtype=np.float64)
    if m.ndim != 1 or m.size < 1 or not np.all(np.isfinite(m)):
        raise DatasetError(f"intensity alignment: frame means: expected finite values, got {m!r}")
    if robust:
        c = float(np.median(m))
        s = float(1.482602218505602 * np.median(np.abs(m - c)))
        if s == 0.0:
            s = float(np.std(m))
    else:
        c, s = float(m.mean()), float(m.std(ddof=1)) if m.size > 1 else 0.0
    limit = float(special.ndtri(0.5 + confidence / 2.0))
    z = (m - c) / s if s > 0 else np.zeros_like(m)
    keep = np.abs(z) <= limit
    mu_a = float(m[keep].mean()) if keep.any() else c
    return IntensityOutliers(m, keep, mu_a, s, z, limit)


def align_intensity(frame: np.ndarray, mu_i: float, mu_a: float, mode: str = "additive") -> np.ndarray:
    """Shift a frame to the common mean: additive ``x - mu_i + mu_a`` (eq. 5.4) or multiplicative ``x mu_a / mu_i``.

    Parameters
    ----------
    frame : ndarray
        One frame (normalised raw).
    mu_i, mu_a : float
        Its mean and the common mean of the kept frames.
    mode : {"additive", "multiplicative", "none"}
        How the frame is brought to ``mu_a``.

    Returns
    -------
    ndarray
        float32 frame with mean ``mu_a``.

    See Also
    --------
    frame_outliers : the common mean ``mu_a`` and the frames kept.

    Examples
    --------
    >>> align_intensity(np.full((2, 2), 0.4, np.float32), 0.4, 0.5, "multiplicative").tolist()
    [[0.5, 0.5], [0.5, 0.5]]
    """
    if mode == "additive":
        return (frame + np.float32(mu_a - mu_i)).astype(np.float32, copy=False)
    if mode == "multiplicative":
        if mu_i == 0:
            raise DatasetError("intensity alignment: multiplicative mode needs frame means != 0")
        return (frame * np.float32(mu_a / mu_i)).astype(np.float32, copy=False)
    if mode == "none":
        return frame
    raise DatasetError(f"intensity alignment: mode: expected additive, multiplicative or none, got {mode!r}")
