"""Exact Poisson-Gaussian sampling with cached alias tables (numba kernel).

``noisy = scale * Poisson(clean / scale) + sd * N(0, 1)`` per pixel, exact in
distribution (no normal approximation), in one compiled kernel.

Poisson part: decomposition into independent Poisson parts
    ``lam = 64 a + m + j / 32 + r`` (``a >= 0``, integer ``0 <= m < 64``,
    ``0 <= j < 32``, ``0 <= r < 1/32``, all exact in float64), and
    ``Poisson(lam) = Poisson(64 a) + Poisson(m) + Poisson(j / 32) + Poisson(r)``
    (a sum of independent Poisson variables is Poisson with the summed mean).
    The first three are drawn from precomputed per-grid-mean tables with the
    alias method (Walker 1977, ACM TOMS 3(3), 253-256,
    doi:10.1145/355744.355749; Vose 1991, IEEE TSE 17(9), 972-975,
    doi:10.1109/32.92917): one 64-bit word per draw, no search loop, no
    data-dependent branch. ``Poisson(r)`` is 0 when ``u < 1 - r <= exp(-r)``
    (probability >= 0.97, no ``exp``), otherwise sequential inversion.
    Means ``lam >= TABLE_LAMBDA_MAX`` use PTRS (Hoermann 1993,
    doi:10.1016/0167-6687(93)90997-4, the float64 algorithm numpy uses).

Tables (numerically exact, documented truncation): the pmf of each grid mean
is built by the ratio recurrence ``p(k+1)/p(k) = lam/(k+1)`` from the mode in
extended precision (``np.longdouble``) and normalised; the two tails are cut
where their mass is below ``2**-61`` each. The kept mass is renormalised and
quantised to integers (column capacity ``2**51``, the rounding units going to
the mode) and turned into an alias table by Vose's algorithm in exact integer
arithmetic. With ``n`` columns, the 128-bit product ``w * n`` of the 64-bit
word picks the column (high 64 bits: uniform to within ``2**-64``) and the
top 51 bits of its low 64 bits are compared with the column's threshold.
Total variation distance to the exact Poisson law: below ``2**-60`` (tails)
+ ``2**-51`` (quantisation and column choice) per table.
Coarse tables exist for ``64 a < 64 na``, ``na`` the power of two covering the
largest mean seen, and are cached (LRU on ``na``); a table's content does not
depend on ``na``, so neither do the samples. Building all tables up to mean
8192 takes well under a second (see ``benchmarks/noise.py``).

Gaussian part: ziggurat (Marsaglia & Tsang 2000, J. Stat. Softw. 5(8),
doi:10.18637/jss.v005.i08) with 256 layers, the layer, sign and 52-bit
abscissa from independent bits of one 64-bit word (as numpy does), the tail by
Marsaglia's exponential rejection; ``R`` is solved in float64 so that all
layers have equal area.

Uniform words: SplitMix64 (Steele, Lea & Flood 2014, "Fast splittable
pseudorandom number generators", OOPSLA, doi:10.1145/2660193.2660195) used as a
counter-based generator: pixel ``i`` of a kernel call uses the words at
counters ``seed0 + (5 i + q + 1) gamma``, ``q < 5`` (generated a pass at a time,
vectorised); the rare extra uniforms (ziggurat rejections, PTRS) come in order
from a second SplitMix64 stream at ``seed1``. The two 64-bit seeds are drawn
from the row block's numpy Generator (:func:`simcam.noise.base.block_rng`), so
the output depends only on (frame key, block, clean values), never on threads
or chunk sizes.
"""

from __future__ import annotations

import math
import threading
from functools import lru_cache

import numpy as np
from numba import njit

#: coarse grid step of the Poisson decomposition.
A_STEP = 64
#: fine grid: means j / FINE in [0, 1).
FINE = 32
#: table indices: fine j (mean j / FINE) at j, integer m (mean m < A_STEP) at
#: FINE + m, coarse a (mean A_STEP a) at N_FINE + a.
N_FINE = FINE + A_STEP
#: means at or above this use PTRS instead of tables.
TABLE_LAMBDA_MAX = 2**14
#: mass cut from each tail of a table.
TAIL_MASS = 2.0**-61
#: alias column capacity (threshold resolution 2**-51).
ALIAS_BITS = 51
#: bits of the alias index in a packed entry (tables have < 2**12 columns).
IDX_BITS = 12

_U11, _U8, _U1 = np.uint64(11), np.uint64(8), np.uint64(1)
_M52 = np.uint64((1 << 52) - 1)
_M8 = np.uint64(0xFF)
_MIDX = np.uint64((1 << IDX_BITS) - 1)
_UIDX = np.uint64(IDX_BITS)
_USH = np.uint64(64 - ALIAS_BITS)
_INV53 = 2.0**-53


# -- tables -------------------------------------------------------------------

def pmf_window(lam: float) -> tuple[int, np.ndarray]:
    """``(k0, p)``: Poisson(lam) probabilities (``np.longdouble``) on k0 .. k0+len-1.

    Built by the ratio recurrence from the mode in extended precision and
    normalised; tails of mass below :data:`TAIL_MASS` each are cut (see module
    docstring). ``p`` sums to 1 - (cut mass).
    """
    if lam <= 0:
        return 0, np.ones(1, dtype=np.longdouble)
    ld = np.longdouble
    m = int(math.floor(lam))
    half = int(math.ceil(12.0 * math.sqrt(lam) + 40.0))  # mass beyond < 1e-30
    lo, hi = max(0, m - half), m + half
    L = ld(lam)
    up = np.cumprod(L / np.arange(m + 1, hi + 1, dtype=ld))
    down = np.cumprod(np.arange(m, lo, -1, dtype=ld) / L)[::-1]
    w = np.concatenate([down, np.ones(1, dtype=ld), up])
    p = w / w.sum()
    cl = np.cumsum(p)
    cr = np.cumsum(p[::-1])[::-1]
    i0 = int(np.searchsorted(cl, ld(TAIL_MASS), side="left"))  # mass below i0 < TAIL
    i1 = int(np.nonzero(cr >= ld(TAIL_MASS))[0][-1])  # mass above i1 < TAIL
    return lo + i0, p[i0:i1 + 1]


def alias_counts(p: np.ndarray) -> np.ndarray:
    """Integer column masses of ``p`` (longdouble, n < 2**IDX_BITS entries): int64
    counts summing exactly to ``n * 2**ALIAS_BITS`` (the remaining rounding
    units go to the most probable entry)."""
    n = int(p.size)
    if n >= 1 << IDX_BITS:
        raise ValueError(f"table of {p.size} entries exceeds {1 << IDX_BITS}")
    total = n << ALIAS_BITS
    c = np.zeros(n, dtype=np.int64)
    c[:p.size] = np.floor(p / p.sum() * np.longdouble(total)).astype(np.int64)
    c[int(np.argmax(p))] += total - int(c.sum())
    return c


def alias_pack(c: np.ndarray) -> np.ndarray:
    """Walker/Vose alias table of integer column masses ``c`` (sum = n * 2**ALIAS_BITS), exact.

    Entry ``i`` packs ``threshold << IDX_BITS | alias``: column ``i`` yields
    ``i`` when a 51-bit uniform integer is below the threshold, else ``alias``.
    Pure Python integers (exact; no compile time).
    """
    M = 1 << ALIAS_BITS
    c = [int(x) for x in c]
    n = len(c)
    thr = [M] * n
    ali = list(range(n))
    small = [i for i in range(n) if c[i] < M]
    large = [i for i in range(n) if c[i] >= M]
    while small and large:
        s = small.pop()
        l = large[-1]  # noqa: E741
        thr[s], ali[s] = c[s], l
        c[l] -= M - c[s]
        if c[l] < M:
            small.append(large.pop())
    # what is left are full columns (exact integer masses): threshold M, alias itself
    return (np.array(thr, dtype=np.uint64) << np.uint64(IDX_BITS)) | np.array(ali, dtype=np.uint64)


def table_means(na: int) -> np.ndarray:
    """The grid means of the fine (j / FINE, j < N_FINE) and ``na`` coarse (A_STEP a) tables."""
    return np.concatenate([np.arange(FINE) / FINE, np.arange(A_STEP, dtype=np.float64),
                           A_STEP * np.arange(na, dtype=np.float64)])


@lru_cache(maxsize=8)
def build_tables(na: int):
    """Packed alias tables for the fine grid and ``na`` coarse means (cached).

    Returns ``(entries, start, size, k0)``: table ``t`` has ``size[t]``
    packed entries at ``entries[start[t]:]`` over counts ``k0[t] ...``; the
    fine and the integer tables have one size per level and ``k0 = 0``.
    """
    ents, k0s = [], []
    wins = [pmf_window(float(lam)) for lam in table_means(na)]
    # the fine and integer tables are padded with zero-mass columns to one
    # power-of-two width per level, from count 0: the kernel finds them without
    # a lookup of their offset, size or first count, and picks the column with
    # the top bits of the word (exactly uniform)
    for lo, hi in ((0, FINE), (FINE, N_FINE)):
        width = 1 << (max(k0 + p.size for k0, p in wins[lo:hi]) - 1).bit_length()
        for t in range(lo, hi):
            k0, p = wins[t]
            q = np.zeros(width, dtype=np.longdouble)
            q[k0:k0 + p.size] = p
            wins[t] = (0, q)
    for k0, p in wins:
        ents.append(alias_pack(alias_counts(p)))
        k0s.append(k0)
    size = np.array([e.size for e in ents], dtype=np.int64)
    start = np.concatenate([[0], np.cumsum(size)[:-1]]).astype(np.int64)
    return np.concatenate(ents), start, size, np.array(k0s, dtype=np.int64)


def table_pmf(tabs, t: int) -> tuple[int, np.ndarray]:
    """The exact law ``(k0, pmf)`` that table ``t`` samples (float64; for tests)."""
    ents, start, size, k0 = tabs
    n = int(size[t])
    e = ents[start[t]:start[t] + n]
    thr = (e >> np.uint64(IDX_BITS)).astype(np.float64) / 2.0**ALIAS_BITS
    ali = (e & _MIDX).astype(np.int64)
    pmf = thr / n
    np.add.at(pmf, ali, (1.0 - thr) / n)
    return int(k0[t]), pmf


def coarse_count(lam_max: float) -> int:
    """Number of coarse tables (a power of two, >= 1) covering means up to ``lam_max``."""
    need = int(min(lam_max, TABLE_LAMBDA_MAX - 1) // A_STEP) + 1
    return 1 << max(0, (need - 1).bit_length())


_BUILD_LOCK = threading.Lock()


def tables_for(lam_max: float):
    """The cached tables covering means up to ``lam_max`` (built on first use)."""
    with _BUILD_LOCK:
        return build_tables(coarse_count(lam_max))


# -- ziggurat constants ---------------------------------------------------------

def _tail_area(r: float) -> float:
    """Area under exp(-x^2/2) beyond ``r``: sqrt(pi/2) erfc(r / sqrt(2)) (``scipy.special.erfc``)."""
    from scipy.special import erfc

    return float(math.sqrt(math.pi / 2) * erfc(r / math.sqrt(2.0)))


def _zig_edges(r: float, tail: float | None = None) -> tuple[np.ndarray, float]:
    """Edges X_0..X_256 of the layers for tail start ``r`` and the top layer's area error.

    ``tail`` is :func:`_tail_area` of ``r`` (computed when not given).
    """
    f = lambda x: math.exp(-0.5 * x * x)  # noqa: E731
    v = r * f(r) + (_tail_area(r) if tail is None else tail)
    x = np.zeros(257)
    x[0], x[1] = v / f(r), r
    for i in range(1, 255):  # layer i: X_i (f(X_{i+1}) - f(X_i)) = v
        arg = v / x[i] + f(x[i])
        if arg >= 1.0:
            return x, -1.0 - (255 - i)  # ran out of height: r too small
        x[i + 1] = math.sqrt(-2.0 * math.log(arg))
    # top layer [0, X_255] x [f(X_255), 1] must have area v as well (X_256 = 0)
    return x, x[255] * (1.0 - f(x[255])) - v


#: Tail start R of the 256-layer ziggurat (G. Marsaglia and W. W. Tsang, "The Ziggurat Method for
#: Generating Random Variables", J. Stat. Softw. 5(8), 2000): the root of the top layer's area error
#: (:func:`_zig_edges`), exactly the float :func:`_zig_solve` finds (a test checks it). Stated here so
#: that importing the kernels does not import scipy.optimize (0.14 s of every process start).
ZIG_R_ROOT = 3.654152885361009
#: :func:`_tail_area` of :data:`ZIG_R_ROOT`, exactly as scipy computes it (a test checks it); stated so
#: that importing the kernels does not import scipy.special either (libm's ``math.erfc`` differs from
#: it in the last bit here, which would change every table and every noise sample).
ZIG_TAIL_AREA = 0.0003233957646633217


def _zig_solve() -> float:
    """Solve for R with Brent's method (``scipy.optimize.brentq``); :data:`ZIG_R_ROOT` is its result."""
    from scipy.optimize import brentq

    g = lambda r: _zig_edges(r)[1]  # noqa: E731
    return brentq(g, 3.4, 3.9, xtol=1e-15, rtol=4 * np.finfo(float).eps)


def ziggurat_tables():
    """``(R, k, w, f)`` for a 256-layer ziggurat of exp(-x^2/2) (see module docstring).

    Layer ``i`` spans x in [0, X_i] (X_0 = v / f(R) the base strip with the
    tail, X_1 = R, X_256 = 0 after the last one); ``k[i] = 2^52 X_{i+1} / X_i``,
    ``w[i] = X_i / 2^52``, ``f[i] = exp(-X_i^2 / 2)``.
    """
    r = ZIG_R_ROOT
    x, _ = _zig_edges(r, ZIG_TAIL_AREA)  # X_0 .. X_255, X_256 = 0
    k = np.floor(2.0**52 * x[1:] / x[:-1]).astype(np.uint64)
    w = x[:-1] / 2.0**52
    f = np.exp(-0.5 * x * x)
    return r, k, w, f


ZIG_R, ZIG_K, ZIG_W, ZIG_F = ziggurat_tables()


# -- kernel --------------------------------------------------------------------

_GAMMA = np.uint64(0x9E3779B97F4A7C15)
_C1 = np.uint64(0xBF58476D1CE4E5B9)
_C2 = np.uint64(0x94D049BB133111EB)


@njit(inline="always")
def _next(ctr):
    """SplitMix64 (Steele, Lea & Flood 2014): the word for counter ``ctr + gamma`` and the new counter."""
    ctr += _GAMMA
    z = ctr
    z = (z ^ (z >> np.uint64(30))) * _C1
    z = (z ^ (z >> np.uint64(27))) * _C2
    return z ^ (z >> np.uint64(31)), ctr


_M32 = np.uint64(0xFFFFFFFF)
_U32 = np.uint64(32)


@njit(inline="always")
def _lookup(w, t, ents, start, size, k0):
    """Alias-table draw from table ``t`` with one 64-bit word ``w``: column
    ``floor(w n / 2^64)`` (n = size), threshold test with the top 51 bits of
    ``w n mod 2^64`` (see module docstring)."""
    n = np.uint64(size[t])
    i = ((w >> _U32) * n + (((w & _M32) * n) >> _U32)) >> _U32
    e = ents[start[t] + np.int64(i)]
    col = i if ((w * n) >> _USH) < (e >> _UIDX) else (e & _MIDX)
    return k0[t] + np.int64(col)


@njit(inline="always")
def _log2(n):
    b = 0
    while (np.int64(1) << b) < n:
        b += 1
    return np.uint64(b)


@njit(inline="always")
def _lookup_fixed(w, off, b, ents):
    """:func:`_lookup` for a table of ``2**b`` columns at ``off`` (uint64) over
    counts 0, 1, ...: the top ``b`` bits of ``w`` pick the column, the next 51
    are compared with its threshold."""
    i = w >> (np.uint64(64) - b)
    e = ents[off + i]
    col = i if ((w << b) >> _USH) < (e >> _UIDX) else (e & _MIDX)
    return np.int64(col)


#: pixels per pass of the kernel (words are generated for a pass at once).
PASS = 512
#: 64-bit words per pixel from the main stream: coarse, integer, fine, remainder, normal.
WORDS = 5


@njit(inline="always")
def _mix(z):
    z = (z ^ (z >> np.uint64(30))) * _C1
    z = (z ^ (z >> np.uint64(27))) * _C2
    return z ^ (z >> np.uint64(31))


@njit(inline="always")
def _u53(w):
    return np.float64(np.int64(w >> _U11)) * _INV53  # signed: one instruction


@njit(inline="always")
def zig_normal(r, ctr, zk, zw, zf, zr):
    """Standard normal from the 64-bit word ``r`` (ziggurat, see module docstring): layer from
    the low 8 bits, sign from the next, 52-bit abscissa from the rest; the rare rejections
    (about 1.2 %) and tail draws take further words from the SplitMix64 stream at ``ctr``.
    Returns ``(z, ctr)`` (float64, the advanced counter)."""
    while True:
        idx = np.int64(r & _M8)
        r >>= _U8
        neg = (r & _U1) != 0
        rabs = (r >> _U1) & _M52
        z = np.float64(np.int64(rabs)) * zw[idx]
        if rabs < zk[idx]:
            break
        if idx == 0:
            while True:  # tail beyond R (Marsaglia 1964)
                r, ctr = _next(ctr)
                e1 = -math.log1p(-_u53(r)) / zr
                r, ctr = _next(ctr)
                e2 = -math.log1p(-_u53(r))
                if e2 + e2 > e1 * e1:
                    break
            z = zr + e1
            break
        r, ctr = _next(ctr)
        if zf[idx] + _u53(r) * (zf[idx + 1] - zf[idx]) < math.exp(-0.5 * z * z):
            break
        r, ctr = _next(ctr)
    if neg:
        z = -z
    return z, ctr


@njit(cache=True, nogil=True, error_model="numpy")
def pg_kernel(clean, scale, sd, out, seed, ents, start, size, k0, zk, zw, zf, zr):
    """Fill ``out`` (float32, 1-D) with ``scale * Poisson(clean / scale) + sd * z``.

    ``scale`` and ``sd`` are float32 arrays of length 1 (broadcast) or
    ``clean.size``. Pixel ``i`` uses the main-stream words ``4 i .. 4 i + 3``
    (SplitMix64 at counter ``seed[0] + (q + 1) gamma``, generated a pass at a
    time); the rare extra uniforms (ziggurat rejections, PTRS) come in order
    from the second stream at ``seed[1]``. Returns the number of means not
    covered by the tables (0 unless the caller passed too few coarse tables).
    """
    c0 = seed[0]
    ctr = seed[1]
    n = clean.size
    sst = 1 if scale.size > 1 else 0
    dst = 1 if sd.size > 1 else 0
    na = start.size - N_FINE
    n_f = size[0]  # fine tables: start j * n_f (a power of two)
    off_m = start[FINE]  # integer tables: start off_m + m * n_m
    n_m = size[FINE]
    b_f = _log2(n_f)
    b_m = _log2(n_m)
    bad = 0
    words = np.empty(PASS * WORDS, np.uint64)
    lamb = np.empty(PASS, np.float64)
    rrb = np.empty(PASS, np.float64)
    ta = np.empty(PASS, np.int64)
    tf = np.empty(PASS, np.uint64)
    tm = np.empty(PASS, np.uint64)
    kb = np.empty(PASS, np.int64)
    for p0 in range(0, n, PASS):
        m = min(PASS, n - p0)
        base = c0 + np.uint64(p0 * WORDS) * _GAMMA
        for q in range(m * WORDS):  # counter-based: vectorises
            words[q] = _mix(base + np.uint64(q + 1) * _GAMMA)
        # the work is split into short loops: one long dependency chain per
        # pixel (divide, convert, two dependent table loads...) would stall.
        if sst:
            for ii in range(m):
                lamb[ii] = np.float64(clean[p0 + ii] / scale[p0 + ii])  # float32 division
        else:
            sc0 = scale[0]
            for ii in range(m):
                lamb[ii] = np.float64(clean[p0 + ii] / sc0)
        for ii in range(m):
            lc = min(lamb[ii], TABLE_LAMBDA_MAX - 1.0)  # PTRS above (tables not used)
            ia = np.int64(lc * (1.0 / A_STEP))  # exact: A_STEP and FINE are powers of two
            rem = lc - ia * float(A_STEP)
            mi = np.int64(rem)
            rem -= mi
            j = np.int64(rem * FINE)
            rrb[ii] = rem - j * (1.0 / FINE)
            over = ia >= na
            bad += over
            ta[ii] = N_FINE + min(ia, na - 1)
            tm[ii] = np.uint64(off_m + mi * n_m)
            tf[ii] = np.uint64(j * n_f)
        # tables for mean 0 (a, m or j = 0) always give 0: no branches
        for ii in range(m):
            kb[ii] = (_lookup(words[ii * WORDS], ta[ii], ents, start, size, k0)
                      + _lookup_fixed(words[ii * WORDS + 1], tm[ii], b_m, ents)
                      + _lookup_fixed(words[ii * WORDS + 2], tf[ii], b_f, ents))
        for ii in range(m):
            i = p0 + ii
            lam = lamb[ii]
            wq = ii * WORDS
            sc = scale[i * sst]
            if lam < TABLE_LAMBDA_MAX:
                k = kb[ii]
                rr = rrb[ii]
                u = _u53(words[wq + 3])
                if u >= 1.0 - rr:  # else u < 1 - rr <= exp(-rr): Poisson(rr) = 0
                    pr = math.exp(-rr)
                    c = pr
                    kk = 0
                    while u >= c and pr > 0.0:
                        kk += 1
                        pr *= rr / kk
                        c += pr
                    k += kk
            else:
                # PTRS (Hoermann 1993), float64, as numpy's random_poisson_ptrs
                slam = math.sqrt(lam)
                loglam = math.log(lam)
                b = 0.931 + 2.53 * slam
                a = -0.059 + 0.02483 * b
                invalpha = 1.1239 + 1.1328 / (b - 3.4)
                vr = 0.9277 - 3.6224 / (b - 2.0)
                U = _u53(words[wq]) - 0.5
                V = _u53(words[wq + 1])
                while True:
                    us = 0.5 - abs(U)
                    kf = math.floor((2.0 * a / us + b) * U + lam + 0.43)
                    if us >= 0.07 and V <= vr:
                        break
                    if kf >= 0.0 and not (us < 0.013 and V > us):
                        if (math.log(V) + math.log(invalpha) - math.log(a / (us * us) + b)
                                <= -lam + kf * loglam - math.lgamma(kf + 1.0)):
                            break
                    r, ctr = _next(ctr)
                    U = _u53(r) - 0.5
                    r, ctr = _next(ctr)
                    V = _u53(r)
                k = np.int64(kf)
            sdv = sd[i * dst]
            val = np.float32(k) * sc
            if sdv != 0:
                # ziggurat standard normal, first try from the main stream
                z, ctr = zig_normal(words[wq + 4], ctr, zk, zw, zf, zr)
                val += sdv * np.float32(z)
            out[i] = val
    return bad


def _as_param(x, n: int) -> np.ndarray:
    a = np.asarray(x, dtype=np.float32)
    if a.ndim == 0 or a.size == 1:
        return a.reshape(1)
    a = np.ascontiguousarray(a).reshape(-1)
    if a.size != n:
        raise ValueError(f"parameter map of {a.size} values for {n} pixels")
    return a


def pg_sample_table(clean: np.ndarray, scale, sd, rng: np.random.Generator, out: np.ndarray, lam_max: float) -> np.ndarray:
    """``out = scale * Poisson(clean / scale) + sd * N(0, 1)`` (float32, exact; see module docstring).

    Parameters
    ----------
    clean : ndarray
        float32 clean values (>= 0), any shape; ``out`` has the same size.
    scale, sd : float32 scalar or map of ``clean``'s shape
        Poisson scale (> 0) and Gaussian standard deviation (>= 0).
    rng : numpy Generator
        Source of the kernel's two 64-bit SplitMix64 seeds.
    lam_max : float
        An upper bound of ``clean / scale`` (float32), selecting the tables.
    """
    c = np.ascontiguousarray(clean, dtype=np.float32).reshape(-1)
    if not out.flags.c_contiguous:
        tmp = np.empty(out.shape, np.float32)
        pg_sample_table(clean, scale, sd, rng, tmp, lam_max)
        out[...] = tmp
        return out
    o = out.reshape(-1)
    seed = rng.bit_generator.random_raw(2).astype(np.uint64)
    tabs = tables_for(lam_max)
    bad = pg_kernel(c, _as_param(scale, c.size), _as_param(sd, c.size), o, seed, *tabs, ZIG_K, ZIG_W, ZIG_F, ZIG_R)
    if bad:
        raise RuntimeError(f"poisson tables cover means below {A_STEP * (tabs[1].size - N_FINE)}, got larger ones")
    return out


def poisson_table_f32(rng: np.random.Generator, lam: np.ndarray) -> np.ndarray:
    """Exact Poisson(lam) counts (float32) through the same kernel (scale 1, no Gaussian)."""
    lam = np.ascontiguousarray(lam, dtype=np.float32)
    out = np.empty(lam.shape, np.float32)
    lam_max = float(lam.max()) if lam.size else 0.0
    return pg_sample_table(lam, np.float32(1.0), np.float32(0.0), rng, out, lam_max)
