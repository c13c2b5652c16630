"""Consecutive row-wise stages run together, band by band, in one buffer.

A pipeline's raw stages are mostly maps of rows: ``normalize`` (black per CFA site, over the white
minus black), ``white_balance`` with known gains (one gain per CFA site), ``clip``. Run one after the
other, each reads and writes the whole frame and makes a new one: at 12 MP three passes over 48 MB
arrays, each fresh memory that a new process pays for page by page. Here a run of such stages
(:meth:`simcam.stages.base.Stage.row_op`) is done on bands of :data:`BAND_ROWS` rows, every stage on
a band while it is in cache, into one float32 buffer: a
new one for the first run, the same one (in place) for a later run whose input is that buffer (or a
view of it, as ``crop`` leaves it). The pixels are those of the stages run one by one, byte for byte
(each stage's own row function on the same rows).

The bands run on the calling thread: memory-bound, a second thread did not shorten them (12 MP
``normalize``, ``white_balance`` and ``clip`` in a fresh process, AMD EPYC: 0.021-0.028 s on two
threads, 0.022-0.029 s on one, against 0.034-0.17 s for the three stages one after the other).
"""

from __future__ import annotations

import numpy as np

from .frame import RawFrame

#: rows per band (32 rows of a 4000-pixel float32 mosaic: 512 KB, within a core's L2 cache)
BAND_ROWS = 32


def run_stages(stages, frame: RawFrame, rngs, progress=None) -> RawFrame:
    """Run ``stages`` on ``frame`` in order, as ``stage(frame, rng)`` does, the runs of row-wise stages
    fused (see the module docstring); ``rngs`` holds each stage's generator (or is empty), ``progress``
    is called with each stage's type after it ran."""
    owned: list[np.ndarray] = []  # the buffers made here: no one else holds them
    k, n = 0, len(stages)
    while k < n:
        ops, out, result, j = [], None, frame, k
        while j < n and not stages[j].random:  # the run of row-wise stages from k: planned, not computed
            stages[j].check_input(result)
            op = stages[j].row_op(result)
            if op is None:
                break
            if out is None:
                out = _buffer(result.data, owned)
            ops.append(op)
            result = op.result(result, out)
            j += 1
        if ops:
            _run_rows(ops, np.asarray(frame.data), out)
            if not any(out is b for b in owned):
                owned.append(out)
        if j < n:  # the stage that ended the run (random, or not a map of rows) on its own
            result = stages[j](result, rngs[j] if rngs else None)
            j += 1
        if progress is not None:
            for st in stages[k:j]:
                progress(st.type)
        frame, k = result, j
    return frame


def _buffer(data, owned: list[np.ndarray]) -> np.ndarray:
    """Where a run of row-wise stages writes: ``data`` itself when it is (a view of) a buffer made here
    and float32, else a new float32 array of its shape."""
    if (isinstance(data, np.ndarray) and data.dtype == np.float32 and data.flags.writeable
            and any(np.may_share_memory(data, b) for b in owned)):
        return data
    return np.empty(np.shape(data), dtype=np.float32)


def _run_rows(ops, src: np.ndarray, out: np.ndarray) -> None:
    """``ops`` one after the other on each band of rows: the first from ``src``, the others in place."""
    for r0 in range(0, src.shape[0], BAND_ROWS):
        r1 = r0 + BAND_ROWS
        dst = out[r0:r1]
        ops[0].fn(src[r0:r1], dst, r0)
        for op in ops[1:]:
            op.fn(dst, dst, r0)


def stand_in(shape) -> np.ndarray:
    """A read-only float32 stand-in of ``shape`` (no memory): what a planned stage sees as its pixels."""
    return np.broadcast_to(np.zeros((1,) * len(shape), np.float32), tuple(shape))


class RowSource:
    """The output of a run of stages, computed for any band of rows on demand.

    Made by :func:`row_source` from stages that are row maps (:meth:`simcam.stages.base.Stage.row_op`),
    crops, or pass the frame through (:meth:`~simcam.stages.base.Stage.passes_through`). :meth:`rows`
    runs the row maps on the source rows under the asked ones, as :func:`run_stages` runs them on
    every band (the same functions on the same rows: the same values), so a consumer that works in
    strips (the Bayer demosaic kernels, :mod:`simcam.demosaic._planes`) never needs the whole output:
    at 12 MP a 48 MB float32 mosaic, which a new process pays for page by page, made in one serial pass.

    ``segments`` is ``[(row ops, crop), ...]``: each segment's row maps, then its crop ``(top, left,
    width)`` of the rows they made (None for the last); ``shape`` is the output's H x W.
    """

    def __init__(self, data: np.ndarray, segments: list, shape: tuple[int, int]):
        import threading

        self.data, self.segments, self.shape = data, segments, tuple(shape)
        self.top = sum(crop[0] for _, crop in segments if crop is not None)  # output row 0 is source row `top`
        self.local = threading.local()

    def rows(self, a: int, b: int) -> np.ndarray:
        """Output rows ``[a, b)``, (b - a) x W float32 (this thread's buffer, valid until its next call)."""
        n, r0 = b - a, a + self.top
        cur, made = self.data[r0:r0 + n], False  # made: cur is this thread's buffer, not the source
        for ops, crop in self.segments:
            for op in ops:
                if not made:
                    buf = getattr(self.local, "buf", None)
                    if buf is None or buf.shape[0] < n:  # its width is the source's, the widest
                        buf = self.local.buf = np.empty((max(n, BAND_ROWS), self.data.shape[1]), np.float32)
                    op.fn(cur, buf[:n, :cur.shape[1]], r0)
                    cur, made = buf[:n, :cur.shape[1]], True
                else:
                    op.fn(cur, cur, r0)
            if crop is not None:
                top, left, width = crop
                cur, r0 = cur[:, left:left + width], r0 - top
        return cur

    def materialize(self) -> np.ndarray:
        """The whole output (H x W float32)."""
        out = np.empty(self.shape, np.float32)
        for r in range(0, self.shape[0], BAND_ROWS):
            rows = self.rows(r, min(r + BAND_ROWS, self.shape[0]))
            out[r:r + len(rows)] = rows
        return out


def row_source(stages, frame: RawFrame, progress=None) -> tuple[RowSource, RawFrame] | None:
    """``stages`` on ``frame`` as a :class:`RowSource` and the frame they would return (its pixels a
    stand-in: only its metadata, kind and shape are real); None unless every stage is a row map, a
    crop or passes the frame through, and none draws random numbers. The stages' checks raise here as
    when they run; ``progress`` is called with each stage's type."""
    segments, ops = [], []
    result = frame.evolve(stand_in(frame.data.shape))
    for st in stages:
        if st.random:
            return None
        st.check_input(result)
        op = st.row_op(result)
        if op is not None:
            ops.append(op)
            result = op.result(result, stand_in(result.data.shape))
        elif st.type == "crop":
            (top, left, bottom, right), meta = st.plan(result)
            segments.append((ops, (top, left, right - left)))
            ops = []
            result = result.evolve(stand_in((bottom - top, right - left)), meta=meta, step=st.type)
        elif st.passes_through(result):
            result = st(result)
        else:
            return None
    segments.append((ops, None))
    if progress is not None:
        for st in stages:
            progress(st.type)
    return RowSource(np.asarray(frame.data), segments, result.data.shape), result
