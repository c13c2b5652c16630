"""``poisson_gaussian``: ``noisy = beta1 * Poisson(clean / beta1) + N(0, beta2)`` (Abdelhamed 2020, eq. 3.6).

Sampling is exact (:func:`simcam.noise.kernels.poisson.pg_sample_table`: alias tables and a
compiled kernel, no normal approximation).
``log_prob`` sums the Poisson-weighted Gaussian densities
``log sum_k Pois(k; lam) N(x; beta1 k, beta2)``, ``lam = clean / beta1``, over a
window of k: the summand is log-concave in k (a product of two log-concave
sequences), so it is unimodal. The window is centred on the mode of its
Gaussian approximation, the precision-weighted mean
``k* = (lam * P_p + (x / beta1) * P_g) / (P_p + P_g)`` with
``P_p = 1 / max(lam, 1)`` and ``P_g = beta1^2 / beta2``, and has half-width
``12 / sqrt(P_p + P_g) + 12``: terms outside lie more than 12 standard
deviations of the summand from its mode (documented truncation; the tests
compare with a brute-force sum over all k to 1e-9).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from ..errors import NoiseModelError
from .base import PoissonScaleModel, check_clean, check_same_shape, register_model
from .kernels.poisson import pg_sample_table

#: largest Poisson mean sampled exactly in float32 (integer counts stay exact).
LAMBDA_MAX = float(2**22)
_LOG_SQRT_2PI = 0.5 * np.log(2.0 * np.pi)
_CHUNK = 2048


def _check_lambda(lam_max: float, beta1_min: float, where: str) -> None:
    if lam_max >= LAMBDA_MAX:
        raise NoiseModelError(
            f"{where}: beta1 {beta1_min:.3g} gives a Poisson mean of {lam_max:.3g} photo-electrons; expected below "
            f"{LAMBDA_MAX:.3g} (use the nlf model for such signals)")


def pg_sample(clean: np.ndarray, scale, beta2, rng: np.random.Generator, out: np.ndarray, *,
              where: str = "clean") -> np.ndarray:
    """``out = scale * Poisson(clean / scale) + sqrt(beta2) * z`` (float32 maps or scalars), exact."""
    scale = np.asarray(scale, dtype=np.float32)
    lam_max = 0.0
    if clean.size:
        # float32 division is monotone: this bounds every clean / scale of the kernel
        lam_max = float(np.float32(clean.max()) / np.float32(scale.min()))
        _check_lambda(lam_max, float(scale.min()), where)
    sd = np.sqrt(np.asarray(beta2, dtype=np.float32))
    return pg_sample_table(clean, scale, sd, rng, out, lam_max)


def pg_logpdf(x: np.ndarray, lam: np.ndarray, scale: np.ndarray, var: np.ndarray) -> np.ndarray:
    """log sum_k Pois(k; lam) N(x; scale k, var), float64 1-D arrays (see module docstring)."""
    out = np.empty(x.size, dtype=np.float64)
    for s in range(0, x.size, _CHUNK):
        sl = slice(s, s + _CHUNK)
        out[sl] = _pg_logpdf_chunk(x[sl], lam[sl], scale[sl], var[sl])
    return out


def _window(x, lam, scale, var):
    prec_p = 1.0 / np.maximum(lam, 1.0)
    prec_g = scale * scale / var
    kstar = (lam * prec_p + (x / scale) * prec_g) / (prec_p + prec_g)
    half = np.ceil(12.0 / np.sqrt(prec_p + prec_g) + 12.0)
    lo = np.maximum(0.0, np.floor(kstar - half))
    return lo, 2 * half + 1


def _poisson_terms(lam, lo, width):
    """The counts ``k = lo, lo + 1, ...`` of each element's Poisson window (rows padded to the widest),
    which of them are inside the ``width`` of the window, and ``log Pois(k; lam)``."""
    from scipy.special import gammaln  # imported here: 0.1 s of every process start otherwise

    kmax = int(width.max())
    k = lo[:, None] + np.arange(kmax)[None, :]
    valid = np.arange(kmax)[None, :] < width[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        logpois = np.where(lam[:, None] > 0, k * np.log(lam[:, None]) - lam[:, None] - gammaln(k + 1.0),
                           np.where(k == 0, 0.0, -np.inf))
    return k, valid, logpois


def _pg_logpdf_chunk(x, lam, scale, var):
    from scipy.special import logsumexp  # imported here: 0.1 s of every process start otherwise

    lo, width = _window(x, lam, scale, var)
    k, valid, logpois = _poisson_terms(lam, lo, width)
    r = x[:, None] - scale[:, None] * k
    lognorm = -0.5 * r * r / var[:, None] - 0.5 * np.log(var[:, None]) - _LOG_SQRT_2PI
    terms = np.where(valid, logpois + lognorm, -np.inf)
    return logsumexp(terms, axis=1)


def pg_logcdf(x: np.ndarray, lam: np.ndarray, scale: np.ndarray, var: np.ndarray, *, upper: bool = False) -> np.ndarray:
    """log P(noisy <= x) (or > x) under the Poisson-Gaussian law, float64 1-D arrays.

    The window is the Poisson one, ``lam +- (12 sqrt(lam) + 12)`` (the Gaussian
    CDF factor is not concentrated), mass outside it below 1e-25.
    """
    from scipy.special import log_ndtr, logsumexp  # imported here: 0.1 s of every process start otherwise

    out = np.empty(x.size, dtype=np.float64)
    for s in range(0, x.size, _CHUNK):
        sl = slice(s, s + _CHUNK)
        xs, ls, ss, vs = x[sl], lam[sl], scale[sl], var[sl]
        half = np.ceil(12.0 * np.sqrt(ls) + 12.0)
        lo = np.maximum(0.0, np.floor(ls - half))
        width = (ls + half) - lo + 1
        k, valid, logpois = _poisson_terms(ls, lo, width)
        r = (xs[:, None] - ss[:, None] * k) / np.sqrt(vs[:, None])
        logc = log_ndtr(-r if upper else r)
        out[sl] = logsumexp(np.where(valid, logpois + logc, -np.inf), axis=1)
    return out


@register_model
class PoissonGaussian(PoissonScaleModel):
    """``noisy = beta1 * Poisson(clean / beta1) + N(0, beta2)`` (Abdelhamed 2020, eq. 3.6).

    Parameters
    ----------
    beta1 : float or 4 floats
        Normalised raw value of one photo-electron (the gain); > 0. The mean is
        ``clean`` and the variance ``beta1 * clean + beta2``, as for ``nlf``.
    beta2 : float or 4 floats
        Variance of the signal-independent Gaussian part, normalised raw^2;
        >= 0 (> 0 for ``log_prob``).
    """

    type: Literal["poisson_gaussian"] = "poisson_gaussian"

    def _sample_block(self, clean, cond, rng, row0, out):
        b1, b2 = self._maps(clean.shape, row0)
        pg_sample(clean, b1, b2, rng, out, where=f"{cond.source or 'clean'}: poisson_gaussian")

    def read_split(self):
        return self.model_copy(update={"beta2": 0.0}), self.beta2

    def variance(self, clean, cond):
        clean = check_clean(clean)
        b1, b2 = self._maps(clean.shape, 0, np.float64)
        return np.broadcast_to(clean.astype(np.float64) * b1 + b2, clean.shape).astype(np.float64)

    def _flat(self, clean, cond):
        b1, b2 = self._maps(clean.shape, 0, np.float64)
        b1 = np.broadcast_to(b1, clean.shape).astype(np.float64).ravel()
        b2 = np.broadcast_to(b2, clean.shape).astype(np.float64).ravel()
        if (b2 <= 0).any():
            raise NoiseModelError(
                f"{cond.source or 'model'}: poisson_gaussian: log_prob needs beta2 > 0 (a density), got {self.beta2!r}")
        return clean.astype(np.float64).ravel() / b1, b1, b2

    def log_prob(self, noisy, clean, cond):
        clean = check_clean(clean, where=f"{cond.source or 'clean'}")
        self.check_cond(cond, clean.shape)
        x = check_same_shape(noisy, clean).astype(np.float64).ravel()
        lam, b1, b2 = self._flat(clean, cond)
        return pg_logpdf(x, lam, b1, b2).reshape(clean.shape)

    def cdf(self, x, clean, cond, *, log: bool = False, upper: bool = False):
        clean = check_clean(clean)
        xs = np.broadcast_to(np.asarray(x, dtype=np.float64), clean.shape).ravel()
        lam, b1, b2 = self._flat(clean, cond)
        lc = pg_logcdf(xs, lam, b1, b2, upper=upper).reshape(clean.shape)
        return lc if log else np.exp(lc)
