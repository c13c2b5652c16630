"""Menon, Andriani & Calvagno (2007) DDFAPD on one row band, compiled with numba.

Menon, D., Andriani, S. and Calvagno, G. (2007). "Demosaicing with directional filtering and a
posteriori decision." IEEE Trans. Image Processing 16(1), 132-141 (with the refining step of its
section III.C).

The steps, kernels and border rules of colour-demosaicing's ``demosaicing_CFA_Bayer_Menon2007``,
computed site by site in one compiled pass per step instead of full-image numpy passes: each
interpolation is evaluated only at the sites that use it (``np.where`` evaluates both branches
everywhere). simcam's previous float32 numpy transcription (scipy.ndimage filters on whole bands)
gave the same values bit for bit on finite data.

The arithmetic follows scipy.ndimage exactly: the 1-D filters (all symmetric) accumulate in float64 in scipy's order for symmetric
kernels, ``x[i] w[0] + (x[i - 2] + x[i + 2]) w[2] + (x[i - 1] + x[i + 1]) w[1]``, at ``mode="mirror"``
(``d c b | a b c d | c b a``); the 5 x 5 directional classifier accumulates in float64 over the
non-zero taps of the flipped kernel in C order, zero outside (``mode="constant"``); every filter
output is rounded to float32 and the rest is float32 arithmetic in numpy's order of operations.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# the 1-D kernels as scipy sees them (float64 of the float32 kernels): centre, +-1, +-2 taps
_H0_0, _H0_1, _H0_2 = 0.0, 0.5, 0.0
_H1_0, _H1_1, _H1_2 = 0.5, 0.0, -0.25
_KB_0, _KB_1 = 0.0, 0.5
_FIR = float(np.float32(1.0 / 3.0))


@njit(inline="always")
def _mir(k, n):
    """scipy's ``mode="mirror"`` (numpy's ``pad(mode="reflect")``) index."""
    if n == 1:
        return 0
    while k < 0 or k >= n:
        if k < 0:
            k = -k
        if k >= n:
            k = 2 * (n - 1) - k
    return k


@njit(cache=True)
def _mirror_table(n):
    """``t[k + 2] = _mir(k, n)`` for k in -2 .. n + 1."""
    t = np.empty(n + 4, np.int64)
    for k in range(-2, n + 2):
        t[k + 2] = _mir(k, n)
    return t


@njit(inline="always")
def _h5(x, i, j, cj, c0, c1, c2):
    t = np.float64(x[i, j]) * c0
    t += (np.float64(x[i, cj[j]]) + np.float64(x[i, cj[j + 4]])) * c2
    t += (np.float64(x[i, cj[j + 1]]) + np.float64(x[i, cj[j + 3]])) * c1
    return np.float32(t)


@njit(inline="always")
def _v5(x, i, j, ri, c0, c1, c2):
    t = np.float64(x[i, j]) * c0
    t += (np.float64(x[ri[i], j]) + np.float64(x[ri[i + 4], j])) * c2
    t += (np.float64(x[ri[i + 1], j]) + np.float64(x[ri[i + 3], j])) * c1
    return np.float32(t)


@njit(inline="always")
def _h3(x, i, j, cj, c0, c1):
    t = np.float64(x[i, j]) * c0
    t += (np.float64(x[i, cj[j + 1]]) + np.float64(x[i, cj[j + 3]])) * c1
    return np.float32(t)


@njit(inline="always")
def _v3(x, i, j, ri, c0, c1):
    t = np.float64(x[i, j]) * c0
    t += (np.float64(x[ri[i + 1], j]) + np.float64(x[ri[i + 3], j])) * c1
    return np.float32(t)


@njit(inline="always")
def _kb_h(own, X, Y, i, j, cj):
    """``(own + KB * X) - KB * Y`` along the row, each filter rounded to float32, as numpy evaluates
    ``own + cnv(X, KB) - cnv(Y, KB)``. (The direction is chosen at the call sites: one helper with a
    direction flag made the passes 2-4x slower, its inlined branches defeating LLVM's optimiser.)"""
    return (own + _h3(X, i, j, cj, _KB_0, _KB_1)) - _h3(Y, i, j, cj, _KB_0, _KB_1)


@njit(inline="always")
def _kb_v(own, X, Y, i, j, ri):
    """:func:`_kb_h` along the column."""
    return (own + _v3(X, i, j, ri, _KB_0, _KB_1)) - _v3(Y, i, j, ri, _KB_0, _KB_1)


@njit(cache=True, nogil=True, error_model="numpy")
def menon_band(x, colour, refining_step, out, keep0, keep1):
    """Demosaic the band ``x`` (h x w float32, its first row and column on CFA phase (0, 0)) and
    write its rows ``keep0:keep1`` into ``out`` (``(keep1 - keep0) x w x 3`` float32).

    ``colour`` (int array of 4): the colour (0 R, 1 G, 2 B) at phases (0,0), (0,1), (1,0), (1,1).
    """
    h, w = x.shape
    f32 = np.float32
    zero = f32(0.0)
    ri, cj = _mirror_table(h), _mirror_table(w)  # row / column k at ri[k + 2] / cj[k + 2]
    # the colour of each row's and column's non-green sites (rows and columns alternate R and B)
    red_row0 = colour[0] == 0 or colour[1] == 0  # row phase 0 holds the red sites

    G_H = np.empty((h, w), np.float32)
    G_V = np.empty((h, w), np.float32)
    C_H = np.empty((h, w), np.float32)
    C_V = np.empty((h, w), np.float32)
    for i in range(h):
        for j in range(w):
            c = colour[(i & 1) * 2 + (j & 1)]
            v = x[i, j]
            if c == 1:
                G_H[i, j] = v
                G_V[i, j] = v
                C_H[i, j] = zero
                C_V[i, j] = zero
            else:
                gh = _h5(x, i, j, cj, _H0_0, _H0_1, _H0_2) + _h5(x, i, j, cj, _H1_0, _H1_1, _H1_2)
                gv = _v5(x, i, j, ri, _H0_0, _H0_1, _H0_2) + _v5(x, i, j, ri, _H1_0, _H1_1, _H1_2)
                G_H[i, j] = gh
                G_V[i, j] = gv
                C_H[i, j] = v - gh
                C_V[i, j] = v - gv
    # D_H, D_V with two rows and columns of zeros around (the classifier's constant-0 border)
    D_H = np.zeros((h + 4, w + 4), np.float32)
    D_V = np.zeros((h + 4, w + 4), np.float32)
    for i in range(h):
        i2 = ri[i + 4]
        for j in range(w):
            D_H[i + 2, j + 2] = abs(C_H[i, j] - C_H[i, cj[j + 4]])
            D_V[i + 2, j + 2] = abs(C_V[i, j] - C_V[i2, j])
    # the directional classifier: scipy.ndimage.convolve with K (and K.T), constant 0 outside;
    # the flipped kernels' non-zero taps in C order
    M = np.empty((h, w), np.bool_)
    G = np.empty((h, w), np.float32)
    for i in range(h):
        for j in range(w):
            a, b = i + 2, j + 2
            dh = np.float64(D_H[a - 2, b - 2])
            dh += np.float64(D_H[a - 2, b])
            dh += np.float64(D_H[a - 1, b - 1])
            dh += np.float64(D_H[a, b - 2]) * 3.0
            dh += np.float64(D_H[a, b]) * 3.0
            dh += np.float64(D_H[a + 1, b - 1])
            dh += np.float64(D_H[a + 2, b - 2])
            dh += np.float64(D_H[a + 2, b])
            dv = np.float64(D_V[a - 2, b - 2])
            dv += np.float64(D_V[a - 2, b]) * 3.0
            dv += np.float64(D_V[a - 2, b + 2])
            dv += np.float64(D_V[a - 1, b - 1])
            dv += np.float64(D_V[a - 1, b + 1])
            dv += np.float64(D_V[a, b - 2])
            dv += np.float64(D_V[a, b]) * 3.0
            dv += np.float64(D_V[a, b + 2])
            m = f32(dv) >= f32(dh)
            M[i, j] = m
            G[i, j] = G_H[i, j] if m else G_V[i, j]
    R = np.empty((h, w), np.float32)
    B = np.empty((h, w), np.float32)
    for i in range(h):
        for j in range(w):
            c = colour[(i & 1) * 2 + (j & 1)]
            R[i, j] = x[i, j] if c == 0 else zero
            B[i, j] = x[i, j] if c == 2 else zero
    # red and blue at the green sites: along the row where the row holds that colour, else along the
    # column (each reads only sites of its own colour and G: one pass for both)
    for i in range(h):
        red_row = ((i & 1) == 0) == red_row0
        for j in range(w):
            if colour[(i & 1) * 2 + (j & 1)] == 1:
                g = G[i, j]
                if red_row:
                    R[i, j] = _kb_h(g, R, G, i, j, cj)
                    B[i, j] = _kb_v(g, B, G, i, j, ri)
                else:
                    R[i, j] = _kb_v(g, R, G, i, j, ri)
                    B[i, j] = _kb_h(g, B, G, i, j, cj)
    # red at blue sites and blue at red sites, in the classifier's direction (each reads its neighbours,
    # green sites, only: one pass for both)
    for i in range(h):
        for j in range(w):
            c = colour[(i & 1) * 2 + (j & 1)]
            if c == 2:
                if M[i, j]:
                    R[i, j] = _kb_h(B[i, j], R, B, i, j, cj)
                else:
                    R[i, j] = _kb_v(B[i, j], R, B, i, j, ri)
            elif c == 0:
                if M[i, j]:
                    B[i, j] = _kb_h(R[i, j], B, R, i, j, cj)
                else:
                    B[i, j] = _kb_v(R[i, j], B, R, i, j, ri)
    if refining_step:
        _refine(R, G, B, M, colour, red_row0, ri, cj)
    for i in range(keep0, keep1):
        for j in range(w):
            out[i - keep0, j, 0] = R[i, j]
            out[i - keep0, j, 1] = G[i, j]
            out[i - keep0, j, 2] = B[i, j]


@njit(inline="always")
def _refine(R, G, B, M, colour, red_row0, ri, cj):
    """Section III.C of the paper, as colour-demosaicing's ``refining_step_Menon2007``: in place."""
    h, w = R.shape
    # green at red and blue sites from the colour differences smoothed along the classifier's direction
    R_G = R - G
    B_G = B - G
    for i in range(h):
        for j in range(w):
            c = colour[(i & 1) * 2 + (j & 1)]
            if c == 0:
                if M[i, j]:
                    G[i, j] = R[i, j] - _h3(R_G, i, j, cj, _FIR, _FIR)
                else:
                    G[i, j] = R[i, j] - _v3(R_G, i, j, ri, _FIR, _FIR)
            elif c == 2:
                if M[i, j]:
                    G[i, j] = B[i, j] - _h3(B_G, i, j, cj, _FIR, _FIR)
                else:
                    G[i, j] = B[i, j] - _v3(B_G, i, j, ri, _FIR, _FIR)
    # red and blue at green sites from the (new) colour differences along the line of that colour
    R_G = R - G
    B_G = B - G
    for i in range(h):
        red_row = ((i & 1) == 0) == red_row0
        for j in range(w):
            if colour[(i & 1) * 2 + (j & 1)] != 1:
                continue
            g = G[i, j]
            if red_row:  # a green site in a red row sits in a blue column
                R[i, j] = g + _h3(R_G, i, j, cj, _KB_0, _KB_1)
                B[i, j] = g + _v3(B_G, i, j, ri, _KB_0, _KB_1)
            else:
                R[i, j] = g + _v3(R_G, i, j, ri, _KB_0, _KB_1)
                B[i, j] = g + _h3(B_G, i, j, cj, _KB_0, _KB_1)
    # red at blue sites and blue at red sites from R - B (blue at a red site reads R there, which the red
    # update at blue sites leaves as it is: one pass for both)
    R_B = R - B
    for i in range(h):
        for j in range(w):
            c = colour[(i & 1) * 2 + (j & 1)]
            if c == 2:
                if M[i, j]:
                    R[i, j] = B[i, j] + _h3(R_B, i, j, cj, _FIR, _FIR)
                else:
                    R[i, j] = B[i, j] + _v3(R_B, i, j, ri, _FIR, _FIR)
            elif c == 0:
                if M[i, j]:
                    B[i, j] = R[i, j] - _h3(R_B, i, j, cj, _FIR, _FIR)
                else:
                    B[i, j] = R[i, j] - _v3(R_B, i, j, ri, _FIR, _FIR)


def warm() -> None:
    """Run a compiled function once: numba's once-per-process set-up (its compiler context, ~0.6 s even
    when every kernel comes from the on-disk cache) is then done."""
    _mirror_table(2)
