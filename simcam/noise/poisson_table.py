"""Exact Poisson sampling by table inversion: Poisson(lam) = Poisson(floor(lam)) + Poisson(frac(lam)).

Superposition of independent Poisson variables is exact. ``Poisson(l0)`` for the
integer part ``l0`` is drawn by inversion of its CDF, tabulated once per ``l0``
(``scipy.special.pdtr``, exact regularised gamma) with a guide table (Chen &
Asau 1974) that gives the search a start index; the fractional part
``delta`` in [0, 1) is drawn by inversion of its CDF with the first four
thresholds unrolled (``P(K >= 4) < 0.019``) and a short loop for the rest.
Uniforms are float64, so the inversion is exact to float64 resolution
(2**-53): a table segment covers ``l0 +- (10 sqrt(l0) + 10)``; the mass outside
it is below 1e-20, i.e. unreachable by a float64 uniform.

Tables are built lazily in chunks of :data:`CHUNK` integer means and cached for
the process (about 16 bytes per entry; means up to 4096 need 3.6 M entries).
"""

from __future__ import annotations

import threading

import numpy as np
from scipy.special import pdtr

#: integer means per lazily built table chunk.
CHUNK = 256
#: largest mean handled by the table (above it: PTRS, see kernels.py).
LMAX = 4096
_LOCK = threading.Lock()
_CHUNKS: dict[int, tuple] = {}
# Flat global tables, rebuilt (concatenated) when a chunk is added.
_STATE: dict[str, np.ndarray] = {}


def _segment_bounds(l0: np.ndarray):
    half = np.ceil(10.0 * np.sqrt(l0) + 10.0)
    lo = np.maximum(0.0, l0 - half).astype(np.int64)
    hi = (l0 + half).astype(np.int64)
    return lo, hi


def _build_chunk(c: int):
    l0 = np.arange(c * CHUNK, (c + 1) * CHUNK, dtype=np.float64)
    lo, hi = _segment_bounds(l0)
    n = hi - lo + 1
    seg = np.repeat(np.arange(CHUNK), n)
    starts = np.concatenate([[0], np.cumsum(n)[:-1]])
    k = lo[seg] + (np.arange(seg.size) - starts[seg])
    cdf = pdtr(k.astype(np.float64), l0[seg])
    cdf[starts + n - 1] = 1.0  # the mass beyond hi (< 1e-20) joins the last entry
    # guide: for each segment, entries at i/n, i = 0..n-1 -> index (within the
    # segment) of the first cdf >= i/n, minus one for safety against rounding.
    key = seg.astype(np.float64) * 2.0 + cdf
    gi = np.arange(seg.size) - starts[seg]
    probes = seg.astype(np.float64) * 2.0 + gi / n[seg]
    pos = np.searchsorted(key, probes, side="left") - 1
    pos = np.maximum(pos, starts[seg])
    guide_local = pos - starts[seg]
    return l0, lo, n, cdf, guide_local


def _ensure(max_l0: int) -> dict[str, np.ndarray]:
    need = max_l0 // CHUNK
    if _STATE and _STATE["nchunks"][0] > need:
        return _STATE
    with _LOCK:
        if _STATE and _STATE["nchunks"][0] > need:
            return _STATE
        nch = max(need + 1, int(_STATE["nchunks"][0]) if _STATE else 0)
        for c in range(nch):
            if c not in _CHUNKS:
                _CHUNKS[c] = _build_chunk(c)
        los, ns, cdfs, guides = [], [], [], []
        for c in range(nch):
            _, lo, n, cdf, g = _CHUNKS[c]
            los.append(lo), ns.append(n), cdfs.append(cdf), guides.append(g)
        lo = np.concatenate(los)
        n = np.concatenate(ns)
        cdf = np.concatenate(cdfs)
        start = np.concatenate([[0], np.cumsum(n)[:-1]])
        guide = np.concatenate(guides) + np.repeat(start, n)
        _STATE.clear()
        _STATE.update(
            nchunks=np.array([nch]),
            start=start.astype(np.int64),
            nf=n.astype(np.float64),
            base=(start - lo).astype(np.int64),  # count = absolute index - base
            cdf=cdf,
            guide=guide.astype(np.int64),
        )
        return _STATE


def poisson_table(rng: np.random.Generator, lam: np.ndarray) -> np.ndarray:
    """Exact Poisson counts (float32) for float32 means in [0, LMAX)."""
    lam = np.asarray(lam, dtype=np.float32).ravel()
    if lam.size == 0:
        return np.zeros(0, np.float32)
    l0 = lam.astype(np.int64)  # floor for lam >= 0
    st = _ensure(int(l0.max()))
    # -- integer part: guide-table inversion --------------------------------
    u = rng.random(lam.size)
    j = u * st["nf"][l0]
    j = j.astype(np.int64)
    j += st["start"][l0]
    k = st["guide"][j]
    cdf = st["cdf"]
    need = cdf[k] < u
    idx = np.flatnonzero(need)
    while idx.size:
        k[idx] += 1
        idx = idx[cdf[k[idx]] < u[idx]]
    k -= st["base"][l0]
    # -- fractional part delta in [0, 1): inversion, four thresholds unrolled
    delta = (lam - l0).astype(np.float64)
    u2 = rng.random(lam.size)
    p = np.exp(-delta)
    t = p.copy()
    k2 = (u2 > t).astype(np.int64)
    for i in (1, 2, 3):
        p *= delta
        p /= i
        t += p
        k2 += u2 > t
    rest = np.flatnonzero(k2 == 4)
    if rest.size:
        d, uu, pp, tt = delta[rest], u2[rest], p[rest], t[rest]
        kk = np.full(rest.size, 4, np.int64)
        live = np.arange(rest.size)
        i = 3
        while live.size:
            i += 1
            pp[live] *= d[live] / i
            tt[live] += pp[live]
            go = (uu[live] > tt[live]) & (pp[live] > 0.0)
            live = live[go]
            kk[live] += 1
        k2[rest] = kk
    k += k2
    return k.astype(np.float32)
