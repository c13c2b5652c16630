"""Fused heteroscedastic Gaussian noise kernel: ``clip(x + sqrt(max(beta1 x + beta2, 0)) z)`` in one pass.

The NLF noise of Abdelhamed 2020 (eq. 5.2; clipped, eq. 5.3) for on-the-fly training
data, where drawing normals with numpy and then combining them in four array
passes costs more than the training step needs. One compiled loop reads the
clean value, draws ``z ~ N(0, 1)`` with the ziggurat of
:mod:`simcam.noise.kernels.poisson` (Marsaglia & Tsang 2000, 256 layers, exact
tail) from counter-based SplitMix64 words, and writes the clipped noisy value:
no temporaries, one read and one write per pixel (:func:`nlf_noise`; about 3.7x
faster than numpy's ``standard_normal`` alone for a 4 x 256 x 256 patch).
:func:`nlf_noise_packed` also packs the 2 x 2 Bayer crop into its four planes in
the same pass (training data: ``simcam.training.samplers``).

Randomness: element ``i`` takes the word at counter ``seed0 + (i + 1) gamma``
for its first ziggurat try (the words of a pass are generated together, which
vectorises); the rare rejections (about 1.2 %) take words in order from a
second SplitMix64 stream at ``seed1``. Both seeds come from the caller's numpy
Generator, so the output depends only on that generator and the inputs.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .poisson import _GAMMA, _M8, _M52, _U1, _U8, ZIG_F, ZIG_K, ZIG_R, ZIG_W, _mix, zig_normal

_U9 = np.uint64(9)
_ALL_ACCEPTED = np.uint64(0x0101010101010101)

#: elements whose first words are generated together (a multiple of 8).
PASS = 1024


@njit(inline="always")
def _normals(base, m, words, zb, first, first8, ctr, zk, zw, zf, zr):
    """Standard normals for the ``m`` counters ``base + (j + 1) gamma`` into ``zb[:m]`` (float32);
    ``first`` / ``first8`` are scratch flags of a length that is a multiple of 8. Returns the
    advanced rejection-stream counter."""
    for j in range(m):  # counter-based words: vectorises
        words[j] = _mix(base + np.uint64(j + 1) * _GAMMA)
    # the ziggurat's first try for every element (branch-free, vectorises) ...
    for j in range(m):
        w = words[j]
        idx = w & _M8
        rabs = (w >> _U9) & _M52
        sign = 1.0 - 2.0 * np.float64((w >> _U8) & _U1)
        zb[j] = np.float32(np.float64(np.int64(rabs)) * zw[idx] * sign)
        first[j] = np.uint8(rabs < zk[idx])
    for j in range(m, first.size):
        first[j] = 1
    # ... the rare rejected ones (about 1.2 %) redone in full from the same word, as zig_normal does;
    # 8 flags per word skip the runs of accepted first tries
    for g in range(first8.size):
        if first8[g] != _ALL_ACCEPTED:
            for j in range(8 * g, 8 * g + 8):
                if first[j] == 0:
                    z, ctr = zig_normal(words[j], ctr, zk, zw, zf, zr)
                    zb[j] = np.float32(z)
    return ctr


@njit(cache=True, nogil=True, error_model="numpy")
def _nlf_kernel(clean, beta1, beta2, lo, hi, out, seed, zk, zw, zf, zr):
    c0 = seed[0]
    ctr = seed[1]
    n = clean.size
    words = np.empty(PASS, np.uint64)
    zb = np.empty(PASS, np.float32)
    first = np.empty(PASS, np.uint8)
    first8 = first.view(np.uint64)
    for p0 in range(0, n, PASS):
        m = min(PASS, n - p0)
        ctr = _normals(c0 + np.uint64(p0) * _GAMMA, m, words, zb, first, first8, ctr, zk, zw, zf, zr)
        for ii in range(m):
            x = clean[p0 + ii]
            v = beta1 * x + beta2
            sd = np.float32(np.sqrt(max(v, np.float32(0.0))))
            y = x + sd * zb[ii]
            out[p0 + ii] = min(max(y, lo), hi)


def nlf_noise(clean: np.ndarray, beta1: float, beta2: float, rng: np.random.Generator, *,
              clip: tuple[float, float] | None = (0.0, 1.0), out: np.ndarray | None = None) -> np.ndarray:
    """Noisy copy of ``clean`` with variance ``beta1 * clean + beta2`` (Abdelhamed 2020, eq. 5.2), clipped (eq. 5.3).

    Parameters
    ----------
    clean : ndarray
        Clean signal, normalised raw (float32; any shape, made contiguous).
    beta1 : float
        Signal-dependent variance factor (>= 0), normalised raw units.
    beta2 : float
        Signal-independent variance (>= 0), normalised raw units squared.
    rng : numpy Generator
        Source of the kernel's two 64-bit seeds (two raw words are consumed).
    clip : (lo, hi) or None
        Clip range of the noisy values (default ``(0, 1)``); None keeps them unclipped.
    out : ndarray, optional
        float32 C-contiguous output of ``clean``'s size (may be ``clean`` itself).

    Returns
    -------
    ndarray
        float32 noisy values, ``clean``'s shape.
    """
    c = np.ascontiguousarray(clean, dtype=np.float32)
    if out is None:
        out = np.empty(c.shape, np.float32)
    elif out.dtype != np.float32 or not out.flags.c_contiguous or out.size != c.size:
        raise ValueError(f"nlf_noise: out must be C-contiguous float32 of {c.size} values, got "
                         f"{out.dtype} {out.shape}")
    lo, hi = (-np.inf, np.inf) if clip is None else clip
    seed = rng.bit_generator.random_raw(2).astype(np.uint64)
    _nlf_kernel(c.reshape(-1), np.float32(beta1), np.float32(beta2), np.float32(lo), np.float32(hi),
                out.reshape(-1), seed, ZIG_K, ZIG_W, ZIG_F, ZIG_R)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _nlf_pack_kernel(mosaic, beta1, beta2, lo, hi, clean_out, noisy_out, seed, zk, zw, zf, zr):
    """:func:`_nlf_kernel` reading a 2p x 2q mosaic crop and writing its packed planes
    (``clean_out``) and their noisy copy (``noisy_out``, both 4 x p x q) in the same pass; element
    (c, y, x) is element ``(c p + y) q + x`` of the packed array, so the output is byte-identical
    to packing first and calling :func:`_nlf_kernel` on the result."""
    p, q = clean_out.shape[1], clean_out.shape[2]
    c0 = seed[0]
    ctr = seed[1]
    q8 = (q + 7) // 8 * 8
    words = np.empty(q8, np.uint64)
    zb = np.empty(q8, np.float32)
    first = np.empty(q8, np.uint8)
    first8 = first.view(np.uint64)
    for c in range(4):
        dy = c // 2
        dx = c % 2
        for y in range(p):
            ctr = _normals(c0 + np.uint64((c * p + y) * q) * _GAMMA, q, words, zb, first, first8, ctr,
                           zk, zw, zf, zr)
            row = mosaic[2 * y + dy]
            for xx in range(q):
                x = row[2 * xx + dx]
                clean_out[c, y, xx] = x
                v = beta1 * x + beta2
                sd = np.float32(np.sqrt(max(v, np.float32(0.0))))
                yv = x + sd * zb[xx]
                noisy_out[c, y, xx] = min(max(yv, lo), hi)


def nlf_noise_packed(mosaic: np.ndarray, beta1: float, beta2: float, rng: np.random.Generator,
                     clean_out: np.ndarray, noisy_out: np.ndarray, *,
                     clip: tuple[float, float] | None = (0.0, 1.0)) -> None:
    """Pack a 2p x 2q mosaic crop into ``clean_out`` (4 x p x q, channels in
    :data:`simcam.cfa.PACK_OFFSETS` order) and write its NLF-noisy copy into ``noisy_out``, in one
    pass; same bytes as ``pack`` followed by :func:`nlf_noise` with the same ``rng``.

    Parameters
    ----------
    mosaic : ndarray
        float32 crop (may be a strided view of a larger mosaic), normalised raw.
    beta1, beta2, rng, clip
        As in :func:`nlf_noise`.
    clean_out, noisy_out : ndarray
        float32 C-contiguous 4 x p x q outputs.
    """
    p, q = clean_out.shape[1:]
    if (mosaic.dtype != np.float32 or mosaic.shape != (2 * p, 2 * q) or clean_out.shape != noisy_out.shape
            or clean_out.shape[0] != 4):
        raise ValueError(f"nlf_noise_packed: expected a float32 {2 * p}x{2 * q} crop and two 4x{p}x{q} outputs, "
                         f"got {mosaic.dtype} {mosaic.shape}, {clean_out.shape}, {noisy_out.shape}")
    for name, a in (("clean_out", clean_out), ("noisy_out", noisy_out)):
        if a.dtype != np.float32 or not a.flags.c_contiguous:
            raise ValueError(f"nlf_noise_packed: {name} must be C-contiguous float32, got {a.dtype}")
    lo, hi = (-np.inf, np.inf) if clip is None else clip
    seed = rng.bit_generator.random_raw(2).astype(np.uint64)
    _nlf_pack_kernel(mosaic, np.float32(beta1), np.float32(beta2), np.float32(lo), np.float32(hi),
                     clean_out, noisy_out, seed, ZIG_K, ZIG_W, ZIG_F, ZIG_R)
