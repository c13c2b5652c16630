"""Single-image noise estimation (Abdelhamed 2020, section 5.2.2).

* :func:`estimate_nlf` -- the signal-dependent noise level function
  ``var = beta1 * y + beta2`` (Abdelhamed 2020, eq. 5.2) of a normalised raw image with
  clipping to [0, 1] (eq. 5.3), after Foi et al. 2008, "Practical
  Poissonian-Gaussian noise modeling and fitting for single-image raw-data",
  IEEE TIP 17(10), doi:10.1109/TIP.2008.2001399: orthonormal Haar wavelet
  (approximation + diagonal detail), removal of non-smooth regions using the
  approximation only (so the detail variance stays unbiased), level sets of
  equal count, and a maximum-likelihood fit of the *clipped* model
  (expected mean and standard deviation of a clipped normal variable).
* :func:`estimate_sigma` -- the homoscedastic Gaussian sigma after Chen, Zhu
  and Heng 2015, "An efficient statistical method for image noise level
  estimation", ICCV, doi:10.1109/ICCV.2015.62: eigenvalues of the covariance
  of image patches; sigma^2 is the mean of the largest set of smallest
  eigenvalues whose mean equals their median.

Units: normalised raw (or any linear scale; sigma is in the image's units).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage, optimize, special

from ..cfa import pack
from ..errors import DatasetError

_SQRT2 = np.sqrt(2.0)


# --------------------------------------------------------------------------------------
# clipped normal moments (Foi et al. 2008, eqs. 12-13 in closed form)
def clipped_moments(y: np.ndarray, sigma: np.ndarray, lo: float = 0.0, hi: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation of ``clip(y + sigma * xi, lo, hi)``, ``xi ~ N(0, 1)``.

    Parameters
    ----------
    y, sigma : ndarray
        Mean and standard deviation of the unclipped normal (broadcast); sigma > 0.
    lo, hi : float
        Clipping bounds (normalised raw: 0 and 1).

    Returns
    -------
    (mean, std) : tuple of ndarray (float64)
    """
    y = np.asarray(y, dtype=np.float64)
    s = np.maximum(np.asarray(sigma, dtype=np.float64), 1e-300)
    a0, a1 = (lo - y) / s, (hi - y) / s
    phi0, phi1 = np.exp(-0.5 * a0 * a0) / np.sqrt(2 * np.pi), np.exp(-0.5 * a1 * a1) / np.sqrt(2 * np.pi)
    cdf0, cdf1 = special.ndtr(a0), special.ndtr(a1)
    inside = cdf1 - cdf0
    m1 = y * inside + s * (phi0 - phi1) + lo * cdf0 + hi * (1.0 - cdf1)
    m2 = ((y * y + s * s) * inside + 2.0 * y * s * (phi0 - phi1)
          + s * s * (np.where(np.isfinite(a0), a0, 0.0) * phi0 - np.where(np.isfinite(a1), a1, 0.0) * phi1)
          + lo * lo * cdf0 + hi * hi * (1.0 - cdf1))
    var = np.maximum(m2 - m1 * m1, 0.0)
    return m1, np.sqrt(var)


# --------------------------------------------------------------------------------------
@dataclass
class LevelSets:
    """Local estimates of one image: observed mean, detail variance and sample count per level set."""

    mean: np.ndarray
    var: np.ndarray
    count: np.ndarray


@dataclass
class NLFEstimate:
    """Result of :func:`estimate_nlf` (float64 parameters, normalised raw units).

    ``beta1``/``beta2`` are fitted jointly over all CFA planes; ``planes`` holds
    one (beta1, beta2) pair per packed plane (order (0,0), (0,1), (1,0), (1,1))
    when ``per_plane=True`` -- the layout of a DNG NoiseProfile.
    """

    beta1: float
    beta2: float
    planes: np.ndarray | None = None
    levels: LevelSets | None = None
    extra: dict = field(default_factory=dict)

    def sigma_at(self, y: float | np.ndarray) -> np.ndarray:
        """Noise standard deviation ``sqrt(beta1 y + beta2)`` at intensity ``y``."""
        return np.sqrt(np.maximum(self.beta1 * np.asarray(y, np.float64) + self.beta2, 0.0))


def _haar(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal 2-D Haar level 1: approximation and diagonal detail (same noise std as x)."""
    h, w = (x.shape[0] // 2) * 2, (x.shape[1] // 2) * 2
    x = x[:h, :w].astype(np.float64)
    a, b, c, d = x[0::2, 0::2], x[0::2, 1::2], x[1::2, 0::2], x[1::2, 1::2]
    return (a + b + c + d) / 2.0, (a - b - c + d) / 2.0


def level_sets(plane: np.ndarray, *, n_levels: int | None = None, smooth_k: float = 2.0,
               min_count: int = 300) -> LevelSets:
    """Level-set estimates of one CFA plane (Foi et al. 2008, section III).

    Non-smooth 2x2 blocks are found from the approximation alone: a block is
    dropped where the non-smoothness of the approximation
    (its local Laplacian energy, which vanishes on locally linear content)
    exceeds ``smooth_k``^2 times the noise variance expected from a first
    robust pass. Because the approximation and diagonal detail of white Gaussian noise
    are independent, this selection does not bias the detail variance.
    """
    approx, detail = _haar(plane)
    ybar = approx / 2.0  # block mean, E = y
    smooth = ndimage.uniform_filter(ybar, 3, mode="reflect")
    # local energy of the Laplacian of the approximation: zero on locally linear content;
    # for white noise of variance v it has mean 20 v (sum of squared kernel taps)
    lap = ndimage.laplace(approx, mode="reflect")
    local_energy = ndimage.uniform_filter(lap * lap, 3, mode="reflect") / 20.0
    keep = np.ones(approx.shape, bool)
    for _ in range(2):
        ls = _bin(smooth[keep], ybar[keep], detail[keep], n_levels, min_count, robust=True)
        if ls.mean.size < 2:
            break
        # expected noise variance at each block's intensity, from the robust level sets
        order = np.argsort(ls.mean)
        noise_var = np.interp(smooth, ls.mean[order], ls.var[order])
        keep = local_energy <= smooth_k**2 * np.maximum(noise_var, 1e-20)
        keep[:1, :] = keep[-1:, :] = False
        keep[:, :1] = keep[:, -1:] = False
    if keep.sum() < 2 * min_count:
        raise DatasetError(f"noise estimation: only {int(keep.sum())} smooth 2x2 blocks in a {plane.shape} plane; "
                           f"expected at least {2 * min_count}")
    return _bin(smooth[keep], ybar[keep], detail[keep], n_levels, min_count, robust=False)


def _bin(key: np.ndarray, ybar: np.ndarray, detail: np.ndarray, n_levels: int | None, min_count: int,
         robust: bool) -> LevelSets:
    n = key.size
    k = n_levels or int(np.clip(n // 2000, 4, 64))
    k = max(1, min(k, n // max(min_count, 1)))
    order = np.argsort(key, kind="stable")
    groups = np.array_split(order, k)
    means, vars_, counts = [], [], []
    for g in groups:
        if g.size < 2:
            continue
        d = detail[g]
        if robust:  # MAD of zero-mean Gaussian detail, tolerant of edges in the first pass
            v = (1.4826 * np.median(np.abs(d))) ** 2
        else:
            v = float(np.mean(d * d))  # E[d] = 0 on smooth blocks (Haar detail kills linear trends)
        means.append(float(np.mean(ybar[g])))
        vars_.append(v)
        counts.append(g.size)
    return LevelSets(np.array(means), np.array(vars_), np.array(counts, dtype=np.int64))


def fit_clipped_nlf(ls: LevelSets, *, clip: tuple[float, float] | None = (0.0, 1.0)) -> tuple[float, float]:
    """Maximum-likelihood (beta1, beta2) from level sets, accounting for clipping.

    Each level set's detail variance ``s2`` (n samples) is modelled as normal
    with mean ``v`` and variance ``2 v^2 / n`` (sample variance of a zero-mean
    normal), where ``v`` is the variance of the clipped variable whose
    *clipped* mean equals the level set's observed mean (Foi et al. 2008,
    section IV). Returns float64 (beta1, beta2).
    """
    m, s2, n = ls.mean, ls.var, ls.count.astype(np.float64)
    if m.size < 2:
        raise DatasetError(f"noise estimation: {m.size} level set(s); expected at least 2 to fit beta1 and beta2")
    # initial guess: weighted least squares on level sets well inside the clipping range
    inner = np.ones_like(m, bool) if clip is None else (m > clip[0] + 3 * np.sqrt(s2)) & (m < clip[1] - 3 * np.sqrt(s2))
    if inner.sum() < 2:
        inner = np.ones_like(m, bool)
    w = n[inner] / np.maximum(s2[inner], 1e-30) ** 2
    A = np.stack([m[inner], np.ones(inner.sum())], 1)
    b1, b2 = np.linalg.lstsq(A * np.sqrt(w)[:, None], s2[inner] * np.sqrt(w), rcond=None)[0]
    if clip is None:
        return float(b1), float(b2)
    lo, hi = clip
    grid = np.linspace(lo - 0.5, hi + 0.5, 4001)
    scale = max(float(np.median(s2)), 1e-12)

    def predicted(params):
        p1, p2 = params[0] * scale, params[1] * scale
        sig = np.sqrt(np.maximum(p1 * grid + p2, 1e-14))
        mean, std = clipped_moments(grid, sig, lo, hi)
        # clipped mean is increasing in y: invert it at the observed means
        mono = np.maximum.accumulate(mean + 1e-15 * np.arange(grid.size))
        y = np.interp(m, mono, grid)
        sig_y = np.sqrt(np.maximum(p1 * y + p2, 1e-14))
        return clipped_moments(y, sig_y, lo, hi)[1] ** 2

    def nll(params):
        v = np.maximum(predicted(params), 1e-20)
        return float(np.sum(n * (s2 - v) ** 2 / (4 * v * v) + np.log(v)))

    x0 = np.array([b1 / scale, b2 / scale])
    res = optimize.minimize(nll, x0, method="Nelder-Mead",
                            options={"xatol": 1e-6, "fatol": 1e-9, "maxiter": 4000})
    return float(res.x[0] * scale), float(res.x[1] * scale)


def estimate_nlf(mosaic: np.ndarray, *, per_plane: bool = False, clip: tuple[float, float] | None = (0.0, 1.0),
                 n_levels: int | None = None) -> NLFEstimate:
    """Estimate the NLF ``var = beta1 y + beta2`` of one noisy normalised-raw image.

    Parameters
    ----------
    mosaic : ndarray
        H x W Bayer mosaic (normalised raw; H, W even) -- each packed CFA plane
        is analysed separately -- or a 4 x h x w packed array.
    per_plane : bool
        Also fit one (beta1, beta2) pair per packed plane.
    clip : (lo, hi) or None
        Clipping range of the data (Abdelhamed 2020, eq. 5.3); None for unclipped data.
    n_levels : int, optional
        Level sets per plane (default: one per ~2,000 smooth blocks, 4..64).

    Returns
    -------
    NLFEstimate
    """
    x = np.asarray(mosaic)
    if x.ndim == 2:
        planes = pack(x)
    elif x.ndim == 3 and x.shape[0] == 4:
        planes = x
    else:
        raise DatasetError(f"estimate_nlf: expected an H x W mosaic or 4 x h x w packed array, got shape {x.shape}")
    sets = [level_sets(p, n_levels=n_levels) for p in planes]
    joint = LevelSets(np.concatenate([s.mean for s in sets]), np.concatenate([s.var for s in sets]),
                      np.concatenate([s.count for s in sets]))
    b1, b2 = fit_clipped_nlf(joint, clip=clip)
    per = np.array([fit_clipped_nlf(s, clip=clip) for s in sets]) if per_plane else None
    return NLFEstimate(b1, b2, per, joint)


# --------------------------------------------------------------------------------------
def estimate_sigma(image: np.ndarray, *, patch: int = 8, stride: int = 3) -> float:
    """Gaussian noise standard deviation of one image (Chen, Zhu and Heng 2015).

    Patches (``patch`` x ``patch``, step ``stride``) form a d x n matrix;
    the eigenvalues of its covariance, sorted ascending, are scanned from
    the full set down: sigma^2 is the mean of the largest prefix whose mean
    equals its median (as many eigenvalues above the mean as below).

    Parameters
    ----------
    image : ndarray
        2-D image, or H x W x C (the channels' estimates are averaged in variance).

    Returns
    -------
    float
        sigma, in the image's units.
    """
    x = np.asarray(image, dtype=np.float64)
    if x.ndim == 3:
        return float(np.sqrt(np.mean([estimate_sigma(x[..., c], patch=patch, stride=stride) ** 2
                                      for c in range(x.shape[2])])))
    if x.ndim != 2 or min(x.shape) < patch:
        raise DatasetError(f"estimate_sigma: expected a 2-D image of at least {patch}x{patch}, got shape {x.shape}")
    win = np.lib.stride_tricks.sliding_window_view(x, (patch, patch))[::stride, ::stride]
    cols = win.reshape(-1, patch * patch)
    cols = cols - cols.mean(axis=0)
    cov = cols.T @ cols / cols.shape[0]
    eig = np.sort(np.linalg.eigvalsh(cov))
    mean = float(eig.mean())
    for k in range(eig.size, 0, -1):
        e = eig[:k]
        mean = float(e.mean())
        if np.sum(e > mean) == np.sum(e < mean):
            break
    return float(np.sqrt(max(mean, 0.0)))
