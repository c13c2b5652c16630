"""Fast exact samplers (float32 kernels) used by the noise models.

``normal_f32``
    Box-Muller transform (Box & Muller 1958, doi:10.1214/aoms/1177706645) with a
    float64 radius uniform (53-bit, so the tail is exact out to 8.5 sigma) and a
    float32 angle. Exact in distribution up to floating-point rounding; about
    3x faster than ``Generator.standard_normal(dtype=float32)`` on large blocks.

``poisson_f32``
    Exact Poisson counts for an array of means (vectorised numpy; the
    Poisson-Gaussian models now sample with the faster table kernel of
    :mod:`simcam.noise.kernels.poisson`, this remains as an independent exact
    sampler). lambda >= 10: the transformed
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

Temporaries live in a per-thread workspace of reusable buffers (:class:`_Workspace`):
allocating fresh half-megabyte arrays for every block makes glibc hand memory
back to the OS and fault it in again, which costs more than the arithmetic.
Kernels therefore write into ``out`` arrays and never return workspace views.
"""

from __future__ import annotations

import threading

import numpy as np

_F32 = np.float32
_TWO_PI32 = np.float32(2.0 * np.pi)
#: float32 margin (nats) below which the PTRS acceptance test is redone in float64.
_BAND = np.float32(2.0e-2)
_PTRS_MIN = 10.0
_UNROLL = 12
#: proposals per rejected element in PTRS rounds after the first.
_RETRY = 4


class _Workspace(threading.local):
    """Per-thread named scratch buffers, grown on demand and reused."""

    def __init__(self) -> None:
        self.bufs: dict[tuple[str, str], np.ndarray] = {}

    def get(self, name: str, n: int, dtype=np.float32) -> np.ndarray:
        key = (name, np.dtype(dtype).str)
        a = self.bufs.get(key)
        if a is None or a.size < n:
            a = np.empty(max(int(n), 1), dtype=dtype)
            self.bufs[key] = a
        return a[:n]


_W = _Workspace()


def normal_f32(rng: np.random.Generator, n: int, out: np.ndarray | None = None) -> np.ndarray:
    """``n`` standard normal variates, float32 (Box-Muller, see module docstring)."""
    m = (n + 1) // 2
    u1 = _W.get("bm_u1", m, np.float64)
    rng.random(out=u1)  # [0, 1)
    np.subtract(1.0, u1, out=u1)  # (0, 1]
    np.log(u1, out=u1)
    u1 *= -2.0
    np.sqrt(u1, out=u1)
    r = _W.get("bm_r", m)
    r[...] = u1
    t = _W.get("bm_t", m)
    rng.random(out=t, dtype=np.float32)
    t *= _TWO_PI32
    if out is None:
        out = np.empty(n, dtype=np.float32)
    out = out.reshape(-1)
    full = out if n == 2 * m else _W.get("bm_full", 2 * m)
    np.cos(t, out=full[:m])
    np.sin(t, out=full[m:])
    full[:m] *= r
    full[m:] *= r
    if full is not out:
        out[:] = full[:n]
    return out


def poisson_f32(rng: np.random.Generator, lam: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Exact Poisson(lam) counts as float32 (``lam`` float32, finite, >= 0, < 2**22).

    Parameters
    ----------
    rng : numpy Generator
    lam : ndarray
        Means, any shape.
    out : ndarray, optional
        float32 output of ``lam``'s size.

    Returns
    -------
    ndarray
        float32 integer-valued counts, shape of ``lam`` (or ``out``).
    """
    lam = np.ascontiguousarray(lam, dtype=np.float32)
    flat = lam.reshape(-1)
    if out is None:
        out = np.empty(lam.shape, dtype=np.float32)
    o = out.reshape(-1)
    small = np.flatnonzero(flat < _PTRS_MIN)
    if small.size == flat.size:
        o[:] = 0
    elif small.size:
        # PTRS on every element (means below 10 clamped: cheaper than gathering
        # the large ones), then the small ones are overwritten by inversion.
        lc = _W.get("lam_clamped", flat.size)
        np.maximum(flat, _F32(_PTRS_MIN), out=lc)
        _ptrs(rng, lc, o)
    else:
        _ptrs(rng, flat, o)
    if small.size:
        ls = flat[small].astype(np.float64)
        pos = ls > 0
        ks = np.zeros(small.size, np.float32)
        if pos.any():
            ks[pos] = _inversion(rng, ls[pos])
        o[small] = ks
    return out


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


def _ptrs(rng: np.random.Generator, lam: np.ndarray, out: np.ndarray) -> None:
    """Vectorised PTRS for lam >= 10 into ``out`` (float32 fast path, float64 decisions near the boundary).

    Round 1 makes one proposal per element. The rejected ones (about 10 %) get
    ``_RETRY`` i.i.d. proposals each per further round and keep the first
    accepted one, which is the sequential rejection loop unrolled (exact).
    """
    accept = _W.get("acc1", lam.size, np.bool_)
    _ptrs_round(rng, lam, out, accept, tag="r1")
    pending = np.flatnonzero(~accept)
    while pending.size:
        n = pending.size
        lm = np.repeat(lam[pending], _RETRY)
        kk = np.empty(lm.size, np.float32)
        aa = np.empty(lm.size, np.bool_)
        _ptrs_round(rng, lm, kk, aa, tag="r2")
        aa = aa.reshape(n, _RETRY)
        got = aa.any(axis=1)
        first = aa.argmax(axis=1)
        out[pending[got]] = kk.reshape(n, _RETRY)[got, first[got]]
        pending = pending[~got]


def _ptrs_round(rng: np.random.Generator, lm: np.ndarray, k: np.ndarray, accept: np.ndarray, *, tag: str) -> None:
    """One PTRS proposal per element: ``k`` and the exact acceptance decision ``accept``."""
    f32 = _F32
    m = lm.size
    w = lambda name: _W.get(f"{tag}_{name}", m)  # noqa: E731
    b, a, vr, u, v, us = w("b"), w("a"), w("vr"), w("u"), w("v"), w("us")
    np.sqrt(lm, out=b)
    b *= f32(2.53)
    b += f32(0.931)
    np.multiply(b, f32(0.02483), out=a)
    a -= f32(0.059)
    np.subtract(b, f32(2.0), out=vr)
    np.divide(f32(-3.6224), vr, out=vr)
    vr += f32(0.9277)
    rng.random(out=u, dtype=np.float32)
    u -= f32(0.5)
    rng.random(out=v, dtype=np.float32)
    np.abs(u, out=us)
    np.subtract(f32(0.5), us, out=us)  # in (0, 0.5]; 0 only for u = -0.5 (then rejected)
    np.multiply(a, f32(2.0), out=k)
    with np.errstate(divide="ignore", invalid="ignore"):
        k /= us
    k += b
    k *= u
    k += lm
    k += f32(0.43)
    np.floor(k, out=k)
    np.greater_equal(us, f32(0.07), out=accept)
    sq = _W.get(f"{tag}_sq", m, np.bool_)
    np.less_equal(v, vr, out=sq)
    accept &= sq
    # Draws outside the squeeze take the exact test (PTRS rejects k < 0 and
    # (us < 0.013 and v > us) outright, inside _ptrs_test).
    idx = np.flatnonzero(~accept)
    if idx.size:
        g = [np.take(x, idx, out=_W.get(f"{tag}_g{j}", idx.size)) for j, x in enumerate((lm, k, us, v, b, a))]
        accept[idx] = _ptrs_test(*g)


def _ptrs_test(lm, k, us, v, b, a) -> np.ndarray:
    """Exact PTRS acceptance ``log(v inv_alpha / (a/us^2 + b)) <= log p(k)`` (bool array).

    Evaluated in float32 with the Stirling form
    ``log p(k) = -(k log1p(d/lam) - d) - 0.5 log(2 pi k) - (1/(12k) - 1/(360k^3))``,
    ``d = k - lam`` (series truncation < 1/(1260 k^5) < 1e-7 for k >= 8); where
    the float32 margin is below ``_BAND`` (or k < 8) it is decided in float64
    with ``gammaln``, so every decision equals the float64 one.
    """
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return _ptrs_test_impl(lm, k, us, v, b, a)


def _ptrs_test_impl(lm, k, us, v, b, a) -> np.ndarray:
    f32 = _F32
    n = k.size
    w = lambda name: _W.get(f"t_{name}", n)  # noqa: E731
    ia, den, lhs, kk, d, t = w("ia"), w("den"), w("lhs"), w("kk"), w("d"), w("t")
    np.subtract(b, f32(3.4), out=ia)
    np.divide(f32(1.1328), ia, out=ia)
    ia += f32(1.1239)
    np.multiply(us, us, out=den)
    np.divide(a, den, out=den)
    den += b
    np.multiply(v, ia, out=lhs)
    lhs /= den
    np.log(lhs, out=lhs)
    np.maximum(k, f32(8.0), out=kk)
    np.subtract(kk, lm, out=d)
    np.divide(d, lm, out=t)
    np.log1p(t, out=t)
    t *= kk
    t -= d
    lhs += t  # lhs - rhs accumulated in place
    np.multiply(kk, _TWO_PI32, out=t)
    np.log(t, out=t)
    t *= f32(0.5)
    lhs += t
    np.multiply(kk, kk, out=t)
    t *= kk
    np.divide(f32(1.0 / 360.0), t, out=t)
    np.divide(f32(1.0 / 12.0), kk, out=d)
    d -= t
    lhs += d
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
        from scipy.special import gammaln  # imported here: 0.1 s of every process start otherwise

        rhs64 = -l64 + k64 * np.log(l64) - gammaln(k64 + 1.0)
        accept[idx] = lhs64 <= rhs64
    return accept
