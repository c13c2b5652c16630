"""Image-quality metrics: PSNR and SSIM with an explicit data range.

Conventions (those of the SIDD benchmark, Abdelhamed 2020, section s 5.4 and 7.2):

* **raw** blocks are compared as one 2-D image (the Bayer mosaic, normalised
  raw), ``data_range=1.0``; the score of a set is the mean of per-block scores.
* **sRGB** blocks are H x W x 3 in [0, 1] (``data_range=1.0``), SSIM is the
  mean of the per-channel SSIMs (scikit-image ``channel_axis=-1``).
* SSIM uses the Gaussian window of Wang et al. 2004 (sigma 1.5, 11 taps,
  population covariance, K1=0.01, K2=0.03) and averages the SSIM map after
  cropping the 5-pixel border, exactly like
  ``skimage.metrics.structural_similarity(ref, x, data_range=..., gaussian_weights=True,
  sigma=1.5, use_sample_covariance=False[, channel_axis=-1])``.
  ``window="uniform"`` gives scikit-image's default (7x7 box, sample covariance).

Everything is computed in float64. Reference: Z. Wang et al., "Image quality
assessment: from error visibility to structural similarity", IEEE TIP 2004,
doi:10.1109/TIP.2003.819861.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from scipy import ndimage

from ..errors import DatasetError


class MetricError(DatasetError):
    """Inputs of a metric are inconsistent (shape, range)."""


def _check_pair(ref: np.ndarray, test: np.ndarray, data_range: float, what: str) -> tuple[np.ndarray, np.ndarray]:
    ref = np.asarray(ref)
    test = np.asarray(test)
    if ref.shape != test.shape:
        raise MetricError(f"{what}: reference shape {ref.shape} and test shape {test.shape} differ; expected equal shapes")
    if not np.isfinite(data_range) or data_range <= 0:
        raise MetricError(f"{what}: data_range: expected a positive number, got {data_range!r}")
    return ref.astype(np.float64, copy=False), test.astype(np.float64, copy=False)


def mse(ref: np.ndarray, test: np.ndarray) -> float:
    """Mean squared error (float64)."""
    d = np.asarray(ref, dtype=np.float64) - np.asarray(test, dtype=np.float64)
    return float(np.mean(d * d))


def psnr(ref: np.ndarray, test: np.ndarray, *, data_range: float) -> float:
    """Peak signal-to-noise ratio in dB: ``10 log10(data_range^2 / MSE)``.

    Parameters
    ----------
    ref, test : ndarray
        Same shape; ``ref`` is the ground truth.
    data_range : float
        Peak-to-peak range of the signal (1.0 for normalised raw and [0, 1] sRGB).

    Returns
    -------
    float
        dB; ``inf`` for identical inputs.

    Examples
    --------
    >>> import numpy as np
    >>> round(psnr(np.zeros((8, 8)), np.full((8, 8), 0.1), data_range=1.0), 6)  # MSE 0.01
    20.0
    """
    ref, test = _check_pair(ref, test, data_range, "psnr")
    err = mse(ref, test)
    if err == 0:
        return float("inf")
    return float(10.0 * np.log10(data_range**2 / err))


def ssim(ref: np.ndarray, test: np.ndarray, *, data_range: float, channel_axis: int | None = None,
         window: Literal["gaussian", "uniform"] = "gaussian") -> float:
    """Mean structural similarity (Wang et al. 2004) of two images.

    Parameters
    ----------
    ref, test : ndarray
        2-D images, or N-D with ``channel_axis`` naming the colour axis (the
        result is the mean over channels).
    data_range : float
        Peak-to-peak range (sets C1 = (0.01 L)^2, C2 = (0.03 L)^2).
    channel_axis : int, optional
        Axis of colour channels, e.g. -1 for H x W x 3.
    window : {"gaussian", "uniform"}
        ``gaussian``: sigma 1.5, 11 taps, population covariance (Wang et al.);
        ``uniform``: 7x7 box, sample covariance (scikit-image's default).

    Returns
    -------
    float
        Mean SSIM in [-1, 1].
    """
    ref, test = _check_pair(ref, test, data_range, "ssim")
    if channel_axis is not None:
        ref = np.moveaxis(ref, channel_axis, -1)
        test = np.moveaxis(test, channel_axis, -1)
        return float(np.mean([_ssim_2d(ref[..., c], test[..., c], data_range, window)
                              for c in range(ref.shape[-1])]))
    return _ssim_2d(ref, test, data_range, window)


def _ssim_2d(x: np.ndarray, y: np.ndarray, data_range: float, window: str) -> float:
    if window == "gaussian":
        sigma, truncate = 1.5, 3.5
        win = 2 * int(truncate * sigma + 0.5) + 1

        def filt(a):
            return ndimage.gaussian_filter(a, sigma=sigma, truncate=truncate, mode="reflect")

        cov_norm = 1.0
    elif window == "uniform":
        win = 7

        def filt(a):
            return ndimage.uniform_filter(a, size=win, mode="reflect")

        npix = win**x.ndim
        cov_norm = npix / (npix - 1)
    else:
        raise MetricError(f"ssim: window: expected 'gaussian' or 'uniform', got {window!r}")
    if min(x.shape) < win:
        raise MetricError(f"ssim: image shape {x.shape} is smaller than the {win}x{win} window")
    ux, uy = filt(x), filt(y)
    vx = cov_norm * (filt(x * x) - ux * ux)
    vy = cov_norm * (filt(y * y) - uy * uy)
    vxy = cov_norm * (filt(x * y) - ux * uy)
    c1 = (0.01 * data_range) ** 2
    c2 = (0.03 * data_range) ** 2
    s = ((2 * ux * uy + c1) * (2 * vxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2))
    pad = (win - 1) // 2
    crop = tuple(slice(pad, n - pad) for n in s.shape)
    return float(s[crop].mean())
