"""Bayer demosaicing kernels (pure functions: mosaic + CFA pattern -> H x W x 3 RGB).

========== ================================================================
method     function
========== ================================================================
bilinear   :func:`demosaic_bilinear` (hand-written, float32)
malvar2004 :func:`demosaic_malvar2004` (hand-written, float32; Malvar et al. 2004)
menon2007  :func:`demosaic_menon2007` (colour-demosaicing's DDFAPD, Menon et al. 2007)
========== ================================================================
"""

from __future__ import annotations

from .bilinear import demosaic_bilinear
from .malvar2004 import demosaic_malvar2004
from .menon2007 import demosaic_menon2007

DEMOSAIC_METHODS = {
    "bilinear": demosaic_bilinear,
    "malvar2004": demosaic_malvar2004,
    "menon2007": demosaic_menon2007,
}


def demosaic(mosaic, cfa: str, method: str = "malvar2004"):
    """Demosaic a Bayer mosaic with one of :data:`DEMOSAIC_METHODS`.

    Parameters
    ----------
    mosaic : ndarray
        H x W Bayer mosaic (H, W >= 2).
    cfa : str
        "RGGB", "BGGR", "GRBG" or "GBRG".
    method : str
        A key of :data:`DEMOSAIC_METHODS`: ``"bilinear"``, ``"malvar2004"`` or ``"menon2007"``.

    Returns
    -------
    ndarray
        H x W x 3 float32 RGB in the units of ``mosaic``.

    Raises
    ------
    StageError
        ``method`` is not one of :data:`DEMOSAIC_METHODS`.

    Examples
    --------
    >>> import numpy as np
    >>> demosaic(np.full((4, 4), 0.5, np.float32), "RGGB", method="bilinear").shape
    (4, 4, 3)
    """
    from ..errors import StageError

    try:
        fn = DEMOSAIC_METHODS[method]
    except KeyError:
        raise StageError(f"demosaic: method: expected one of {sorted(DEMOSAIC_METHODS)}, got {method!r}") from None
    return fn(mosaic, cfa)


__all__ = ["DEMOSAIC_METHODS", "demosaic", "demosaic_bilinear", "demosaic_malvar2004", "demosaic_menon2007"]
