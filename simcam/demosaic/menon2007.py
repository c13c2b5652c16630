"""Menon, Andriani & Calvagno (2007) DDFAPD demosaicing, float32, on row bands in threads.

Menon, D., Andriani, S. and Calvagno, G. (2007). "Demosaicing with directional
filtering and a posteriori decision." IEEE Trans. Image Processing 16(1),
132-141. doi:10.1109/TIP.2006.884928

A float32 transcription of colour-demosaicing's
``demosaicing_CFA_Bayer_Menon2007`` (same steps, same kernels, same border
handling: scipy ``mode="mirror"`` for the 1-D filters, ``mode="constant"`` for
the directional classifier, numpy ``reflect`` for the colour-difference
gradients), with its refining step (section III.C). It agrees with that
function within float32 rounding, without importing colour-science (seconds of
start-up) and at a quarter of its memory.

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

_H0 = np.array([0.0, 0.5, 0.0, 0.5, 0.0], np.float32)
_H1 = np.array([-0.25, 0.0, 0.5, 0.0, -0.25], np.float32)
_KB = np.array([0.5, 0.0, 0.5], np.float32)
_FIR = np.full(3, 1.0 / 3.0).astype(np.float32)
_K = np.array([[0, 0, 1, 0, 1], [0, 0, 0, 1, 0], [0, 0, 3, 0, 3], [0, 0, 0, 1, 0], [0, 0, 1, 0, 1]], np.float32)


def _masks(shape, cfa: str):
    """Boolean R, G, B masks of a band starting on an even row and column."""
    h, w = shape
    out = []
    for c in "RGB":
        m = np.zeros((h, w), bool)
        for k, ch in enumerate(cfa):
            if ch == c:
                m[k // 2::2, k % 2::2] = True
        out.append(m)
    return out


def _menon_band(cfa_img: np.ndarray, pattern: str, refining_step: bool) -> np.ndarray:
    from scipy.ndimage import convolve, convolve1d

    def cnv_h(x, k):
        return convolve1d(x, k, mode="mirror")

    def cnv_v(x, k):
        return convolve1d(x, k, mode="mirror", axis=0)

    x = cfa_img
    R_m, G_m, B_m = _masks(x.shape, pattern)
    zero = np.float32(0)
    R = np.where(R_m, x, zero)
    G = np.where(G_m, x, zero)
    B = np.where(B_m, x, zero)
    G_H = np.where(~G_m, cnv_h(x, _H0) + cnv_h(x, _H1), G)
    G_V = np.where(~G_m, cnv_v(x, _H0) + cnv_v(x, _H1), G)
    C_H = np.where(R_m, R - G_H, zero)
    C_H = np.where(B_m, B - G_H, C_H)
    C_V = np.where(R_m, R - G_V, zero)
    C_V = np.where(B_m, B - G_V, C_V)
    D_H = np.abs(C_H - np.pad(C_H, ((0, 0), (0, 2)), mode="reflect")[:, 2:])
    D_V = np.abs(C_V - np.pad(C_V, ((0, 2), (0, 0)), mode="reflect")[2:, :])
    d_H = convolve(D_H, _K, mode="constant")
    d_V = convolve(D_V, np.ascontiguousarray(_K.T), mode="constant")
    mask = d_V >= d_H
    G = np.where(mask, G_H, G_V)
    M = mask
    del G_H, G_V, C_H, C_V, D_H, D_V, d_H, d_V
    R_r = np.broadcast_to(np.any(R_m, axis=1)[:, None], R.shape)
    B_r = np.broadcast_to(np.any(B_m, axis=1)[:, None], B.shape)
    gr, gb = G_m & R_r, G_m & B_r
    R = np.where(gr, G + cnv_h(R, _KB) - cnv_h(G, _KB), R)
    R = np.where(gb, G + cnv_v(R, _KB) - cnv_v(G, _KB), R)
    B = np.where(gb, G + cnv_h(B, _KB) - cnv_h(G, _KB), B)
    B = np.where(gr, G + cnv_v(B, _KB) - cnv_v(G, _KB), B)
    R = np.where(B_r & B_m, np.where(M, B + cnv_h(R, _KB) - cnv_h(B, _KB), B + cnv_v(R, _KB) - cnv_v(B, _KB)), R)
    B = np.where(R_r & R_m, np.where(M, R + cnv_h(B, _KB) - cnv_h(R, _KB), R + cnv_v(B, _KB) - cnv_v(R, _KB)), B)
    if refining_step:
        R, G, B = _refine(R, G, B, R_m, G_m, B_m, M, cnv_h, cnv_v)
    return np.stack([R, G, B], axis=-1)


def _refine(R, G, B, R_m, G_m, B_m, M, cnv_h, cnv_v):
    """colour-demosaicing's ``refining_step_Menon2007`` in float32."""
    zero = np.float32(0)
    R_G = R - G
    B_G = B - G
    B_G_m = np.where(B_m, np.where(M, cnv_h(B_G, _FIR), cnv_v(B_G, _FIR)), zero)
    R_G_m = np.where(R_m, np.where(M, cnv_h(R_G, _FIR), cnv_v(R_G, _FIR)), zero)
    G = np.where(R_m, R - R_G_m, G)
    G = np.where(B_m, B - B_G_m, G)
    R_r = np.broadcast_to(np.any(R_m, axis=1)[:, None], R.shape)
    R_c = np.broadcast_to(np.any(R_m, axis=0)[None], R.shape)
    B_r = np.broadcast_to(np.any(B_m, axis=1)[:, None], B.shape)
    B_c = np.broadcast_to(np.any(B_m, axis=0)[None], B.shape)
    R_G = R - G
    B_G = B - G
    R = _at_green(R, R_G, R_G_m, G, (G_m & B_r, cnv_v), (G_m & B_c, cnv_h))
    B = _at_green(B, B_G, B_G_m, G, (G_m & R_r, cnv_v), (G_m & R_c, cnv_h))
    R_B = R - B
    R_B_m = np.where(B_m, np.where(M, cnv_h(R_B, _FIR), cnv_v(R_B, _FIR)), zero)
    R = np.where(B_m, B + R_B_m, R)
    R_B_m = np.where(R_m, np.where(M, cnv_h(R_B, _FIR), cnv_v(R_B, _FIR)), zero)
    B = np.where(R_m, R - R_B_m, B)
    return R, G, B


def _at_green(X, X_G, X_G_m, G, *steps):
    """The refining step's update of colour X at green sites: for each ``(sites, cnv)`` in turn, X - G
    smoothed by ``cnv`` (along the line of the same colour) replaces the current estimate there."""
    for sites, cnv in steps:
        X_G_m = np.where(sites, cnv(X_G, _KB), X_G_m)
        X = np.where(sites, G + X_G_m, X)
    return X


def demosaic_menon2007(mosaic: np.ndarray, cfa: str = "RGGB", *, refining_step: bool = True) -> np.ndarray:
    """Demosaic with DDFAPD (Menon et al. 2007, doi:10.1109/TIP.2006.884928).

    Parameters
    ----------
    mosaic : ndarray
        H x W Bayer mosaic; H, W >= 2.
    cfa : str
        "RGGB", "BGGR", "GRBG" or "GBRG".
    refining_step : bool
        Apply the paper's refining step (section III.C).

    Returns
    -------
    ndarray
        H x W x 3 float32, not clipped.

    Examples
    --------
    >>> import numpy as np
    >>> out = demosaic_menon2007(np.ones((8, 8), np.float32), "BGGR", refining_step=False)
    >>> out.dtype.name, out.shape
    ('float32', (8, 8, 3))
    """
    from ..parallel import run_bands

    m, cfa = check_mosaic(mosaic, cfa, "menon2007")
    h, w = m.shape
    out = np.empty((h, w, 3), np.float32)
    if h <= BAND + 2 * HALO:
        out[...] = _menon_band(m, cfa, refining_step)
        return out

    def band(r0: int, r1: int) -> bool:
        a, b = max(0, r0 - HALO), min(h, r1 + HALO)
        out[r0:r1] = _menon_band(m[a:b], cfa, refining_step)[r0 - a:r1 - a]
        return False

    run_bands(h, band, rows=BAND)
    return out
