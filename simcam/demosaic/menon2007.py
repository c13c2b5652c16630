"""Menon, Andriani & Calvagno (2007) DDFAPD demosaicing, via colour-demosaicing.

Menon, D., Andriani, S. and Calvagno, G. (2007). "Demosaicing with directional
filtering and a posteriori decision." IEEE Trans. Image Processing 16(1),
132-141. doi:10.1109/TIP.2006.884928

A thin wrapper over ``colour_demosaicing.demosaicing_CFA_Bayer_Menon2007``
(float64 inside, with its refining step; its border follows scipy's
``mode="reflect"``). Slow (seconds per megapixel): a quality reference, not the
fast path.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import require_extra
from ._planes import check_mosaic


def demosaic_menon2007(mosaic: np.ndarray, cfa: str = "RGGB", *, refining_step: bool = True) -> np.ndarray:
    """Demosaic with DDFAPD (Menon et al. 2007, doi:10.1109/TIP.2006.884928).

    Parameters
    ----------
    mosaic : ndarray
        H x W Bayer mosaic; H, W >= 2.
    cfa : str
        "RGGB", "BGGR", "GRBG" or "GBRG" (same strings as colour-demosaicing).
    refining_step : bool
        Apply the paper's refining step (section III.C).

    Returns
    -------
    ndarray
        H x W x 3 float32, not clipped.
    """
    m, cfa = check_mosaic(mosaic, cfa, "menon2007")
    cd = require_extra("colour_demosaicing", "bench")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rgb = cd.demosaicing_CFA_Bayer_Menon2007(m.astype(np.float64), cfa, refining_step=refining_step)
    return np.ascontiguousarray(rgb, dtype=np.float32)
