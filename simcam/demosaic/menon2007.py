"""Menon, Andriani & Calvagno (2007) DDFAPD demosaicing, float32, on row bands in threads.

Menon, D., Andriani, S. and Calvagno, G. (2007). "Demosaicing with directional
filtering and a posteriori decision." IEEE Trans. Image Processing 16(1),
132-141. doi:10.1109/TIP.2006.884928

A float32 transcription of colour-demosaicing's
``demosaicing_CFA_Bayer_Menon2007`` (same steps, same kernels, same border
handling: scipy ``mode="mirror"`` for the 1-D filters, ``mode="constant"`` for
the directional classifier, numpy ``reflect`` for the colour-difference
gradients), with its refining step (section III.C), compiled with numba site by
site (:mod:`simcam.demosaic._menon_kernel`; the filters round as scipy's do). It
agrees with that function within float32 rounding, without importing
colour-science (seconds of start-up) and at a quarter of its memory. Against
the numpy transcription it replaced (full-image ``np.where`` and scipy passes)
the output is the same bytes (NaN where it gave NaN) and a band takes ~4x
less time (the ``sidd-srgb`` render of ``benchmarks/render.py`` uses it).

Every output pixel depends on input rows at most :data:`HALO` rows away, so
the image is processed in bands of :data:`BAND` rows (each with ``HALO`` rows of
context either side, cut at the image's own borders) on a thread pool; the
result is the same bytes whatever the number of threads.
"""

from __future__ import annotations

import numpy as np

from ._planes import check_mosaic

#: rows per band (even: bands keep the CFA phase)
BAND = 128
#: context rows either side of a band (even; the receptive field is under 12 rows)
HALO = 16


def _colour_codes(cfa: str) -> np.ndarray:
    """The colour (0 R, 1 G, 2 B) at CFA phases (0,0), (0,1), (1,0), (1,1)."""
    return np.array(["RGB".index(c) for c in cfa], np.int64)


def demosaic_menon2007(mosaic: np.ndarray, cfa: str = "RGGB", *, refining_step: bool = True, sink=None):
    """Demosaic with DDFAPD (Menon et al. 2007, doi:10.1109/TIP.2006.884928).

    Parameters
    ----------
    mosaic : ndarray
        H x W Bayer mosaic; H, W >= 2.
    cfa : str
        "RGGB", "BGGR", "GRBG" or "GBRG".
    refining_step : bool
        Apply the paper's refining step (section III.C).
    sink : callable, optional
        ``sink(y0, y1, block) -> bool``: instead of an H x W x 3 output, each band's output rows
        ``[y0, y1)`` (``block``, (y1 - y0) x W x 3 float32, valid during the call) are handed to it from
        the band's thread as soon as they are computed; the return value is then True if any call
        returned True (as :func:`simcam.demosaic.demosaic_malvar2004`'s).

    Returns
    -------
    ndarray
        H x W x 3 float32, not clipped (with ``sink``: the bool above).

    Examples
    --------
    >>> import numpy as np
    >>> out = demosaic_menon2007(np.ones((8, 8), np.float32), "BGGR", refining_step=False)
    >>> out.dtype.name, out.shape
    ('float32', (8, 8, 3))
    """
    import threading

    from ..parallel import run_bands
    from ._menon_kernel import menon_band

    m, cfa = check_mosaic(mosaic, cfa, "menon2007")
    m = np.ascontiguousarray(m, dtype=np.float32)
    colour = _colour_codes(cfa)
    h, w = m.shape
    out = np.empty((h, w, 3), np.float32) if sink is None else None
    local = threading.local()

    def band(r0: int, r1: int) -> bool:
        a, b = max(0, r0 - HALO), min(h, r1 + HALO)
        if sink is None:
            menon_band(m[a:b], colour, bool(refining_step), out[r0:r1], r0 - a, r1 - a)
            return False
        buf = getattr(local, "buf", None)
        if buf is None:
            buf = local.buf = np.empty((min(BAND, h), w, 3), np.float32)
        menon_band(m[a:b], colour, bool(refining_step), buf[:r1 - r0], r0 - a, r1 - a)
        return bool(sink(r0, r1, buf[:r1 - r0]))

    stopped = run_bands(h, band, rows=BAND)
    return out if sink is None else stopped
