"""Render a frame through a pipeline straight to output samples, fusing the display tail.

:func:`render_samples` runs the pipeline's stages one by one, except its tail
when that tail is made only of

* linear maps: ``camera_to_xyz``, ``xyz_to_srgb``, ``tone`` with ``curve: none``
  (a gain ``2^exposure``), which compose into one 3 x 3 matrix;
* then ``clip`` stages (their bounds intersect);
* then at most one ``gamma`` with ``curve: srgb``;
* then at most one ``orientation``.

That tail runs as one parallel pass (:func:`simcam.colour.display_kernel.encode_display`)
writing the output samples directly; orientation is then a view of them. Where a
``demosaic`` (bilinear or malvar2004) comes before the tail with only ``crop`` and
``opcodes`` (list 3) stages between, the demosaic's strips are encoded as they are
computed (:func:`render_demosaic_tail`): the H x W x 3 float32 image is never
written and read back (at 12 MP 144 MB of fresh memory, which a new process pays
for page by page).
The samples equal the stage-by-stage render's quantised output within one
code (the transfer curve is read from a table; the matrices are multiplied
together first).

Otherwise, a tail of per-pixel stages (:data:`PER_PIXEL`, in any order and with
any parameters, e.g. a filmic tone curve or simple-camera-pipeline's power
gamma and smoothstep) with at most one ``orientation`` among them runs band by
band (:func:`render_banded`): each band of rows goes through the stages' own
code and is quantised while it is in cache, bands on threads, and orientation
(which commutes with per-pixel stages) is applied to the samples at the end.
The samples are those of the stage-by-stage render (the same functions on the
same pixels). Any other pipeline runs stage by stage, and the samples come
from :func:`simcam.io.images.to_samples`.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from .frame import RawFrame
from .row_fusion import row_source, stand_in

_LINEAR = ("camera_to_xyz", "xyz_to_srgb", "tone")
#: stages that act on each pixel alone (no neighbours, no randomness), so they can run on row bands
PER_PIXEL = frozenset({"camera_to_xyz", "xyz_to_srgb", "tone", "clip", "gamma", "quantize"})
#: rows per band of :func:`render_banded`
BANDED_ROWS = 32


@dataclass
class Rendered:
    """Output samples and the frame they came from (``frame.data`` is not filled for a fused tail).

    ``kind`` is the signal kind of the samples, ``meta`` the metadata after the last stage. ``samples``
    is None when they went to a ``target`` instead (:func:`render_samples`); ``shape`` is theirs.
    """

    samples: np.ndarray | None
    kind: str
    meta: object
    depth: str
    shape: tuple = ()

    def __post_init__(self):
        if self.samples is not None:
            self.shape = tuple(self.samples.shape)


def fusable_tail(stages) -> int:
    """Index of the first stage of the fusable display tail of ``stages`` (``len(stages)`` if none)."""
    n = len(stages)
    i = n
    if i and stages[i - 1].type == "orientation":
        i -= 1
    if i and stages[i - 1].type == "gamma" and stages[i - 1].params.curve == "srgb":
        i -= 1
    while i and stages[i - 1].type == "clip":
        i -= 1
    k = i
    while k and _is_linear(stages[k - 1]):
        k -= 1
    if k == i:  # no matrix: nothing worth fusing
        return n
    return k


def _is_linear(stage) -> bool:
    if stage.type not in _LINEAR:
        return False
    return stage.type != "tone" or stage.params.curve == "none"


def render_samples(pipe, frame: RawFrame, depth: str, *, seed: int | None = None, index: int = 0,
                   progress=None, fuse: bool = True, target=None) -> Rendered:
    """Run ``pipe`` on ``frame`` and return ``depth`` samples (``uint8``, ``uint16``, ``float32``, ``half``).

    Parameters
    ----------
    pipe : simcam.pipeline.Pipeline
        The pipeline; its random stages draw as in ``pipe(frame, seed=seed)``.
    frame : RawFrame
        Input frame of the pipeline's input kind.
    depth : str
        Output sample type.
    seed : int, optional
        Seed for random stages.
    index : int
        Item index of the random streams (``SeedSequence([seed, 0, index])``, as the pipeline's).
    progress : callable, optional
        Called with each stage's type after it ran (the fused or banded tail's stages together, at its end).
    fuse : bool
        Fuse the display tail (see the module docstring); False runs every stage.
    target : simcam.io.tiff_stream.TiffStream, optional
        Where a streamed demosaic tail (:func:`render_demosaic_tail`) writes its output rows as they
        are encoded, when the output needs no turning (orientation 1): the samples are then not kept
        (``Rendered.samples`` is None). Other pipelines ignore it.

    Returns
    -------
    Rendered
    """
    from .io.images import to_samples

    stages = pipe.stages
    usable = fuse and frame.kind == pipe.input_kind
    start = fusable_tail(stages) if usable else len(stages)
    if start < len(stages):
        k = streamed_demosaic(stages, start)
        if k < start:
            planned = row_source(stages[:k], frame, progress) if k else None
            if planned is not None:  # the head's rows made strip by strip inside the demosaic
                rows, frame = planned
                return _done(render_demosaic_tail(stages[k:start], stages[start:], frame, depth, target=target,
                                                  rows=rows), stages[k:], progress)
            head = _head(pipe, k)
            frame = head(frame, seed=seed, index=index, progress=progress) if head is not None else frame
            return _done(render_demosaic_tail(stages[k:start], stages[start:], frame, depth, target=target),
                         stages[k:], progress)
        head = _head(pipe, start)
        frame = head(frame, seed=seed, index=index, progress=progress) if head is not None else frame
        return _done(render_tail(stages[start:], frame, depth), stages[start:], progress)
    start = banded_tail(stages) if usable else len(stages)
    if start < len(stages) and streamed_demosaic(stages, start) == start - 1:  # the demosaic right before it
        head = _head(pipe, start - 1)
        frame = head(frame, seed=seed, index=index, progress=progress) if head is not None else frame
        return _done(render_demosaic_banded(stages[start - 1], stages[start:], frame, depth), stages[start - 1:],
                     progress)
    if start < len(stages):
        head = _head(pipe, start)
        frame = head(frame, seed=seed, index=index, progress=progress) if head is not None else frame
        if frame.data.ndim == 3:
            return _done(render_banded(stages[start:], frame, depth), stages[start:], progress)
        for st in stages[start:]:  # a mosaic (e.g. a clip after normalize): per-pixel, but not RGB bands
            frame = st(frame)
        return _done(Rendered(to_samples(frame.data, depth), frame.kind, frame.meta, depth), stages[start:], progress)
    out = pipe(frame, seed=seed, index=index, progress=progress)
    return Rendered(to_samples(out.data, depth), out.kind, out.meta, depth)


def _done(rendered: Rendered, tail, progress) -> Rendered:
    if progress is not None:
        for st in tail:
            progress(st.type)
    return rendered


def banded_tail(stages) -> int:
    """Index of the first stage of the longest tail of per-pixel stages (with at most one
    ``orientation``) that follows an RGB stage; ``len(stages)`` if there is none."""
    i, n_orient = len(stages), 0
    while i and (stages[i - 1].type in PER_PIXEL or (stages[i - 1].type == "orientation" and n_orient == 0)):
        n_orient += stages[i - 1].type == "orientation"
        i -= 1
    if i == 0 or all(s.type == "orientation" for s in stages[i:]):
        return len(stages)
    return i


def render_banded(tail, frame: RawFrame, depth: str) -> Rendered:
    """Run per-pixel stages (and one orientation, moved to the end) on bands of rows, quantising each band."""
    from .errors import ImageIOError
    from .parallel import run_bands

    if frame.data.ndim != 3:
        raise ValueError("render_banded: expected an H x W x 3 frame")
    h, w = frame.data.shape[:2]
    bands = _BandedTail(tail, h, w, depth)
    if run_bands(h, lambda r0, r1: bands.encode(frame.data[r0:r1], frame.meta, frame.kind, r0), rows=BANDED_ROWS):
        raise ImageIOError(f"{frame.meta.source or 'frame'}: image data contains NaN or infinite values")
    return bands.rendered()


def render_demosaic_banded(demosaic, tail, frame: RawFrame, depth: str) -> Rendered:
    """A streaming demosaic (:attr:`simcam.stages.demosaic.Demosaic.STREAMING`) straight into a banded
    tail: each block of rows the kernel finishes runs through the per-pixel stages while it is in
    memory, so the H x W x 3 float32 image is never made. The samples are :func:`render_banded`'s on
    the demosaicked frame, byte for byte (the same stages on the same rows)."""
    from .errors import ImageIOError

    demosaic.check_input(frame)
    kind = demosaic.output_kind(frame.kind)
    h, w = frame.data.shape
    bands = _BandedTail(tail, h, w, depth)
    if demosaic.stream(frame, sink=lambda y0, y1, block: bands.encode(block, frame.meta, kind, y0)):
        raise ImageIOError(f"{frame.meta.source or 'frame'}: image data contains NaN or infinite values")
    return bands.rendered()


class _BandedTail:
    """The per-pixel stages of a banded tail on blocks of rows of an H x W x 3 frame, quantised into one
    output; the orientation (at most one) turns the whole output at the end."""

    def __init__(self, tail, h: int, w: int, depth: str):
        from .colour.display_kernel import sample_dtype

        self.pixel = [s for s in tail if s.type != "orientation"]
        self.orientation = next((s for s in tail if s.type == "orientation"), None)
        self.depth = depth
        self.out = np.empty((h, w, 3), sample_dtype(depth))
        self.first: list = []

    def encode(self, block: np.ndarray, meta, kind: str, r0: int) -> bool:
        """Rows ``r0 : r0 + len(block)``, in pieces of :data:`BANDED_ROWS`; True on a non-finite value."""
        depth = self.depth
        for q in range(0, block.shape[0], BANDED_ROWS):
            f = RawFrame(block[q:q + BANDED_ROWS], meta, kind=kind)
            for st in self.pixel:
                f = st(f)
            x = f.data
            if not np.isfinite(x).all():
                return True
            if depth in ("uint8", "uint16"):  # as to_samples: round(clip(x, 0, 1) * top), half to even
                x = np.clip(x, np.float32(0), np.float32(1)) * np.float32(255 if depth == "uint8" else 65535)
                np.rint(x, out=x)
            self.out[r0 + q:r0 + q + x.shape[0]] = x
            if r0 + q == 0:
                self.first.append(f)
        return False

    def rendered(self) -> Rendered:
        from .stages.orientation import orient

        out, kind, meta = self.out, self.first[0].kind, self.first[0].meta
        if self.orientation is not None:
            self.orientation.check_input(RawFrame(np.zeros((1, 1, 3), np.float32), meta, kind=kind))
            value = self.orientation.transform_value(meta)
            out = np.ascontiguousarray(orient(out, value))
            meta = meta.copy()
            meta.orientation = 1
        return Rendered(out, kind, meta, self.depth)


def _head(pipe, start: int):
    """The pipeline of ``stages[:start]``; it draws the same random numbers as the whole pipeline
    (``SeedSequence.spawn`` gives child k the same state whatever the number of children)."""
    if start == 0:
        return None
    from .pipeline import Pipeline

    return Pipeline(pipe.stages[:start], input_kind=pipe.input_kind, name=pipe.name, source=pipe.source)


def streamed_demosaic(stages, start: int) -> int:
    """Index of a ``demosaic`` stage whose strips can stream into the fused tail at ``start``: a
    method with a strip sink (:attr:`simcam.stages.demosaic.Demosaic.STREAMING`) followed only by
    ``crop`` and ``opcodes`` (list 3) stages; ``start`` if there is none."""
    k = start
    while k and (stages[k - 1].type == "crop" or (stages[k - 1].type == "opcodes" and stages[k - 1].params.list == 3)):
        k -= 1
    if k and stages[k - 1].type == "demosaic" and stages[k - 1].params.method in stages[k - 1].STREAMING:
        return k - 1
    return start


def render_demosaic_tail(middle, tail, frame: RawFrame, depth: str, *, target=None, rows=None) -> Rendered:
    """Demosaic straight into the fused display tail: each strip of the demosaic is encoded to output
    samples while it is in cache (:func:`simcam.colour.display_kernel.display_encoder`), so the
    H x W x 3 float32 image (144 MB at 12 MP) is never written and read back.

    ``middle`` is the demosaic stage and the ``crop`` / ``opcodes`` stages after it
    (:func:`streamed_demosaic`), ``tail`` the fusable tail. The crops act on the strips' rows and
    columns (their checks and metadata from :meth:`simcam.stages.raw.Crop.plan`). A list-3 opcode
    list the file holds needs the whole image: the stages then run one by one, as they do elsewhere.
    The samples are those of :func:`render_tail` on the stage-by-stage frame, byte for byte (the same
    kernels on the same pixels). With a ``target`` (a :class:`simcam.io.tiff_stream.TiffStream`) and
    an upright output, each strip's samples go to it from a small buffer per thread instead of into an
    H x W x 3 array (72 MB of fresh memory at 12 MP, 16 bits). With ``rows`` (a
    :class:`simcam.row_fusion.RowSource`: the pipeline's head, planned by :func:`simcam.row_fusion.row_source`)
    the mosaic's rows are made strip by strip from it and ``frame`` only gives the metadata and shape.
    """
    from .colour.display_kernel import display_encoder, sample_dtype
    from .errors import ImageIOError

    demosaic = middle[0]
    demosaic.check_input(frame)
    if any(st.type == "opcodes" and getattr(frame.meta, f"opcode_list{st.params.list}") for st in middle[1:]):
        if rows is not None:
            frame = frame.evolve(rows.materialize())
        for st in middle:
            frame = st(frame)
        return render_tail(tail, frame, depth)
    kind = demosaic.output_kind(frame.kind)
    h, w = frame.data.shape
    top, left, bottom, right = 0, 0, h, w
    meta = frame.meta
    for st in middle[1:]:
        if st.type == "crop":  # a stand-in frame of the current size: the crop's checks without pixels
            proxy = RawFrame(stand_in((bottom - top, right - left, 3)), meta, kind=kind)
            st.check_input(proxy)
            (t, l, b, r), meta = st.plan(proxy)
            top, left, bottom, right = top + t, left + l, top + b, left + r
    plan = _tail_plan(tail, kind, meta)
    try:
        encode = display_encoder(plan.matrix, lo=plan.lo, hi=plan.hi, curve=plan.curve, depth=depth)
    except ValueError as exc:
        raise ImageIOError(f"{meta.source or 'frame'}: {exc}") from None
    shape, dtype = (bottom - top, right - left, 3), sample_dtype(depth)
    if target is not None and (plan.orientation is None or plan.orientation.transform_value(meta) == 1):
        out_meta = _upright_meta(plan, meta)
        writer = target.open(shape, dtype, plan.kind, out_meta)
        local = threading.local()

        def sink(y0: int, y1: int, block: np.ndarray) -> bool:
            a, z = max(y0, top), min(y1, bottom)
            if a >= z:
                return False
            buf = getattr(local, "buf", None)
            if buf is None or len(buf) < z - a:
                buf = local.buf = np.empty((z - a,) + shape[1:], dtype)
            if encode(block[a - y0:z - y0, left:right], buf[:z - a]):
                return True
            writer.write(a - top, buf[:z - a])
            return False

        if demosaic.stream(frame, sink=sink, rows=rows):
            raise ImageIOError(f"{meta.source or 'frame'}: image data contains NaN or infinite values")
        return Rendered(None, plan.kind, out_meta, depth, shape)
    out = np.empty(shape, dtype)

    def sink(y0: int, y1: int, block: np.ndarray) -> bool:
        a, z = max(y0, top), min(y1, bottom)
        return a < z and encode(block[a - y0:z - y0, left:right], out[a - top:z - top])

    if demosaic.stream(frame, sink=sink, rows=rows):
        raise ImageIOError(f"{meta.source or 'frame'}: image data contains NaN or infinite values")
    return _oriented(out, plan, meta, depth)


@dataclass
class _TailPlan:
    """What a fusable tail does: one matrix, the clip bounds, the transfer curve, an orientation."""

    matrix: np.ndarray
    lo: float | None
    hi: float | None
    curve: str
    kind: str
    orientation: object


def render_tail(tail, frame: RawFrame, depth: str) -> Rendered:
    """Run a fusable tail (``stages[fusable_tail(stages):]``) on ``frame`` in one pass; ``depth`` samples."""
    from .colour.display_kernel import encode_display
    from .errors import ImageIOError

    plan = _tail_plan(tail, frame.kind, frame.meta)
    try:
        samples = encode_display(frame.data, plan.matrix, lo=plan.lo, hi=plan.hi, curve=plan.curve, depth=depth)
    except ValueError as exc:
        raise ImageIOError(f"{frame.meta.source or 'frame'}: {exc}") from None
    return _oriented(samples, plan, frame.meta, depth)


def _oriented(samples: np.ndarray, plan: _TailPlan, meta, depth: str) -> Rendered:
    """The samples turned upright by the tail's orientation stage, if it has one."""
    from .stages.orientation import orient

    if plan.orientation is not None:
        samples = np.ascontiguousarray(orient(samples, plan.orientation.transform_value(meta)))
    return Rendered(samples, plan.kind, _upright_meta(plan, meta), depth)


def _upright_meta(plan: _TailPlan, meta):
    """The metadata after the tail's orientation stage (orientation 1), if it has one."""
    if plan.orientation is None:
        return meta
    meta = meta.copy()
    meta.orientation = 1
    return meta


def _tail_plan(tail, kind: str, meta) -> _TailPlan:
    """Compose a fusable tail's stages (for frames of ``kind`` with metadata ``meta``)."""
    from .colour.display import sidd_xyz_to_srgb_matrix, xyz_d50_to_linear_srgb_matrix

    m = np.eye(3)
    lo, hi = -np.inf, np.inf
    curve, orientation = "linear", None
    for st in tail:
        t = st.type
        if t == "camera_to_xyz":
            m = st.matrix(meta) @ m
            kind = "xyz"
        elif t == "xyz_to_srgb":
            s = sidd_xyz_to_srgb_matrix() if st.params.mode == "sidd" else xyz_d50_to_linear_srgb_matrix()
            m = s @ m
            kind = "linear_srgb"
        elif t == "tone":
            m = (2.0 ** st.params.exposure) * m
        elif t == "clip":  # clip[l2, h2] after clip[lo, hi] is clip[clip(lo, l2, h2), clip(hi, l2, h2)]
            l2 = -np.inf if st.params.low is None else st.params.low
            h2 = np.inf if st.params.high is None else st.params.high
            lo, hi = float(np.clip(lo, l2, h2)), float(np.clip(hi, l2, h2))
        elif t == "gamma":
            curve, kind = "srgb", "display"
        elif t == "orientation":
            orientation = st
    return _TailPlan(m, None if np.isinf(lo) else lo, None if np.isinf(hi) else hi, curve, kind, orientation)
