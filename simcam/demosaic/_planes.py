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
    """Validate a mosaic and pattern; return (float32 C-contiguous mosaic, pattern). A row source (an
    object with ``shape`` and ``rows(a, b)`` giving float32 mosaic rows ``[a, b)`` on demand, e.g.
    :class:`simcam.row_fusion.RowSource`) is kept as it is."""
    source = is_row_source(mosaic)
    arr = mosaic if source else np.asarray(mosaic)
    if not source and arr.ndim != 2:
        raise StageError(f"demosaic ({method}): mosaic: expected a 2-D H x W array, got shape {arr.shape}")
    if arr.shape[0] < 2 or arr.shape[1] < 2:
        raise StageError(f"demosaic ({method}): mosaic: expected at least 2 x 2 pixels, got shape {arr.shape}")
    if not source and (not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr)):
        raise StageError(f"demosaic ({method}): mosaic: expected real numbers, got dtype {arr.dtype}")
    try:
        pattern = check_pattern(cfa, where=f"demosaic ({method}): cfa")
    except CfaError as exc:  # a demosaic kernel's input error is a stage error
        raise StageError(str(exc)) from None
    return (arr if source else np.ascontiguousarray(arr, dtype=np.float32)), pattern


def is_row_source(mosaic) -> bool:
    """True for a row source (see :func:`check_mosaic`) rather than an array."""
    return not isinstance(mosaic, np.ndarray) and callable(getattr(mosaic, "rows", None)) and hasattr(mosaic, "shape")


def mirror_index(idx: np.ndarray, n: int) -> np.ndarray:
    """Whole-sample mirror of integer positions into ``[0, n)`` (period ``2 (n - 1)``)."""
    period = 2 * (n - 1)
    idx = np.mod(idx, period)
    return np.where(idx > n - 1, period - idx, idx)


def _runs(idx: np.ndarray) -> tuple[int, int]:
    """``(a, b)``: ``idx[a:b]`` is the interior stride-2 run of ``idx`` (``(0, 0)`` if none); the
    entries before ``a`` and from ``b`` on are the few mirrored ones at each end."""
    inner = np.flatnonzero(np.diff(idx) == 2)  # interior run: consecutive steps of +2
    return (int(inner[0]), int(inner[-1]) + 2) if inner.size else (0, 0)


def _gather(m: np.ndarray, rows: np.ndarray, cols: np.ndarray, out: np.ndarray, col_run: tuple[int, int]) -> np.ndarray:
    """``m[np.ix_(rows, cols)]`` into ``out`` where ``rows``/``cols`` are stride-2 runs with a few mirrored
    entries at each end (``col_run``: ``_runs(cols)``): the bulk is one strided copy."""
    ra, rb = _runs(rows)
    ca, cb = col_run
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


class PhasePlanes:
    """The four CFA-phase planes of a mosaic mirror-padded by 2 pixels, gathered strip by strip.

    ``planes[p][q][i, j]`` is the padded mosaic at ``(2 i + p - 2, 2 j + q - 2)`` of the image, so
    output pixel ``(2 i + p, 2 j + q)`` sits at ``planes[p][q][i + 1, j + 1]``. ``he``/``we`` are H
    and W rounded up to even (the computed grid; crop to H x W after).

    :meth:`strip` copies the plane rows one strip of output needs into its thread's buffers, so the
    whole planes (a second copy of the mosaic: 48 MB of fresh memory at 12 MP, which a new process
    pays for page by page, in one serial pass before the strips start) are never made.
    """

    def __init__(self, m, rows: int):
        """``m``: the H x W float32 mosaic, or a row source of it (:func:`check_mosaic`)."""
        import threading

        h, w = m.shape
        self.m, self.rows = m, rows
        self.he, self.we = h + h % 2, w + w % 2
        self.row_idx = [mirror_index(np.arange(p - 2, self.he + 2, 2), h) for p in (0, 1)]
        self.col_idx = [mirror_index(np.arange(q - 2, self.we + 2, 2), w) for q in (0, 1)]
        self.col_runs = [_runs(c) for c in self.col_idx]
        self.local = threading.local()

    def strip(self, s0: int, s1: int) -> list[list[np.ndarray]]:
        """Plane rows ``[s0, s1 + 2)`` (what output plane rows ``[s0, s1)`` read), in this thread's
        buffers: index them as :class:`PhaseView` with ``s0 = 0`` (valid until the thread's next strip)."""
        bufs = getattr(self.local, "bufs", None)
        if bufs is None:
            wp = self.we // 2 + 2
            bufs = self.local.bufs = [[np.empty((self.rows + 2, wp), np.float32) for _ in (0, 1)] for _ in (0, 1)]
        n = s1 - s0 + 2
        idx = [self.row_idx[p][s0:s0 + n] for p in (0, 1)]
        m = self.m
        if is_row_source(m):  # make the mosaic rows the strip reads (mirrored ones too)
            a = int(min(idx[0].min(), idx[1].min()))
            m = m.rows(a, int(max(idx[0].max(), idx[1].max())) + 1)
            idx = [i - a for i in idx]
        return [[_gather(m, idx[p], self.col_idx[q], out=bufs[p][q][:n], col_run=self.col_runs[q]) for q in (0, 1)]
                for p in (0, 1)]


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
    """What the strip kernels start from: the checked mosaic and pattern, its phase planes (a
    :class:`PhasePlanes`: each strip gathers its own rows), the half-size grid ``(h2, w2)``, the
    even-size float32 output (None when ``full`` is False: the strips then go to a sink,
    :class:`StripTarget`) and the strip height.

    Returns ``(m, cfa, planes, h2, w2, rgb, rows)``; crop ``rgb`` to ``m.shape`` with :func:`crop_output`.
    """
    m, cfa = check_mosaic(mosaic, cfa, method)
    h, w = m.shape
    rows = min(STRIP_ROWS, (h + h % 2) // 2)
    planes = PhasePlanes(m, rows)
    h2, w2 = planes.he // 2, planes.we // 2
    rgb = np.empty((planes.he, planes.we, 3), dtype=np.float32) if full else None
    return m, cfa, planes, h2, w2, rgb, rows


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
