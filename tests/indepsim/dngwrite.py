"""A small, independent DNG writer on top of ``tifffile`` (Adobe DNG Specification 1.7, ch. 4-6).

One uncompressed 16-bit IFD0 raw image (NewSubfileType 0) with the CFA or LinearRaw
photometric interpretation and the tags a raw reader needs: DNGVersion, UniqueCameraModel,
CFARepeatPatternDim / CFAPattern / CFAPlaneColor / CFALayout (Bayer), BlackLevelRepeatDim /
BlackLevel, WhiteLevel, ColorMatrix1, AsShotNeutral, ExposureTime, ISOSpeedRatings.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import tifffile

_COLOURS = {"R": 0, "G": 1, "B": 2}
# TIFF type codes
BYTE, ASCII, SHORT, LONG, RATIONAL, SRATIONAL = 1, 2, 3, 4, 5, 10


def _rational(x: float, limit: int = 1_000_000) -> tuple[int, int]:
    f = Fraction(float(x)).limit_denominator(limit)
    return f.numerator, f.denominator


def write_dng(path, data: np.ndarray, *, cfa: str | None, black: np.ndarray | float, white: int,
              iso: float, exposure_s: float, model: str = "indepsim sensor") -> None:
    """Write ``data`` (H, W) uint16 DN as a DNG.

    ``black`` is a scalar or a 2x2 array (declared black per CFA site, DN); stored as RATIONAL
    with BlackLevelRepeatDim 2x2 (1x1 for a scalar).
    """
    data = np.ascontiguousarray(data, dtype=np.uint16)
    b = np.asarray(black, dtype=np.float64)
    if b.ndim == 0 or np.all(b == b.flat[0]):
        rep, vals = (1, 1), [float(b.flat[0])]
    else:
        rep, vals = (2, 2), [float(v) for v in np.broadcast_to(b, (2, 2)).ravel()]
    black_rat = []
    for v in vals:
        black_rat += list(_rational(v, 1000))
    tags = [
        (271, ASCII, 0, "indepsim", True),  # Make
        (272, ASCII, 0, model, True),  # Model
        (50706, BYTE, 4, (1, 4, 0, 0), True),  # DNGVersion
        (50707, BYTE, 4, (1, 1, 0, 0), True),  # DNGBackwardVersion
        (50708, ASCII, 0, model, True),  # UniqueCameraModel
        (50713, SHORT, 2, rep, True),  # BlackLevelRepeatDim
        (50714, RATIONAL, len(vals), tuple(black_rat), True),  # BlackLevel
        (50717, LONG, 1, int(white), True),  # WhiteLevel
        (33434, RATIONAL, 1, _rational(exposure_s), True),  # ExposureTime
        (34855, SHORT, 1, round(iso), True),  # ISOSpeedRatings
    ]
    if cfa is not None:
        photometric = 32803
        tags += [
            (33421, SHORT, 2, (2, 2), True),  # CFARepeatPatternDim
            (33422, BYTE, 4, tuple(_COLOURS[c] for c in cfa), True),  # CFAPattern
            (50710, BYTE, 3, (0, 1, 2), True),  # CFAPlaneColor
            (50711, SHORT, 1, 1, True),  # CFALayout rectangular
            (50721, SRATIONAL, 9, (1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1), True),  # ColorMatrix1
            (50728, RATIONAL, 3, (1, 1, 1, 1, 1, 1), True),  # AsShotNeutral
            (50778, SHORT, 1, 21, True),  # CalibrationIlluminant1 D65
        ]
    else:
        photometric = 34892  # LinearRaw
        tags += [(50721, SRATIONAL, 3, (1, 1, 1, 1, 1, 1), True)]
    # tifffile insists on 3 samples for LinearRaw: write BlackIsZero, then patch the tag in place
    with tifffile.TiffWriter(path, bigtiff=False) as tw:
        tw.write(data, photometric=photometric if cfa is not None else 1, subfiletype=0, compression=None,
                 planarconfig=None, metadata=None, extratags=tags, software="indepsim")
    if cfa is None:
        with tifffile.TiffFile(path, mode="r+b") as tf:
            tf.pages[0].tags["PhotometricInterpretation"].overwrite(photometric)
