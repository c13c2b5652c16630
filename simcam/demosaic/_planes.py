"""Shared machinery of the hand-written Bayer kernels: input checks, CFA-phase
planes with mirror padding, and row strips.

Border convention
-----------------
The mosaic is extended by *whole-sample mirroring* about the first and last
row/column (numpy ``np.pad(mode="reflect")``, scipy ``mode="mirror"``):
``x[-1] = x[1]``, ``x[-2] = x[2]``. This mirror keeps the Bayer phase (a pixel
and its mirror image have the same colour filter), so border pixels are
interpolated from samples of the right colour for every pattern. It differs from
colour-demosaicing, whose ``scipy.ndimage.convolve`` default (``mode="reflect"``,
``x[-1] = x[0]``) swaps the colours in the padding; the two agree everywhere
except the outer 2 pixels (1 for bilinear). The result equals colour-demosaicing
run on ``np.pad(mosaic, 2, mode="reflect")`` and cropped back.

Odd heights/widths are handled: the kernels work on an even-sized grid whose
extra row/column is mirror-padded too, and the output is cropped to H x W.
"""

from __future__ import annotations

import numpy as np

from ..cfa import check_pattern
from ..errors import CfaError, StageError

#: Rows of a phase plane processed at once: small enough that the temporaries
#: of one strip stay in a core's L2 cache at 12 MP widths.
STRIP_ROWS = 16


def check_mosaic(mosaic, cfa: str, method: str) -> tuple[np.ndarray, str]:
    """Validate a mosaic and pattern; return (float32 C-contiguous mosaic, pattern)."""
    arr = np.asarray(mosaic)
    if arr.ndim != 2:
        raise StageError(f"demosaic ({method}): mosaic: expected a 2-D H x W array, got shape {arr.shape}")
    if arr.shape[0] < 2 or arr.shape[1] < 2:
        raise StageError(f"demosaic ({method}): mosaic: expected at least 2 x 2 pixels, got shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise StageError(f"demosaic ({method}): mosaic: expected real numbers, got dtype {arr.dtype}")
    try:
        pattern = check_pattern(cfa, where=f"demosaic ({method}): cfa")
    except CfaError as exc:  # a demosaic kernel's input error is a stage error
        raise StageError(str(exc)) from None
    return np.ascontiguousarray(arr, dtype=np.float32), pattern


def mirror_index(idx: np.ndarray, n: int) -> np.ndarray:
    """Whole-sample mirror of integer positions into ``[0, n)`` (period ``2 (n - 1)``)."""
    period = 2 * (n - 1)
    idx = np.mod(idx, period)
    return np.where(idx > n - 1, period - idx, idx)


def _gather(m: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """``m[np.ix_(rows, cols)]`` where ``rows``/``cols`` are stride-2 runs with a few
    mirrored entries at each end: the bulk is one strided copy."""
    out = np.empty((rows.size, cols.size), dtype=np.float32)
    r_in = np.flatnonzero(np.diff(rows) == 2)  # interior run: consecutive steps of +2
    c_in = np.flatnonzero(np.diff(cols) == 2)
    ra, rb = (r_in[0], r_in[-1] + 2) if r_in.size else (0, 0)
    ca, cb = (c_in[0], c_in[-1] + 2) if c_in.size else (0, 0)
    if rb > ra and cb > ca:
        out[ra:rb, ca:cb] = m[rows[ra]:rows[rb - 1] + 1:2, cols[ca]:cols[cb - 1] + 1:2]
    else:
        ra = rb = ca = cb = 0
    for rsel in (slice(0, ra), slice(rb, None)):
        if rows[rsel].size:
            out[rsel, :] = m[np.ix_(rows[rsel], cols)]
    for csel in (slice(0, ca), slice(cb, None)):
        if cols[csel].size:
            out[ra:rb, csel] = m[np.ix_(rows[ra:rb], cols[csel])]
    return out


def phase_planes(m: np.ndarray) -> tuple[list[list[np.ndarray]], int, int]:
    """The four CFA-phase planes of the mosaic mirror-padded by 2 pixels.

    Returns ``(planes, He, We)``: ``planes[p][q][i, j]`` is the padded mosaic at
    ``(2 i + p - 2, 2 j + q - 2)`` of the image, so output pixel
    ``(2 i + p, 2 j + q)`` sits at ``planes[p][q][i + 1, j + 1]``. ``He``/``We``
    are H and W rounded up to even (the computed grid; crop to H x W after).
    """
    h, w = m.shape
    he, we = h + h % 2, w + w % 2
    rows = [mirror_index(np.arange(p - 2, he + 2, 2), h) for p in (0, 1)]
    cols = [mirror_index(np.arange(q - 2, we + 2, 2), w) for q in (0, 1)]
    planes = [[_gather(m, rows[p], cols[q]) for q in (0, 1)] for p in (0, 1)]
    return planes, he, we


class PhaseView:
    """Neighbour access on phase planes for one strip of one output phase.

    ``self(a, b)`` is the strip-shaped array of mosaic values at offset
    ``(a, b)`` (|a|, |b| <= 2) from every output pixel of phase ``(p, q)`` in
    phase-plane rows ``[s0, s1)``.
    """

    __slots__ = ("planes", "p", "q", "s0", "s1", "w2")

    def __init__(self, planes, p: int, q: int, s0: int, s1: int, w2: int):
        self.planes, self.p, self.q, self.s0, self.s1, self.w2 = planes, p, q, s0, s1, w2

    def __call__(self, a: int, b: int) -> np.ndarray:
        pa, qb = self.p + a, self.q + b
        di, dj = pa // 2 + 1, qb // 2 + 1
        return self.planes[pa & 1][qb & 1][self.s0 + di:self.s1 + di, dj:dj + self.w2]


def strip_setup(mosaic, cfa: str, method: str, *, full: bool = True):
    """What the strip kernels start from: the checked mosaic and pattern, its phase planes, the
    half-size grid ``(h2, w2)``, the even-size float32 output (None when ``full`` is False: the strips
    then go to a sink, :class:`StripTarget`) and the strip height.

    Returns ``(m, cfa, planes, h2, w2, rgb, rows)``; crop ``rgb`` to ``m.shape`` with :func:`crop_output`.
    """
    m, cfa = check_mosaic(mosaic, cfa, method)
    planes, he, we = phase_planes(m)
    h2, w2 = he // 2, we // 2
    rgb = np.empty((he, we, 3), dtype=np.float32) if full else None
    return m, cfa, planes, h2, w2, rgb, min(STRIP_ROWS, h2)


class StripTarget:
    """Where a strip kernel writes the RGB rows of phase-plane rows ``[s0, s1)``.

    Without a sink, into the whole even-sized output ``rgb``. With a sink, into a buffer of one strip
    per thread, handed to ``sink(y0, y1, block)`` once the strip is complete: ``block`` holds output
    rows ``[y0, y1)`` cropped to the mosaic's H x W (a view of the buffer, valid during the call).
    The sink's return value (True: stop, e.g. a non-finite value) is the strip's.
    """

    def __init__(self, rgb: np.ndarray | None, sink, rows: int, h: int, w: int, w2: int):
        import threading

        self.rgb, self.sink, self.rows, self.h, self.w, self.w2 = rgb, sink, rows, h, w, w2
        self.local = threading.local()

    def block(self, s0: int) -> tuple[np.ndarray, int]:
        """The array the strip starting at plane row ``s0`` writes to, and the output row it starts at."""
        if self.sink is None:
            return self.rgb, 0
        buf = getattr(self.local, "rgb", None)
        if buf is None:
            buf = self.local.rgb = np.empty((2 * self.rows, 2 * self.w2, 3), dtype=np.float32)
        return buf, 2 * s0

    def done(self, s0: int, s1: int, buf: np.ndarray) -> bool:
        if self.sink is None:
            return False
        y0, y1 = 2 * s0, min(2 * s1, self.h)
        return bool(self.sink(y0, y1, buf[: y1 - y0, : self.w]))


def site_layout(cfa: str) -> dict[tuple[int, int], tuple[int, int]]:
    """Per phase ``(p, q)``: (colour index at the site, colour index of the
    horizontal neighbours). 0 = R, 1 = G, 2 = B."""
    cell = [["RGB".index(c) for c in cfa[0:2]], ["RGB".index(c) for c in cfa[2:4]]]
    return {(p, q): (cell[p][q], cell[p][1 - q]) for p in (0, 1) for q in (0, 1)}


def crop_output(rgb: np.ndarray, h: int, w: int) -> np.ndarray:
    """Crop the even-sized working grid back to H x W x 3 (contiguous)."""
    if rgb.shape[0] == h and rgb.shape[1] == w:
        return rgb
    return np.ascontiguousarray(rgb[:h, :w])
