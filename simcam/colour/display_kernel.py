"""Fused display tail: ``3x3 matrix -> clip -> transfer curve -> output samples`` in one pass over the image.

The stage-by-stage render makes five full-image passes after demosaicking
(camera -> XYZ, XYZ -> sRGB, clip, sRGB OETF, quantisation), each reading and
writing 144 MB at 12 MP. :func:`encode_display` works on bands of
:data:`BAND_ROWS` rows that stay in cache, on a thread pool (numpy releases the
GIL in its loops), with no just-in-time compiler to load (a command-line render
pays no start-up for it). Every pixel is computed independently with the same
float32 operations, so the output is byte-identical whatever the thread count:

1. ``v = (M[c, 0] r + M[c, 1] g) + M[c, 2] b`` in float32 (``M`` the product of the
   stages' matrices);
2. ``v = clip(v, lo, hi)`` (the clips; composed with [0, 1] for integer output);
3. the transfer curve: ``srgb`` (IEC 61966-2-1 OETF: ``12.92 v`` for
   ``v <= 0.0031308``, else ``1.055 v^(1/2.4) - 0.055``) or ``linear`` (none);
4. the output: ``uint8``/``uint16`` samples ``round(clip(y, 0, 1) (2^b - 1))``,
   or float32 / half values.

Integer outputs of the ``srgb`` curve read a table of codes indexed by the
linear value quantised to ``2^16`` (8-bit) or ``2^20`` (16-bit) steps on
[0, 1]: the table's code is exact at its grid points and a value is at most half
a step away, so it differs from quantising the exact curve by at most one code
(near black, where the curve is steepest, 12.92 x 65535 / 2^21 = 0.4 code; far
less elsewhere). Float outputs use the exact curve (:func:`simcam.colour.display.srgb_oetf`).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..parallel import run_bands, threads  # noqa: F401  (threads: re-exported for the benchmark)

#: rows per band (a band of a 4000-wide image is 0.8 MB of float32 input)
BAND_ROWS = 16

_SRGB_T = 0.0031308


def srgb_oetf64(x: np.ndarray) -> np.ndarray:
    """The IEC 61966-2-1 OETF in float64 (the tables' source)."""
    x = np.asarray(x, dtype=np.float64)
    return np.where(x <= _SRGB_T, 12.92 * x, 1.055 * np.power(np.maximum(x, _SRGB_T), 1.0 / 2.4) - 0.055)


def table_steps(depth: str) -> int:
    """Linear-value steps on [0, 1] of the code table for ``depth`` (2^16 for uint8, 2^20 for uint16)."""
    return 1 << 16 if depth == "uint8" else 1 << 20


def srgb_eotf64(y: np.ndarray) -> np.ndarray:
    """The inverse of :func:`srgb_oetf64` (IEC 61966-2-1), float64."""
    y = np.asarray(y, dtype=np.float64)
    return np.where(y <= 12.92 * _SRGB_T, y / 12.92, np.power((np.maximum(y, 0.04045) + 0.055) / 1.055, 2.4))


@lru_cache(maxsize=4)
def code_table(depth: str) -> np.ndarray:
    """sRGB codes of the linear values ``i / table_steps(depth)``, ``i = 0 .. steps`` (of type ``depth``).

    ``table[i] = round(clip(oetf(i / steps), 0, 1) top)``. The codes are non-decreasing in ``i``,
    so the table is built from where each code begins: the linear value where the curve crosses
    ``(k - 1/2) / top`` (:func:`srgb_eotf64`), with the two grid points beside each crossing
    evaluated exactly (a crossing that falls on a grid point, or one rounded the other way). This is
    65,536 evaluations of the curve instead of 2^20 for 16-bit output (about 3 ms instead of 45 ms
    a process); ``tests/test_render_fused.py`` checks it against the direct definition.
    """
    n = table_steps(depth)
    top = 255 if depth == "uint8" else 65535
    k = np.arange(1, top + 1, dtype=np.float64)
    starts = np.clip(np.ceil(srgb_eotf64((k - 0.5) / top) * n), 0, n + 1).astype(np.int64)
    counts = np.diff(np.concatenate(([0], starts, [n + 1])))
    t = np.repeat(np.arange(top + 1, dtype=depth), counts)
    near = np.clip(np.concatenate((starts - 1, starts)), 0, n)  # repeats do no harm
    t[near] = np.round(np.clip(srgb_oetf64(near / n), 0.0, 1.0) * top).astype(depth)
    t.flags.writeable = False
    return t


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
    encode = display_encoder(matrix, lo=lo, hi=hi, curve=curve, depth=depth)  # checks curve and depth first
    rgb = np.asarray(rgb, dtype=np.float32)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"encode_display: expected an H x W x 3 image, got shape {rgb.shape}")
    h, w = rgb.shape[:2]
    out = np.empty((h, w, 3), sample_dtype(depth))
    if run_bands(h, lambda r0, r1: encode(rgb[r0:r1], out[r0:r1]), rows=BAND_ROWS):
        raise ValueError("image data contains NaN or infinite values")
    return out


def sample_dtype(depth: str) -> np.dtype:
    """The numpy type of ``depth`` samples (``half`` is float16)."""
    return np.dtype(np.float16 if depth == "half" else depth)


def display_encoder(matrix: np.ndarray, *, lo: float | None = None, hi: float | None = None, curve: str = "srgb",
                    depth: str = "uint8"):
    """The per-band work of :func:`encode_display` as a function ``encode(x, out) -> bool``.

    ``x`` is an n x w x 3 float32 block of rows (any strides), ``out`` the n x w x 3 ``depth`` block it
    is written to; the return value is True when a product is NaN or infinite (``out`` is then not
    complete). Blocks are independent, so callers run them on threads in any order (the demosaic
    kernels call it on each strip they finish: :func:`simcam.render_samples.render_demosaic_tail`).
    """
    from .display import srgb_oetf

    if curve not in ("srgb", "linear"):
        raise ValueError(f"encode_display: curve: expected 'srgb' or 'linear', got {curve!r}")
    if depth not in ("uint8", "uint16", "float32", "half"):
        raise ValueError(f"encode_display: depth: expected uint8, uint16, float32 or half, got {depth!r}")
    m = np.asarray(matrix, dtype=np.float64).astype(np.float32)
    lo = -np.inf if lo is None else float(lo)
    hi = np.inf if hi is None else float(hi)
    integer = depth in ("uint8", "uint16")
    if integer:  # clip(clip(v, lo, hi), 0, 1) == clip(v, clip(lo, 0, 1), clip(hi, 0, 1))
        lo, hi = float(np.clip(lo, 0.0, 1.0)), float(np.clip(hi, 0.0, 1.0))
    flo, fhi = np.float32(lo), np.float32(hi)
    code_type = sample_dtype(depth)
    if integer and curve == "srgb":
        table, scale = code_table(depth), np.float32(table_steps(depth))
    else:
        table, scale = None, np.float32(255 if depth == "uint8" else 65535)
    # a block's values bound every product: |v| <= max|x| * max_c sum_j |M[c, j]|
    gain = float(np.abs(m.astype(np.float64)).sum(axis=1).max())

    def encode(x: np.ndarray, out: np.ndarray) -> bool:
        # the three channels as contiguous planes: numpy's contiguous loops are SIMD, its strided ones
        # are not (a multiply reading every third float32 takes ~10x as long as one reading them all)
        planes = [np.ascontiguousarray(x[..., j], dtype=np.float32) for j in range(3)]
        if not _finite_products(planes, m, gain):
            return True
        acc = np.empty(planes[0].shape, np.float32)
        tmp = np.empty_like(acc)
        idx = np.empty(acc.shape, np.int32) if integer else None
        codes = np.empty(acc.shape, code_type) if table is not None else None
        r, g, b = planes
        for c in range(3):
            np.multiply(r, m[c, 0], out=acc)
            np.multiply(g, m[c, 1], out=tmp)
            acc += tmp
            np.multiply(b, m[c, 2], out=tmp)
            acc += tmp
            if flo > -np.inf or fhi < np.inf:
                np.clip(acc, flo, fhi, out=acc)
            if integer:
                acc *= scale
                np.rint(acc, out=acc)
                idx[...] = acc
                if table is not None:  # idx is in [0, steps] (clipped above): mode="clip" skips the bounds check
                    np.take(table, idx, out=codes, mode="clip")
                    out[..., c] = codes
                else:
                    out[..., c] = idx
            else:
                out[..., c] = srgb_oetf(acc) if curve == "srgb" else acc
        return False

    return encode


def _finite_products(planes: list[np.ndarray], m: np.ndarray, gain: float) -> bool:
    """True when every product ``(M[c, 0] r + M[c, 1] g) + M[c, 2] b`` of the band is finite (float32).

    The planes hold no NaN or infinity (``min`` and ``max`` propagate them), and where
    ``max|x| * gain`` stays far inside float32's range no product can overflow; only otherwise are the
    products computed and checked one by one (a band of huge values).
    """
    bound = 0.0
    for p in planes:
        lo, hi = float(p.min()), float(p.max())
        if not (np.isfinite(lo) and np.isfinite(hi)):
            return False
        bound = max(bound, -lo, hi)
    if bound * gain < 1e37:
        return True
    r, g, b = planes
    with np.errstate(over="ignore", invalid="ignore"):
        return all(bool(np.isfinite((r * m[c, 0] + g * m[c, 1]) + b * m[c, 2]).all()) for c in range(3))


def quantise(data: np.ndarray, depth: str) -> np.ndarray:
    """``round(clip(x, 0, 1) * (2^b - 1))`` as ``uint8``/``uint16`` (round half to even), on bands in threads.

    Same values as ``np.round(np.clip(x, 0, 1) * top).astype(depth)`` on float32 data.

    Raises
    ------
    ValueError
        If ``data`` has a NaN or infinite value.
    """
    x = np.asarray(data, dtype=np.float32)
    out = np.empty(x.shape, dtype=depth)
    top = np.float32(255 if depth == "uint8" else 65535)
    if x.ndim == 0 or x.shape[0] == 0:
        if not np.all(np.isfinite(x)):
            raise ValueError("image data contains NaN or infinite values")
        out[...] = np.round(np.clip(x, 0, 1) * top)
        return out

    def band(r0: int, r1: int) -> bool:
        v = x[r0:r1]
        if not np.isfinite(v).all():
            return True
        t = np.clip(v, np.float32(0), np.float32(1))
        t *= top
        np.rint(t, out=t)
        out[r0:r1] = t
        return False

    if run_bands(x.shape[0], band, rows=BAND_ROWS):
        raise ValueError("image data contains NaN or infinite values")
    return out
