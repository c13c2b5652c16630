"""Bilinear Bayer demosaicing, float32.

Each missing colour is the mean of its nearest samples of that colour: G at an
R/B site from the four edge neighbours, R/B at a G site from the two neighbours
along the row or column holding that colour, B at an R site (R at a B site) from
the four diagonals (Losson, Macaire & Yang 2010, "Comparison of color
demosaicing methods", Adv. Imaging Electron Phys. 162, doi:10.1016/S1076-5670(10)62005-8).
Evaluated only where needed on the four CFA-phase planes; border: whole-sample
mirror, which keeps the Bayer phase (see :mod:`simcam.demosaic._planes`).
"""

from __future__ import annotations

import threading

import numpy as np

from ..parallel import run_bands
from ._planes import PhaseView, StripTarget, crop_output, site_layout, strip_setup


def demosaic_bilinear(mosaic: np.ndarray, cfa: str = "RGGB", *, sink=None):
    """Demosaic a Bayer mosaic by bilinear interpolation.

    Parameters
    ----------
    mosaic : ndarray
        H x W Bayer mosaic (computed in float32); H, W >= 2, odd sizes allowed.
    cfa : str
        "RGGB", "BGGR", "GRBG" or "GBRG".
    sink : callable, optional
        Strip by strip output instead of an H x W x 3 array, as
        :func:`simcam.demosaic.malvar2004.demosaic_malvar2004`'s ``sink`` (the return value is then a bool).

    Returns
    -------
    ndarray
        H x W x 3 float32 RGB in the units of ``mosaic``, not clipped.

    References
    ----------
    Losson et al. 2010, doi:10.1016/S1076-5670(10)62005-8. Equals
    ``colour_demosaicing.demosaicing_CFA_Bayer_bilinear`` away from the 1-pixel
    border (and everywhere on a phase-preserving mirror-padded mosaic).

    Examples
    --------
    >>> import numpy as np
    >>> rgb = demosaic_bilinear(np.full((6, 8), 0.25), "GRBG")
    >>> rgb.shape, bool(np.allclose(rgb, 0.25))
    ((6, 8, 3), True)
    """
    m, cfa, planes, h2, w2, rgb, rows = strip_setup(mosaic, cfa, "bilinear", full=sink is None)
    h, w = m.shape
    target = StripTarget(rgb, sink, rows, h, w, w2)
    local = threading.local()

    def strip(s0: int, s1: int) -> bool:  # strips are independent: run on threads, same bytes
        buf = getattr(local, "buf", None)
        if buf is None:
            buf = local.buf = np.empty((rows, w2), dtype=np.float32)
        t = buf[: s1 - s0]
        dest, y0 = target.block(s0)
        local_planes = planes.strip(s0, s1)
        for (p, q), (site, horiz) in site_layout(cfa).items():
            nb = PhaseView(local_planes, p, q, 0, s1 - s0, w2)
            out = dest[2 * s0 - y0 + p:2 * s1 - y0:2, q::2]
            out[..., site] = nb(0, 0)
            if site == 1:  # G site: row neighbours give `horiz`, column neighbours the other
                np.add(nb(0, -1), nb(0, 1), out=t)
                np.multiply(t, 0.5, out=out[..., horiz])
                np.add(nb(-1, 0), nb(1, 0), out=t)
                np.multiply(t, 0.5, out=out[..., 2 - horiz])
            else:  # R/B site: G from the 4 edge neighbours, the other from the 4 diagonals
                np.add(nb(0, -1), nb(0, 1), out=t)
                t += nb(-1, 0)
                t += nb(1, 0)
                np.multiply(t, 0.25, out=out[..., 1])
                np.add(nb(-1, -1), nb(-1, 1), out=t)
                t += nb(1, -1)
                t += nb(1, 1)
                np.multiply(t, 0.25, out=out[..., 2 - site])
        return target.done(s0, s1, dest)

    stopped = run_bands(h2, strip, rows=rows)
    return stopped if sink is not None else crop_output(rgb, h, w)
