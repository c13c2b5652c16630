"""Write a ground-truth estimate as a DNG with the burst's own metadata."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import DatasetError
from ..frame import RawFrame


def write_ground_truth_dng(path: str | Path, result, burst) -> Path:
    """Write ``result.gt`` as a 16-bit DNG carrying the burst's metadata.

    The estimate is turned back into DN with the burst's black and white levels
    and rounded (the ``.npz`` keeps the float32 values); values outside
    0..white clip, pixels without any sample (NaN) are written as black.
    Needs a Bayer burst read from DNG files (its metadata is copied).
    """
    from ..io.dng_write import write_dng

    meta = getattr(burst, "meta", None)
    if meta is None or meta.cfa is None:
        raise DatasetError(f"{path}: DNG output needs a Bayer burst read from DNG files (its metadata is copied); "
                           "write the .npz instead")
    # normalised 1.0 is the white level: estimates above it (censored fits) clip there, as documented
    gt = np.minimum(np.where(np.isfinite(result.gt), result.gt, 0.0), 1.0).astype(np.float32)
    meta = meta.replace(source="", noise_profile=None)
    return write_dng(path, RawFrame(gt, meta, kind="raw"), protect=tuple(burst.names),
                     software="simcam gt (ground truth from a burst)")
