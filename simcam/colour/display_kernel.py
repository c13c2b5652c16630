"""Fused display tail: ``3x3 matrix -> clip -> transfer curve -> output samples`` in one parallel pass.

The stage-by-stage render makes five full-image passes after demosaicking
(camera -> XYZ, XYZ -> sRGB, clip, sRGB OETF, quantisation), each reading and
writing 144 MB at 12 MP. :func:`encode_display` does them in one numba loop
over rows (``prange``; every pixel is computed independently, so the output
is byte-identical whatever the thread count):

1. ``v = M x`` in float32 (``M`` the product of the stages' matrices);
2. ``v = min(max(v, lo), hi)`` (the clips; ``lo``/``hi`` may be infinite);
3. the transfer curve: ``srgb`` (IEC 61966-2-1 OETF: ``12.92 v`` for
   ``v <= 0.0031308``, else ``1.055 v^(1/2.4) - 0.055``) or ``linear`` (none);
4. the output: ``uint8``/``uint16`` samples ``round(clip(y, 0, 1) (2^b - 1))``,
   or float32 / half values.

The ``srgb`` curve interpolates a table of the float64 curve linearly on
[0, 1] (2^16 intervals; within 1e-6 of the float64 curve, so integer samples
differ from quantising the exact curve by at most one code, where a value lies
that close to a code boundary) and uses the exact formula outside [0, 1].
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

#: linear-value steps of the tables on [0, 1]
LUT_STEPS = 65535

_SRGB_A, _SRGB_T = 0.055, 0.0031308


def srgb_oetf64(x: np.ndarray) -> np.ndarray:
    """The IEC 61966-2-1 OETF in float64 (the tables' source)."""
    x = np.asarray(x, dtype=np.float64)
    return np.where(x <= _SRGB_T, 12.92 * x, 1.055 * np.power(np.maximum(x, _SRGB_T), 1.0 / 2.4) - _SRGB_A)


def value_table(curve: str) -> np.ndarray:
    """Curve values at ``i / LUT_STEPS`` (float32, length LUT_STEPS + 2; the last entry repeats)."""
    x = np.arange(LUT_STEPS + 2, dtype=np.float64) / LUT_STEPS
    x[-1] = 1.0
    y = srgb_oetf64(x) if curve == "srgb" else x
    return y.astype(np.float32)


@njit(inline="always")
def _curve(v, table, srgb):  # pragma: no cover - compiled
    if not srgb:
        return v
    if v >= np.float32(0.0) and v <= np.float32(1.0):
        t = v * np.float32(LUT_STEPS)
        k = np.int32(t)
        f = t - np.float32(k)
        return table[k] + f * (table[k + 1] - table[k])
    if v < np.float32(0.0):
        return v * np.float32(12.92)
    return np.float32(1.055 * np.exp(np.log(np.float64(v)) / 2.4) - 0.055)


@njit(cache=True, parallel=True, nogil=True)
def _encode(rgb, m, lo, hi, table, srgb, top, out):  # pragma: no cover - compiled
    """``top > 0``: integer samples ``rint(clip(y, 0, 1) top)``; ``top == 0``: float values."""
    h, w = rgb.shape[0], rgb.shape[1]
    bad = np.zeros(h, np.uint8)
    for i in prange(h):
        for j in range(w):
            r, g, b = rgb[i, j, 0], rgb[i, j, 1], rgb[i, j, 2]
            for c in range(3):
                v = m[c, 0] * r + m[c, 1] * g + m[c, 2] * b
                if not np.isfinite(v):
                    bad[i] = 1
                    v = np.float32(0.0)
                v = _curve(min(max(v, lo), hi), table, srgb)
                if top > 0:
                    v = np.rint(min(max(v, np.float32(0.0)), np.float32(1.0)) * top)
                out[i, j, c] = v
    return bad.any()


def encode_display(rgb: np.ndarray, matrix: np.ndarray, *, lo: float | None = None, hi: float | None = None,
                   curve: str = "srgb", depth: str = "uint8") -> np.ndarray:
    """``depth`` samples of ``curve(clip(M rgb, lo, hi))`` for an H x W x 3 float32 image.

    Parameters
    ----------
    rgb : ndarray
        H x W x 3 float32 (linear).
    matrix : ndarray
        3 x 3 applied per pixel (``out[..., i] = sum_j M[i, j] rgb[..., j]``, float32 arithmetic).
    lo, hi : float or None
        Clip bounds applied after the matrix (None: no bound).
    curve : {"srgb", "linear"}
        Transfer curve after the clip.
    depth : {"uint8", "uint16", "float32", "half"}
        Output sample type; integer types take [0, 1] to full scale, clipped.

    Returns
    -------
    ndarray
        H x W x 3 of ``depth``.

    Raises
    ------
    ValueError
        If the matrix product has a NaN or infinite value.
    """
    if curve not in ("srgb", "linear"):
        raise ValueError(f"encode_display: curve: expected 'srgb' or 'linear', got {curve!r}")
    rgb = np.ascontiguousarray(rgb, dtype=np.float32)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"encode_display: expected an H x W x 3 image, got shape {rgb.shape}")
    m = np.ascontiguousarray(matrix, dtype=np.float32)
    flo = np.float32(-np.inf if lo is None else lo)
    fhi = np.float32(np.inf if hi is None else hi)
    h, w = rgb.shape[:2]
    if depth not in ("uint8", "uint16", "float32", "half"):
        raise ValueError(f"encode_display: depth: expected uint8, uint16, float32 or half, got {depth!r}")
    top = np.float32({"uint8": 255, "uint16": 65535}.get(depth, 0))
    out = np.empty((h, w, 3), depth if top else np.float32)
    bad = _encode(rgb, m, flo, fhi, value_table("srgb"), curve == "srgb", top, out)
    if depth == "half":
        out = out.astype(np.float16)
    if bad:
        raise ValueError("image data contains NaN or infinite values")
    return out


@njit(cache=True, parallel=True, nogil=True)
def _quantise(flat, top, out):  # pragma: no cover - compiled
    n = flat.size
    chunk = 1 << 16
    nchunks = (n + chunk - 1) // chunk
    bad = np.zeros(nchunks, np.uint8)
    for k in prange(nchunks):
        for i in range(k * chunk, min(n, (k + 1) * chunk)):
            v = flat[i]
            if not np.isfinite(v):
                bad[k] = 1
                v = np.float32(0.0)
            v = min(max(v, np.float32(0.0)), np.float32(1.0))
            out[i] = np.rint(v * top)
    return bad.any()


def quantise(data: np.ndarray, depth: str) -> np.ndarray:
    """``round(clip(x, 0, 1) * (2^b - 1))`` as ``uint8``/``uint16`` (round half to even), in parallel.

    Same values as ``np.round(np.clip(x, 0, 1) * top).astype(depth)`` on float32 data.

    Raises
    ------
    ValueError
        If ``data`` has a NaN or infinite value.
    """
    x = np.ascontiguousarray(data, dtype=np.float32)
    out = np.empty(x.shape, dtype=depth)
    top = np.float32(255 if depth == "uint8" else 65535)
    if _quantise(x.reshape(-1), top, out.reshape(-1)):
        raise ValueError("image data contains NaN or infinite values")
    return out
