"""Per-pixel robust mean of a burst with censored (clipped) samples (Abdelhamed 2020, section 5.3.4).

Three estimators, all vectorised over pixels (no per-pixel Python loop):

``wls``
    Abdelhamed 2020, eq. 5.6-5.12: samples at or beyond the clip points are dropped from the
    fit, a normal CDF is fitted to the empirical CDF of the rest by weighted least
    squares with weights ``w = (F (1 - F))^(-1/2)`` (eq. 5.11). The empirical CDF
    is evaluated with Hazen plotting positions ``F_k = (k - 1/2) / n`` over *all*
    ``n`` finite samples of the pixel, the censored ones keeping their rank
    positions at the bottom (low clip) or top (high clip) of the order; this is
    what makes the fit unbiased under censoring (a CDF normalised over the
    uncensored samples only would describe the truncated distribution).
    For a fixed sample order the objective is solved in closed form by its first
    order expansion around the fitted CDF (a weighted linear regression of the
    sorted samples on ``z_k = Phi^-1(F_k)`` with weights ``w_k phi(z_k)^2``), then
    ``refine`` Gauss-Newton steps on the exact objective (eq. 5.10).
``mle``
    Censored (Tobit) maximum likelihood of N(mu, sigma) with left censoring at
    ``lo`` and right censoring at ``hi``; vectorised Newton on (mu, log sigma)
    using the pixel's sufficient statistics.
``mean``
    The plain per-pixel mean (and standard deviation) of every finite sample,
    clipped ones included: the baseline Abdelhamed 2020 compares against.

Units: normalised raw (dimensionless); ``sigma`` is the per-sample noise standard
deviation in the same units. Samples are along ``axis`` (default 0: shape (N, P));
``axis=1`` takes (P, N), the fast layout used on large tiles.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import special

from ..errors import DatasetError

METHODS = ("wls", "mle", "mean")
_SQRT2PI = np.sqrt(2.0 * np.pi)


@dataclass
class RobustMean:
    """Per-pixel estimate of a burst.

    Attributes
    ----------
    mu : ndarray, float32, (P,)
        Estimated noise-free value (normalised raw).
    sigma : ndarray, float32, (P,)
        Estimated per-sample noise standard deviation (normalised raw).
    n_used : ndarray, int16, (P,)
        Uncensored finite samples that entered the fit.
    n_low, n_high : ndarray, int16, (P,)
        Samples censored at the low / high clip point.
    valid : ndarray, bool, (P,)
        False where the pixel had fewer than ``min_samples`` uncensored samples
        and the documented fallback was used (see :func:`robust_mean`).

    Parameters
    ----------
    mu, sigma, n_used, n_low, n_high, valid
        As the attributes.

    Examples
    --------
    >>> import numpy as np
    >>> r = plain_mean(np.array([[0.2, 0.4], [0.4, 0.4], [0.6, 0.4]]))
    >>> [round(float(v), 3) for v in r.mu], r.valid.tolist()
    ([0.4, 0.4], [True, True])
    """

    mu: np.ndarray
    sigma: np.ndarray
    n_used: np.ndarray
    n_low: np.ndarray
    n_high: np.ndarray
    valid: np.ndarray


def _check_samples(samples: np.ndarray, axis: int = 0) -> np.ndarray:
    """Samples as a float32 (P, N) array (pixels first, C-contiguous)."""
    x = np.asarray(samples)
    if x.ndim == 1:
        x = x[:, None] if axis == 0 else x[None, :]
    if x.ndim != 2 or axis not in (0, 1, -1):
        raise DatasetError(f"robust_mean: samples: expected an (N, P) array with axis 0 or 1, got shape {x.shape}")
    if axis == 0:
        x = x.T
    return np.ascontiguousarray(x, dtype=np.float32)


def _positions(n_fin: np.ndarray, N: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hazen positions F = (k + 1/2)/n, z = Phi^-1(F), linearised weights u = w phi(z)^2.

    ``n_fin`` is a scalar or a (P, 1) array of finite-sample counts; ranks k >= n
    get F = 0.5 and u = 0.
    """
    k = np.arange(N, dtype=np.float64)[None, :]
    n = np.asarray(n_fin, dtype=np.float64)
    inside = k < n
    F = np.where(inside, (k + 0.5) / np.maximum(n, 1), 0.5)
    z = special.ndtri(F)
    w = 1.0 / np.sqrt(F * (1.0 - F))
    phi = np.exp(-0.5 * z * z) / _SQRT2PI
    u = np.where(inside, w * phi * phi, 0.0)
    return F, z, u


@lru_cache(maxsize=16)
def _positions_full(N: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    F, z, u = _positions(N, N)
    return F[0], z[0], u[0]


def _sorted_with_censoring(x: np.ndarray, lo: float, hi: float):
    """Sort (P, N) samples along N with low-censored -> -inf, high-censored -> +inf, NaN last."""
    key = x.copy()
    key[x <= lo] = -np.inf
    key[x >= hi] = np.inf
    key.sort(axis=1)
    n_fin = x.shape[1] - np.count_nonzero(np.isnan(key), axis=1)
    n_low = np.count_nonzero(key == -np.inf, axis=1)
    n_high = np.count_nonzero(key == np.inf, axis=1)
    return key, n_fin, n_low, n_high


def _weighted_row_sums(m: np.ndarray, x: np.ndarray, cols: np.ndarray, chunk: int = 8192) -> np.ndarray:
    """``[m @ c0, m @ c1, m @ c2, x @ c0, x @ c1]`` (float32 products, float64 result) for P x N rows.

    Row by row with numpy's own summation over the contiguous last axis instead of a BLAS
    matrix-vector product: BLAS kernels block rows differently for different row counts, so a
    pixel's sum would depend on the tile it falls in (a ground truth that changes in the last bits
    with ``tile_pixels``); here each row's sum depends only on that row.
    """
    P = m.shape[0]
    out = np.empty((5, P), dtype=np.float64)
    for r0 in range(0, P, chunk):
        mc = m[r0:r0 + chunk].astype(np.float32)
        xc = x[r0:r0 + chunk]
        for k, (a, c) in enumerate(((mc, 0), (mc, 1), (mc, 2), (xc, 0), (xc, 1))):
            out[k, r0:r0 + chunk] = np.multiply(a, cols[c]).sum(axis=1, dtype=np.float32)
    return out


def wls_cdf_fit(samples: np.ndarray, *, lo: float = 0.0, hi: float = 1.0, refine: int = 0,
                min_samples: int = 3, axis: int = 0, nlf: tuple[float, float] | None = None) -> RobustMean:
    """WLS fit of a normal CDF to the censored empirical CDF, per pixel (Abdelhamed 2020, eq. 5.8-5.12).

    Parameters
    ----------
    samples : ndarray, (N, P) (``axis=0``) or (P, N) (``axis=1``)
        Burst samples of P pixels, normalised raw. NaN marks a missing sample.
        Samples ``<= lo`` or ``>= hi`` are censored (or ±inf, already marked).
    lo, hi : float
        Clip points in normalised raw (Abdelhamed 2020: 0 and 1).
    refine : int
        Gauss-Newton iterations on the exact objective eq. 5.10 after the closed
        form (linearised) solution. 0 (default) keeps the closed form: it agrees
        with the exact minimiser to a small fraction of the standard error and is
        ~20x faster on large bursts (see ``experiments/fig5_9_robust_mean.py``).
    min_samples : int
        Fewest uncensored samples for a fit (>= 2); fewer -> fallback, ``valid`` False.
    nlf : (beta1, beta2), optional
        Known noise level function (Abdelhamed 2020, eq. 5.2, e.g. the DNG NoiseProfile). Then
        sigma = sqrt(beta1 mu + beta2) is not fitted: the regression keeps only its
        intercept, mu = sum u (x - sigma z) / sum u, iterated twice with sigma
        re-evaluated at the new mu (an extension beyond Abdelhamed 2020; it recovers most of
        the precision the two-parameter fit loses on heavily censored pixels).

    Returns
    -------
    RobustMean
        Per-pixel ``mu``, ``sigma``, sample counts and ``valid``.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.random.default_rng(0).normal(0.5, 0.05, (200, 3))
    >>> fit = wls_cdf_fit(x)
    >>> bool(np.all(np.abs(fit.mu - 0.5) < 0.02)), bool(np.all(np.abs(fit.sigma - 0.05) < 0.01))
    (True, True)
    """
    x = _check_samples(samples, axis)
    P, N = x.shape
    key, n_fin, n_low, n_high = _sorted_with_censoring(x, lo, hi)
    n_used = n_fin - n_low - n_high
    m = np.isfinite(key)
    xs = np.where(m, key, np.float32(0.0))
    S = np.zeros((5, P), dtype=np.float64)
    full = n_fin == N
    if full.any():  # common case: every sample present, rank positions shared by all pixels
        _, z, u = _positions_full(N)
        cols = np.stack([u, u * z, u * z * z]).astype(np.float32)        # (3, N)
        S[:, full] = _weighted_row_sums(m[full], xs[full], cols)
    part = ~full
    if part.any():  # pixels with missing (NaN) samples: per-pixel rank positions
        _, z, u = _positions(n_fin[part][:, None], N)
        u = np.where(m[part], u, 0.0)
        xp = xs[part].astype(np.float64)
        S[0, part] = u.sum(1)
        S[1, part] = (u * z).sum(1)
        S[2, part] = (u * z * z).sum(1)
        S[3, part] = (u * xp).sum(1)
        S[4, part] = (u * xp * z).sum(1)
    S0, Sz, Szz, Sx, Sxz = S
    det = S0 * Szz - Sz * Sz
    ok = (n_used >= max(int(min_samples), 2)) & (det > 1e-12 * np.maximum(S0 * Szz, 1e-300))
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma = np.where(ok, (S0 * Sxz - Sz * Sx) / np.where(ok, det, 1.0), 0.0)
        mu = np.where(ok, (Sx - sigma * Sz) / np.where(S0 > 0, S0, 1.0), 0.0)
    sigma = np.maximum(sigma, 0.0)
    if nlf is not None:
        b1, b2 = float(nlf[0]), float(nlf[1])
        with np.errstate(divide="ignore", invalid="ignore"):
            for _ in range(2):
                sigma = np.sqrt(np.maximum(b1 * np.clip(mu, 0, None) + b2, 1e-30))
                mu = np.where(ok, (Sx - sigma * Sz) / np.where(S0 > 0, S0, 1.0), mu)
        sigma = np.sqrt(np.maximum(b1 * np.clip(mu, 0, None) + b2, 1e-30))
        refine = 0
    if refine > 0 and ok.any():
        sel_all = np.nonzero(ok & (sigma > 0))[0]
        for c0 in range(0, sel_all.size, 16384):  # bounded float64 temporaries
            sel = sel_all[c0:c0 + 16384]
            Fsel, _, _ = _positions(n_fin[sel][:, None], N)
            mu_s, sg_s = _gauss_newton(xs[sel].astype(np.float64), m[sel], Fsel, mu[sel], sigma[sel], refine)
            mu[sel], sigma[sel] = mu_s, sg_s
    res = RobustMean(mu=mu.astype(np.float32), sigma=sigma.astype(np.float32),
                     n_used=n_used.astype(np.int16), n_low=n_low.astype(np.int16),
                     n_high=n_high.astype(np.int16), valid=ok)
    _fallback(res, x, lo, hi)
    return res


def wls_objective(mu: float, sigma: float, x: np.ndarray, lo: float = 0.0, hi: float = 1.0) -> float:
    """Eq. 5.10 for one pixel: sum over uncensored samples of w (Phi_p - Phi_e)^2.

    The reference definition used by the tests and the Nelder-Mead baseline
    (same plotting positions and censoring ranks as :func:`wls_cdf_fit`).

    Parameters
    ----------
    mu, sigma : float
        The normal law to evaluate.
    x : ndarray
        One pixel's samples (NaN skipped; at or beyond ``lo`` / ``hi``: censored).
    lo, hi : float
        The clip points.

    Returns
    -------
    float
        The weighted squared CDF misfit.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.array([0.4, 0.5, 0.6])
    >>> wls_objective(0.5, 0.1, x) < wls_objective(0.7, 0.1, x)
    True
    """
    x = np.asarray(x, dtype=np.float64)
    x = x[~np.isnan(x)]
    n = x.size
    key = np.sort(np.where(x <= lo, -np.inf, np.where(x >= hi, np.inf, x)))
    F = (np.arange(n) + 0.5) / n
    m = np.isfinite(key)
    w = 1.0 / np.sqrt(F * (1.0 - F))
    if sigma <= 0:
        return np.inf
    r = special.ndtr((key[m] - mu) / sigma) - F[m]
    return float(np.sum(w[m] * r * r))


def _gauss_newton(xs, m, F, mu, sigma, iters):
    """Gauss-Newton on psi(mu, sigma) = sum w (Phi((x-mu)/sigma) - F)^2 (eq. 5.10), step halving.

    Arrays are (P, N); ``m`` marks the uncensored samples that enter the sum.
    """
    w = np.where(m, 1.0 / np.sqrt(F * (1.0 - F)), 0.0)
    mu = mu.astype(np.float64).copy()
    sg = sigma.astype(np.float64).copy()

    def psi(mu_, sg_):
        a = (xs - mu_[:, None]) / sg_[:, None]
        r = special.ndtr(a) - F
        return (w * r * r).sum(1), a, r

    cur, a, r = psi(mu, sg)
    for _ in range(iters):
        phi = np.exp(-0.5 * a * a) / _SQRT2PI
        jm = -phi / sg[:, None]      # d r / d mu
        js = jm * a                  # d r / d sigma
        A = (w * jm * jm).sum(1)
        B = (w * jm * js).sum(1)
        C = (w * js * js).sum(1)
        gm = (w * jm * r).sum(1)
        gs = (w * js * r).sum(1)
        det = A * C - B * B
        good = det > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            dmu = np.where(good, -(C * gm - B * gs) / np.where(good, det, 1.0), 0.0)
            dsg = np.where(good, -(A * gs - B * gm) / np.where(good, det, 1.0), 0.0)
        step = 1.0
        accepted = ~good
        new_mu, new_sg = mu.copy(), sg.copy()
        for _h in range(4):  # backtracking: accept where psi does not increase
            tmu = mu + step * dmu
            tsg = sg + step * dsg
            tsg = np.where(tsg > 0, tsg, 0.5 * sg)
            val, _, _ = psi(tmu, tsg)
            better = ~accepted & (val <= cur)
            new_mu = np.where(better, tmu, new_mu)
            new_sg = np.where(better, tsg, new_sg)
            cur = np.where(better, val, cur)
            accepted |= better
            if accepted.all():
                break
            step *= 0.5
        mu, sg = new_mu, new_sg
        _, a, r = psi(mu, sg)
    return mu, sg


def _fallback(res: RobustMean, x: np.ndarray, lo: float, hi: float) -> None:
    """Pixels without enough uncensored samples: documented fallbacks, ``valid`` False.

    * every sample high-censored -> ``hi`` (a lower bound of the truth);
    * every sample low-censored -> ``lo`` (an upper bound);
    * otherwise the plain mean of the finite samples, clipped to [lo, hi];
    * no finite sample at all -> NaN.
    ``sigma`` is 0 for all of them.
    """
    bad = ~res.valid
    if not bad.any():
        return
    xb = x[bad]
    fin = np.isfinite(xb)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(fin, xb, 0.0).sum(1) / fin.sum(1)
    n_fin = res.n_used[bad] + res.n_low[bad] + res.n_high[bad]
    val = np.clip(mean, lo, hi)
    val = np.where(res.n_high[bad] == n_fin, hi, val)
    val = np.where(res.n_low[bad] == n_fin, lo, val)
    val = np.where(n_fin == 0, np.nan, val)
    res.mu[bad] = val
    res.sigma[bad] = 0.0


def censored_mle(samples: np.ndarray, *, lo: float = 0.0, hi: float = 1.0, max_iter: int = 50,
                 tol: float = 1e-10, min_samples: int = 3, axis: int = 0) -> RobustMean:
    """Censored-normal (Tobit) maximum likelihood per pixel, vectorised Newton.

    log L = sum_uncensored [log phi((x - mu)/sigma) - log sigma]
            + n_low log Phi((lo - mu)/sigma) + n_high log Phi((mu - hi)/sigma).

    Newton steps on
    (mu, log sigma) with analytic gradient and Hessian, step halving where the
    likelihood would not increase, gradient ascent where the Hessian is not
    negative definite. Reference: Tobin (1958), doi:10.2307/1907382.

    Parameters
    ----------
    samples, lo, hi, min_samples, axis
        As :func:`wls_cdf_fit`.
    max_iter, tol : int, float
        Newton iterations at most, and the step size that stops them.

    Returns
    -------
    RobustMean
        As :func:`wls_cdf_fit`.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.clip(np.random.default_rng(1).normal(0.95, 0.05, (400, 2)), 0.0, 1.0)  # clipped at white
    >>> fit = censored_mle(x)
    >>> bool(np.all(np.abs(fit.mu - 0.95) < 0.01)), bool(np.all(fit.n_high > 0))
    (True, True)
    """
    x = _check_samples(samples, axis)
    fin = ~np.isnan(x)
    low = fin & (x <= lo)
    high = fin & (x >= hi)
    unc = fin & ~low & ~high
    n_low = low.sum(1).astype(np.float64)
    n_high = high.sum(1).astype(np.float64)
    nu = unc.sum(1).astype(np.float64)
    s1 = np.where(unc, x, 0.0).sum(1, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_u = np.where(nu > 0, s1 / np.maximum(nu, 1), 0.5 * (lo + hi))
        dev = np.where(unc, x - mean_u[:, None], 0.0)
    s2c = (dev * dev).sum(1)  # centred second moment (numerically stable)
    var_u = s2c / np.maximum(nu - 1, 1)
    del dev
    ok = nu >= max(int(min_samples), 2)
    mu = mean_u.copy()
    s = np.log(np.sqrt(np.maximum(var_u, 1e-20)))

    def loglik(mu_, s_):
        sg = np.exp(s_)
        d = mean_u - mu_
        ssq = s2c + nu * d * d
        ll = -0.5 * ssq / sg**2 - nu * s_
        al = (lo - mu_) / sg
        ah = (mu_ - hi) / sg
        ll = ll + np.where(n_low > 0, n_low * special.log_ndtr(al), 0.0)
        ll = ll + np.where(n_high > 0, n_high * special.log_ndtr(ah), 0.0)
        return ll

    def mills(a):  # phi(a) / Phi(a), stable
        return np.exp(-0.5 * a * a - special.log_ndtr(a)) / _SQRT2PI

    with np.errstate(all="ignore"):
        cur = loglik(mu, s)
        act = ok.copy()
        for _ in range(max_iter):
            if not act.any():
                break
            sg = np.exp(s)
            d = mean_u - mu
            # uncensored part (sufficient statistics)
            gm = nu * d / sg**2
            gs = (s2c + nu * d * d) / sg**2 - nu
            Hmm = -nu / sg**2
            Hms = -2.0 * nu * d / sg**2
            Hss = -2.0 * (s2c + nu * d * d) / sg**2
            # censored terms: l = n log Phi(b); low: b = (lo - mu)/sigma, high: b = (mu - hi)/sigma
            for cnt, c, sign in ((n_low, lo, -1.0), (n_high, hi, 1.0)):
                has = cnt > 0
                b = np.where(has, sign * (mu - c) / sg, 0.0)
                lam = np.where(has, mills(b), 0.0)
                g1 = lam                       # dl/db
                g2 = -lam * (b + lam)          # d2l/db2
                db_dmu = sign / sg
                db_ds = -b
                gm = gm + cnt * g1 * db_dmu
                gs = gs + cnt * g1 * db_ds
                Hmm = Hmm + cnt * g2 * db_dmu**2
                Hms = Hms + cnt * (g2 * db_dmu * db_ds - g1 * db_dmu)
                Hss = Hss + cnt * (g2 * db_ds**2 + g1 * b)
            det = Hmm * Hss - Hms * Hms
            negdef = (Hmm < 0) & (det > 0)
            with np.errstate(divide="ignore", invalid="ignore"):
                dmu = np.where(negdef, -(Hss * gm - Hms * gs) / np.where(negdef, det, 1.0), 0.1 * sg * np.sign(gm))
                ds = np.where(negdef, -(Hmm * gs - Hms * gm) / np.where(negdef, det, 1.0), 0.1 * np.sign(gs))
            ds = np.clip(ds, -1.0, 1.0)
            step = np.ones_like(mu)
            done = ~act
            new_mu, new_s = mu.copy(), s.copy()
            gain = np.zeros_like(mu)
            for _h in range(8):
                tmu, ts = mu + step * dmu, s + step * ds
                val = loglik(tmu, ts)
                better = ~done & (val >= cur)
                new_mu = np.where(better, tmu, new_mu)
                new_s = np.where(better, ts, new_s)
                gain = np.where(better, val - cur, gain)
                cur = np.where(better, val, cur)
                done |= better
                if done.all():
                    break
                step = step * 0.5
            moved = np.abs(new_mu - mu) + np.abs(new_s - s)
            mu, s = new_mu, new_s
            act = act & (moved > tol) & (gain > tol * 1e-3)
    res = RobustMean(mu=mu.astype(np.float32), sigma=np.exp(s).astype(np.float32),
                     n_used=nu.astype(np.int16), n_low=n_low.astype(np.int16),
                     n_high=n_high.astype(np.int16), valid=ok)
    _fallback(res, x, lo, hi)
    return res


def plain_mean(samples: np.ndarray, *, lo: float = 0.0, hi: float = 1.0, min_samples: int = 1,
               axis: int = 0) -> RobustMean:
    """Plain per-pixel mean and standard deviation (ddof=1) of every finite sample.

    Clipped samples are averaged as they are (the biased baseline of Abdelhamed 2020, fig. 5.9);
    NaN samples are skipped. ``valid`` is False only where no sample is finite.

    Parameters
    ----------
    samples, lo, hi, axis
        As :func:`wls_cdf_fit` (``lo`` and ``hi`` only count the clipped samples).
    min_samples : int
        Fewest finite samples for ``valid``.

    Returns
    -------
    RobustMean
        The plain mean and standard deviation per pixel.

    See Also
    --------
    robust_mean : the estimate that accounts for the clipped samples.

    Examples
    --------
    >>> plain_mean(np.array([[1.0], [0.5], [np.nan]])).mu.tolist()  # the clipped 1.0 counts as it is
    [0.75]
    """
    x = _check_samples(samples, axis)
    fin = ~np.isnan(x)
    n = fin.sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mu = np.where(fin, x, 0.0).sum(1, dtype=np.float64) / n
        d = np.where(fin, x - mu[:, None], 0.0)
        sd = np.sqrt((d * d).sum(1) / np.maximum(n - 1, 1))
    low = (fin & (x <= lo)).sum(1)
    high = (fin & (x >= hi)).sum(1)
    return RobustMean(mu=mu.astype(np.float32), sigma=sd.astype(np.float32), n_used=(n - low - high).astype(np.int16),
                      n_low=low.astype(np.int16), n_high=high.astype(np.int16), valid=n >= max(min_samples, 1))


def robust_mean(samples: np.ndarray, method: str = "wls", *, lo: float = 0.0, hi: float = 1.0,
                uncensored_mean: bool = False, **kw) -> RobustMean:
    """Dispatch to :func:`wls_cdf_fit`, :func:`censored_mle` or :func:`plain_mean`.

    ``uncensored_mean=True`` fits (``wls``/``mle``) only the pixels that have a
    censored or missing sample and gives the others their plain mean and
    standard deviation: without censoring the mean is the minimum-variance
    unbiased estimate, while the WLS CDF fit (an L-estimator) has ~94 %
    efficiency (variance ratio measured 1.06, see the tests).

    Fallback (``wls``/``mle``) where fewer than ``min_samples`` (default 3)
    samples are uncensored: all high-censored -> ``hi``, all low-censored ->
    ``lo``, otherwise the plain mean clipped to [lo, hi]; ``valid`` is False there.

    Parameters
    ----------
    samples, lo, hi
        As :func:`wls_cdf_fit`.
    method : {"wls", "mle", "mean"}
        :func:`wls_cdf_fit`, :func:`censored_mle` or :func:`plain_mean`.
    uncensored_mean : bool
        Plain mean where no sample is censored or missing (above).
    **kw
        Passed on to the method.

    Returns
    -------
    RobustMean
        The chosen estimate.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.array([[0.3, 1.0], [0.5, 1.0], [0.4, 0.9]])
    >>> [round(float(v), 3) for v in robust_mean(x, "mean").mu]
    [0.4, 0.967]
    """
    if method in ("wls", "mle"):
        fn = wls_cdf_fit if method == "wls" else censored_mle
        if not uncensored_mean:
            return fn(samples, lo=lo, hi=hi, **kw)
        axis = kw.pop("axis", 0)
        x = _check_samples(samples, axis)
        fin = ~np.isnan(x)
        cens = (fin & ((x <= lo) | (x >= hi))).any(1) | ~fin.all(1)
        res = plain_mean(x, lo=lo, hi=hi, axis=1)
        res.valid = res.valid & (res.n_used >= max(int(kw.get("min_samples", 3)), 2))
        if cens.any():
            sub = fn(x[cens], lo=lo, hi=hi, axis=1, **kw)
            for f in ("mu", "sigma", "n_used", "n_low", "n_high", "valid"):
                getattr(res, f)[cens] = getattr(sub, f)
        return res
    if method == "mean":
        return plain_mean(samples, lo=lo, hi=hi, **{k: v for k, v in kw.items() if k in ("min_samples", "axis")})
    raise DatasetError(f"robust_mean: method: expected one of {METHODS}, got {method!r}")
