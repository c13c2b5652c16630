"""The one "raw in" step: read a DNG and normalise it (:func:`read_normalized`)."""

from __future__ import annotations

import os

from ..frame import RawFrame
from ..raw import normalize
from .dng import read_dng


def read_normalized(path: str | os.PathLike) -> RawFrame:
    """Read a DNG and map its DN to normalised raw (black 0, white 1; negatives kept).

    Parameters
    ----------
    path : str or os.PathLike
        A DNG file.

    Returns
    -------
    RawFrame
        Kind ``raw``, float32, the whole stored image, history ``read_dng(NAME)``, ``normalize``.

    Raises
    ------
    simcam.errors.DngError
        When the file is not a readable DNG.

    Examples
    --------
    >>> from pathlib import Path
    >>> import simcam
    >>> chart = Path(simcam.__file__).parents[1] / "examples" / "data" / "chart.dng"
    >>> frame = read_normalized(chart)
    >>> frame.kind, frame.data.dtype.name, frame.history[-1]
    ('raw', 'float32', 'normalize')
    """
    return normalize(read_dng(path))
