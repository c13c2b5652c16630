"""Fast exact samplers (float32 kernels) used by the noise models.

``normal_f32``
    Box-Muller transform (Box & Muller 1958, doi:10.1214/aoms/1177706645) with a
    float64 radius uniform (53-bit, so the tail is exact out to 8.5 sigma) and a
    float32 angle. Exact in distribution up to floating-point rounding; about
    3x faster than ``Generator.standard_normal(dtype=float32)`` on large blocks.

``poisson_f32``
    Exact Poisson counts for an array of means. lambda >= 10: the transformed
    rejection with squeeze of Hoermann (1993), "The transformed rejection method
    for generating Poisson random variables", Insurance: Mathematics and
    Economics 12, 39-45 (doi:10.1016/0167-6687(93)90997-4), the algorithm numpy
    itself uses (PTRS), vectorised. The exact acceptance test
    ``log(v * inv_alpha / (a / us^2 + b)) <= log p(k)`` is first evaluated in
    float32 with the Stirling form of ``log p(k)``; only draws whose float32
    margin is within ``_BAND`` (far above the float32 error bound) are decided
    again in float64 with ``scipy.special.gammaln``, so every decision is the
    float64 one. lambda < 10: sequential inversion of the CDF in float64.
    No normal approximation is used anywhere.
"""

from __future__ import annotations

import numpy as np
from scipy.special import gammaln

_TWO_PI32 = np.float32(2.0 * np.pi)
#: float32 margin (nats) below which the PTRS acceptance test is redone in float64.
_BAND = np.float32(2.0e-2)
_PTRS_MIN = 10.0
_UNROLL = 12
#: proposals per rejected element in PTRS rounds after the first.
_RETRY = 4


def normal_f32(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` standard normal variates, float32 (Box-Muller, see module docstring)."""
    m = (n + 1) // 2
    u1 = rng.random(m)  # [0, 1), float64
    np.subtract(1.0, u1, out=u1)  # (0, 1]
    np.log(u1, out=u1)
    u1 *= -2.0
    np.sqrt(u1, out=u1)
    r = u1.astype(np.float32)
    t = rng.random(m, dtype=np.float32)
    t *= _TWO_PI32
    out = np.empty(2 * m, dtype=np.float32)
    np.cos(t, out=out[:m])
    np.sin(t, out=out[m:])
    out[:m] *= r
    out[m:] *= r
    return out[:n]


def poisson_f32(rng: np.random.Generator, lam: np.ndarray) -> np.ndarray:
    """Exact Poisson(lam) counts as float32 (``lam`` float32, finite, >= 0, < 2**22).

    Parameters
    ----------
    rng : numpy Generator
    lam : ndarray
        Means, any shape (flattened internally).

    Returns
    -------
    ndarray
        float32 integer-valued counts, same shape as ``lam``.
    """
    lam = np.ascontiguousarray(lam, dtype=np.float32)
    flat = lam.reshape(-1)
    small = np.flatnonzero(flat < _PTRS_MIN)
    if small.size == flat.size:
        out = np.zeros(flat.size, dtype=np.float32)
    else:
        # PTRS on every element (means below 10 clamped: cheaper than gathering
        # the large ones), then the small ones are overwritten by inversion.
        out = _ptrs(rng, np.maximum(flat, np.float32(_PTRS_MIN)) if small.size else flat)
    if small.size:
        ls = flat[small].astype(np.float64)
        pos = ls > 0
        ks = np.zeros(small.size, np.float32)
        if pos.any():
            ks[pos] = _inversion(rng, ls[pos])
        out[small] = ks
    return out.reshape(lam.shape)


def _inversion(rng: np.random.Generator, lam: np.ndarray) -> np.ndarray:
    """Sequential-search inversion for small means (float64), exact.

    The first ``_UNROLL`` CDF steps are evaluated for every element at once;
    the few elements beyond continue in a loop.
    """
    u = rng.random(lam.size)
    p = np.exp(-lam)
    cdf = p.copy()
    k = (u > cdf).astype(np.float64)
    for j in range(1, _UNROLL):
        p *= lam
        p /= j
        cdf += p
        k += u > cdf
    idx = np.flatnonzero(u > cdf)
    j = _UNROLL - 1
    while idx.size:
        j += 1
        p_i = p[idx] * lam[idx] / j
        p[idx] = p_i
        cdf[idx] += p_i
        # cdf rounding can stall just below u for u within 1e-16 of 1: stop once
        # the term underflows (the remaining mass is below float64 resolution).
        keep = (u[idx] > cdf[idx]) & (p_i > 0.0)
        k[idx[keep]] += 1
        idx = idx[keep]
    return k.astype(np.float32)


def _ptrs_consts(lam: np.ndarray):
    slam = np.sqrt(lam)
    b = slam * np.float32(2.53)
    b += np.float32(0.931)
    a = b * np.float32(0.02483)
    a -= np.float32(0.059)
    vr = np.float32(-3.6224) / (b - np.float32(2.0))
    vr += np.float32(0.9277)
    return b, a, vr


def _ptrs(rng: np.random.Generator, lam: np.ndarray) -> np.ndarray:
    """Vectorised PTRS for lam >= 10 (float32 fast path, float64 decisions near the boundary).

    Round 1 makes one proposal per element. The rejected ones (about 10 %) get
    ``_RETRY`` i.i.d. proposals each per further round and keep the first
    accepted one, which is the sequential rejection loop unrolled (exact).
    """
    k, accept = _ptrs_round(rng, lam)
    pending = np.flatnonzero(~accept)
    while pending.size:
        n = pending.size
        kk, aa = _ptrs_round(rng, np.repeat(lam[pending], _RETRY))
        aa = aa.reshape(n, _RETRY)
        got = aa.any(axis=1)
        first = aa.argmax(axis=1)
        k[pending[got]] = kk.reshape(n, _RETRY)[got, first[got]]
        pending = pending[~got]
    return k


def _ptrs_round(rng: np.random.Generator, lm: np.ndarray):
    """One PTRS proposal per element: (k, accepted) with the exact acceptance decision."""
    f32 = np.float32
    m = lm.size
    b, a, vr = _ptrs_consts(lm)
    u = rng.random(m, dtype=np.float32)
    u -= f32(0.5)
    v = rng.random(m, dtype=np.float32)
    us = np.abs(u)
    np.subtract(f32(0.5), us, out=us)  # in (0, 0.5]; 0 only for u = -0.5 (then rejected below)
    k = a * f32(2.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        k /= us
    k += b
    k *= u
    k += lm
    k += f32(0.43)
    np.floor(k, out=k)
    accept = us >= f32(0.07)
    accept &= v <= vr
    # Draws outside the squeeze take the exact test (PTRS rejects k < 0 and
    # (us < 0.013 and v > us) outright, inside _ptrs_test).
    idx = np.flatnonzero(~accept)
    if idx.size:
        accept[idx] = _ptrs_test(lm.take(idx), k.take(idx), us.take(idx), v.take(idx),
                                 b.take(idx), a.take(idx))
    return k, accept


def _ptrs_test(lm, k, us, v, b, a) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return _ptrs_test_impl(lm, k, us, v, b, a)


def _ptrs_test_impl(lm, k, us, v, b, a) -> np.ndarray:
    """Exact PTRS acceptance ``log(v inv_alpha / (a/us^2 + b)) <= log p(k)`` (bool array).

    Evaluated in float32 with the Stirling form
    ``log p(k) = -(k log1p(d/lam) - d) - 0.5 log(2 pi k) - (1/(12k) - 1/(360k^3))``,
    ``d = k - lam`` (series truncation < 1/(1260 k^5) < 1e-7 for k >= 8); where
    the float32 margin is below ``_BAND`` (or k < 8) it is decided in float64
    with ``gammaln``, so every decision equals the float64 one.
    """
    f32 = np.float32
    inv_alpha = b - f32(3.4)
    np.divide(f32(1.1328), inv_alpha, out=inv_alpha)
    inv_alpha += f32(1.1239)
    den = us * us
    np.divide(a, den, out=den)
    den += b
    lhs = v * inv_alpha
    lhs /= den
    np.log(lhs, out=lhs)
    kk = np.maximum(k, f32(8.0))
    d = kk - lm
    t = d / lm
    np.log1p(t, out=t)
    t *= kk
    t -= d
    lhs += t  # lhs - rhs accumulated in place
    st = kk * f32(2.0 * np.pi)
    np.log(st, out=st)
    st *= f32(0.5)
    lhs += st
    k3 = kk * kk
    k3 *= kk
    np.divide(f32(1.0 / 360.0), k3, out=k3)
    np.subtract(f32(1.0 / 12.0) / kk, k3, out=k3)
    lhs += k3
    ok = k >= 0
    ok &= ~((us < f32(0.013)) & (v > us))
    accept = lhs <= 0
    accept &= ok
    unsure = np.abs(lhs) < _BAND
    unsure |= k < f32(8.0)
    unsure &= ok
    idx = np.flatnonzero(unsure)
    if idx.size:
        l64 = lm[idx].astype(np.float64)
        k64 = k[idx].astype(np.float64)
        us64 = us[idx].astype(np.float64)
        v64 = v[idx].astype(np.float64)
        b64 = 0.931 + 2.53 * np.sqrt(l64)
        a64 = -0.059 + 0.02483 * b64
        ia64 = 1.1239 + 1.1328 / (b64 - 3.4)
        lhs64 = np.log(v64 * ia64 / (a64 / (us64 * us64) + b64))
        rhs64 = -l64 + k64 * np.log(l64) - gammaln(k64 + 1.0)
        accept[idx] = lhs64 <= rhs64
    return accept
