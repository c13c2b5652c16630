"""``orientation``: turn an RGB image upright according to the EXIF/TIFF Orientation tag.

Orientation values (TIFF 6.0 tag 274): where row 0 / column 0 of the stored image
lie when displayed. The transform applied to make it upright:

=====  ==================================  ======================
value  stored image is                     applied
=====  ==================================  ======================
1      upright                             nothing
2      mirrored horizontally               flip left-right
3      rotated 180                         rotate 180
4      mirrored vertically                 flip top-bottom
5      mirrored horizontally + rot. 270 CW transpose
6      rotated 90 CCW                      rotate 90 CW
7      mirrored horizontally + rot. 90 CW  transverse (anti-transpose)
8      rotated 90 CW                       rotate 90 CCW (270 CW)
=====  ==================================  ======================

After the stage, ``meta.orientation`` is 1. The geometry tags (active area,
default crop, origin) keep referring to the stored sensor grid.
``convention: sidd`` reproduces simple-camera-pipeline's ``fix_orientation``,
which swaps 2 with 4 and 5 with 7 (compatibility only).
"""

from __future__ import annotations

from typing import Literal, Optional

import numpy as np

from ..errors import MetadataError, StageError
from ..frame import RGB_KINDS, RawFrame
from .base import Stage, StageParams, register_stage

#: simple-camera-pipeline's fix_orientation, expressed in EXIF terms: cv2.flip(img, 0)
#: (flip about the x axis, i.e. top-bottom) for 2, cv2.flip(img, 1) for 4, and for 5/7
#: a top-bottom flip followed by a 90 deg CCW / CW rotation, which is the transverse /
#: transpose (the EXIF transforms of 7 / 5).
_SIDD_SWAP = {2: 4, 4: 2, 5: 7, 7: 5}


def orient(image: np.ndarray, value: int) -> np.ndarray:
    """Apply the upright transform of EXIF orientation ``value`` (1..8) to an H x W [x C] array."""
    v = int(value)
    if v == 1:
        out = image
    elif v == 2:
        out = image[:, ::-1]
    elif v == 3:
        out = image[::-1, ::-1]
    elif v == 4:
        out = image[::-1]
    elif v == 5:
        out = np.swapaxes(image, 0, 1)
    elif v == 6:
        out = np.swapaxes(image[::-1], 0, 1)
    elif v == 7:
        out = np.swapaxes(image[::-1, ::-1], 0, 1)
    elif v == 8:
        out = np.swapaxes(image, 0, 1)[::-1]
    else:
        raise StageError(f"orientation: expected a value in 1..8, got {value!r}")
    return np.ascontiguousarray(out)


@register_stage
class Orientation(Stage, type="orientation", accepts=frozenset(RGB_KINDS)):
    """Make the image upright from ``meta.orientation`` (or an explicit ``value``)."""

    class Params(StageParams):
        #: EXIF orientation 1..8; None reads meta.orientation
        value: Optional[int] = None
        convention: Literal["exif", "sidd"] = "exif"

    def check_params(self, p) -> None:
        v = p.value
        if v is not None and not 1 <= v <= 8:
            raise StageError(f"orientation: value: expected an EXIF orientation 1..8, got {v}")

    def transform_value(self, meta) -> int:
        """The EXIF orientation (1..8) this stage applies to a frame with metadata ``meta``."""
        v = self.params.value if self.params.value is not None else meta.orientation
        if v is None or not 1 <= int(v) <= 8:
            raise MetadataError(f"{meta.source or 'frame'}: Orientation: expected 1..8, got {v!r}")
        v = int(v)
        if self.params.convention == "sidd":
            v = _SIDD_SWAP.get(v, v)
        return v

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        v = self.transform_value(frame.meta)
        meta = frame.meta.copy()
        meta.orientation = 1
        return frame.evolve(orient(frame.data, v), meta=meta, step=self.type)
