"""The ``demosaic`` stage: normalised-raw Bayer mosaic -> camera RGB.

Kernels live in :mod:`simcam.demosaic`; this stage checks the frame, picks the
method and records the step. Metadata is passed on unchanged (``meta.cfa`` still
names the sensor's pattern; ``kind`` says the data is now RGB).
"""

from __future__ import annotations

from typing import Literal

from ..demosaic import DEMOSAIC_METHODS
from ..errors import StageError
from ..frame import RawFrame
from .base import Stage, StageParams, register_stage


@register_stage
class Demosaic(Stage, type="demosaic", accepts=frozenset({"raw"}), produces="camera_rgb"):
    """Bayer demosaicing: ``raw`` (H x W) -> ``camera_rgb`` (H x W x 3 float32), not clipped.

    ``method``: ``bilinear``, ``malvar2004`` (default; Malvar, He & Cutler 2004,
    doi:10.1109/ICASSP.2004.1326587) or ``menon2007`` (Menon et al. 2007,
    doi:10.1109/TIP.2006.884928, colour-demosaicing's steps compiled with numba).
    """

    class Params(StageParams):
        method: Literal["bilinear", "malvar2004", "menon2007"] = "malvar2004"

    #: methods whose kernels can hand their output to a sink strip by strip (``stream``)
    STREAMING = frozenset({"bilinear", "malvar2004", "menon2007"})

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        return frame.evolve(self.stream(frame), kind="camera_rgb", step=self.type)

    def warm_up(self):
        """What loads Menon 2007's compiled kernel ahead of use (numba sets up its compiler context on the
        first call in a process, ~0.6 s even from its on-disk cache; :meth:`Pipeline.warm_in_background`
        runs it while the input is read); None for the other methods."""
        if self.params.method != "menon2007":
            return None
        from ..demosaic._menon_kernel import warm

        return warm

    #: methods whose kernels read the mosaic strip by strip from a :class:`simcam.row_fusion.RowSource`
    ROW_SOURCE = frozenset({"bilinear", "malvar2004"})

    def stream(self, frame: RawFrame, sink=None, rows=None):
        """The kernel on ``frame``: the H x W x 3 RGB, or with ``sink`` (methods in :attr:`STREAMING`)
        each strip's rows handed to ``sink(y0, y1, block)`` and True if a call returned True.

        ``rows``, a :class:`simcam.row_fusion.RowSource`, gives the mosaic instead of ``frame.data``
        (the frame then only says its metadata and shape): methods in :attr:`ROW_SOURCE` make each
        strip's rows from it, the others the whole mosaic first."""
        src = frame.meta.source or "frame"
        if frame.meta.cfa is None:
            raise StageError(f"{src}: cfa: demosaic needs a Bayer pattern (RGGB, BGGR, GRBG, GBRG), got None")
        kernel = DEMOSAIC_METHODS[self.params.method]
        mosaic = frame.data if rows is None else rows if self.params.method in self.ROW_SOURCE else rows.materialize()
        try:
            return kernel(mosaic, frame.meta.cfa) if sink is None else kernel(mosaic, frame.meta.cfa, sink=sink)
        except StageError as exc:
            raise StageError(f"{src}: {exc}") from None
