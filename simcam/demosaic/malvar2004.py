"""Malvar-He-Cutler (2004) gradient-corrected linear demosaicing, float32.

Malvar, H. S., He, L.-W. and Cutler, R. (2004). "High-quality linear
interpolation for demosaicing of Bayer-patterned color images." ICASSP 2004,
vol. 3, pp. 485-488. doi:10.1109/ICASSP.2004.1326587

The paper's eight 5 x 5 kernels (bilinear estimate plus a scaled Laplacian of the
known colour at the site) are evaluated only at the sites that need them: the
mosaic is split into its four CFA-phase planes and each kernel becomes a few
shifted-slice additions on one plane, in row strips that stay in cache. Output is
not clipped (negatives and overshoots kept). Border: whole-sample mirror, which
keeps the Bayer phase (see :mod:`simcam.demosaic._planes`).
"""

from __future__ import annotations

import threading

import numpy as np

from ..parallel import run_bands
from ._planes import PhaseView, StripTarget, crop_output, site_layout, strip_setup


def demosaic_malvar2004(mosaic: np.ndarray, cfa: str = "RGGB", *, sink=None):
    """Demosaic a Bayer mosaic with the Malvar-He-Cutler 2004 kernels.

    Parameters
    ----------
    mosaic : ndarray
        H x W Bayer mosaic (any real dtype; computed in float32), e.g. normalised
        raw in [0, 1] with negatives allowed. H, W >= 2; odd sizes are allowed.
    cfa : str
        "RGGB", "BGGR", "GRBG" or "GBRG" (colour of pixels (0,0), (0,1), (1,0), (1,1)).

    sink : callable, optional
        ``sink(y0, y1, block) -> bool``: instead of an H x W x 3 output, each strip's output rows
        ``[y0, y1)`` (``block``, (y1 - y0) x W x 3 float32, valid during the call) are handed to it
        as soon as they are computed, from the strip's thread; the return value is then True if any
        call returned True. A render streams strips into the display tail this way without holding
        the whole RGB image (:func:`simcam.render_samples.render_demosaic_tail`).

    Returns
    -------
    ndarray
        H x W x 3 float32 RGB in the units of ``mosaic``; the known sample of each
        pixel is copied unchanged.

    References
    ----------
    Malvar, He & Cutler, ICASSP 2004, doi:10.1109/ICASSP.2004.1326587. Equals
    ``colour_demosaicing.demosaicing_CFA_Bayer_Malvar2004`` away from the 2-pixel
    border (and everywhere on a phase-preserving mirror-padded mosaic).

    Examples
    --------
    >>> import numpy as np
    >>> mosaic = np.arange(36, dtype=np.float32).reshape(6, 6) / 36
    >>> float(demosaic_malvar2004(mosaic, "RGGB")[0, 0, 0]) == float(mosaic[0, 0])  # red at (0, 0) kept
    True
    """
    m, cfa, planes, h2, w2, rgb, rows = strip_setup(mosaic, cfa, "malvar2004", full=sink is None)
    h, w = m.shape
    target = StripTarget(rgb, sink, rows, h, w, w2)
    layout = site_layout(cfa)
    local = threading.local()

    def strip(s0: int, s1: int) -> bool:  # strips are independent: run on threads, same bytes
        bufs = getattr(local, "bufs", None)
        if bufs is None:
            bufs = local.bufs = [np.empty((rows, w2), dtype=np.float32) for _ in range(5)]
        t = [b[: s1 - s0] for b in bufs]
        dest, y0 = target.block(s0)
        local_planes = planes.strip(s0, s1)
        for (p, q), (site, horiz) in layout.items():
            nb = PhaseView(local_planes, p, q, 0, s1 - s0, w2)
            out = dest[2 * s0 - y0 + p:2 * s1 - y0:2, q::2]
            c = nb(0, 0)
            out[..., site] = c
            if site == 1:
                _green_site(nb, c, out, horiz, 2 - horiz, *t)
            else:
                _red_blue_site(nb, c, out, 2 - site, *t)
        return target.done(s0, s1, dest)

    stopped = run_bands(h2, strip, rows=rows)
    return stopped if sink is not None else crop_output(rgb, h, w)


def _red_blue_site(nb, c, out, other, t1, t2, t3, t4, t5):
    """At an R (B) site: G and B (R).

    8 G = 4 c + 2 (N + S + E + W) - A,   8 B = 6 c + 2 D - 1.5 A
    with A the four same-colour samples at distance 2 and D the four diagonals;
    written as w = 4 c - A, G = (w + 2 Gn) / 8, B = (0.75 w + D) / 4.
    """
    np.add(nb(0, -2), nb(0, 2), out=t1)
    t1 += nb(-2, 0)
    t1 += nb(2, 0)  # A
    np.multiply(c, 4.0, out=t3)
    t3 -= t1  # w = 4c - A
    np.add(nb(0, -1), nb(0, 1), out=t2)
    t2 += nb(-1, 0)
    t2 += nb(1, 0)
    t2 *= 2.0
    t2 += t3
    np.multiply(t2, 0.125, out=out[..., 1])
    np.add(nb(-1, -1), nb(-1, 1), out=t4)
    t4 += nb(1, -1)
    t4 += nb(1, 1)  # D
    np.multiply(t3, 0.75, out=t1)
    t1 += t4
    np.multiply(t1, 0.25, out=out[..., other])


def _green_site(nb, c, out, horiz, vert, t1, t2, t3, t4, t5):
    """At a G site: the colour of the horizontal neighbours and of the vertical ones.

    8 Hc = 5 c - Dg - H2 + V2 / 2 + 4 H1,   8 Vc = 5 c - Dg - V2 + H2 / 2 + 4 V1
    with Dg the four diagonal G, H2/V2 the G pairs at (0, +-2)/(+-2, 0) and H1/V1
    the pairs at (0, +-1)/(+-1, 0).
    """
    np.add(nb(-1, -1), nb(-1, 1), out=t1)
    t1 += nb(1, -1)
    t1 += nb(1, 1)
    np.multiply(c, 5.0, out=t2)
    t2 -= t1  # base = 5c - Dg
    np.add(nb(0, -2), nb(0, 2), out=t3)  # H2
    np.add(nb(-2, 0), nb(2, 0), out=t4)  # V2
    # 8 Hc from H1 (the pair at (0, +-1)), 8 Vc from V1 (at (+-1, 0)): the same formula with H2 and V2 swapped
    for (a, b), same, other, where in ((((0, -1), (0, 1)), t3, t4, horiz), (((-1, 0), (1, 0)), t4, t3, vert)):
        np.add(nb(*a), nb(*b), out=t1)
        t1 *= 4.0
        t1 += t2
        t1 -= same
        np.multiply(other, 0.5, out=t5)
        t1 += t5
        np.multiply(t1, 0.125, out=out[..., where])
