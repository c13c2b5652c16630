"""Display transforms: XYZ (D50) -> linear sRGB, transfer functions, tone curves (pure functions).

Kernels take and return float32 arrays; matrices are float64 constants.

References: IEC 61966-2-1:1999 (sRGB: primaries, D65 white, piecewise OETF and the
published XYZ -> RGB matrix); Lam (1985) Bradford transform; Hable, J. (2010)
"Filmic Tonemapping Operators", http://filmicworlds.com/blog/filmic-tonemapping-operators/
(Uncharted 2 curve); A. Abdelhamed, simple-camera-pipeline (SIDD renderer).
"""

from __future__ import annotations

import numpy as np

from .dng import D50_XY, bradford_matrix, xy_to_xyz

#: sRGB / Rec. 709 white (D65), CIE 1931 xy, as IEC 61966-2-1 gives it.
SRGB_WHITE_XY = np.array([0.3127, 0.3290])

#: XYZ (D65, Y = 1 white) -> linear sRGB, the matrix published in IEC 61966-2-1.
XYZ_TO_SRGB = np.array([
    [3.2406, -1.5372, -0.4986],
    [-0.9689, 1.8758, 0.0415],
    [0.0557, -0.2040, 1.0570],
])

#: The XYZ -> sRGB matrix simple-camera-pipeline uses (Lindbloom's, 7 decimals) before
#: it row-normalises it (``transform_xyz_to_srgb``).
_SIDD_XYZ_TO_SRGB = np.array([
    [3.2404542, -1.5371385, -0.4985314],
    [-0.9692660, 1.8760108, 0.0415560],
    [0.0556434, -0.2040259, 1.0572252],
])


def xyz_d50_to_linear_srgb_matrix() -> np.ndarray:
    """3x3 float64: Bradford D50 -> D65, then IEC 61966-2-1 XYZ -> linear sRGB."""
    return XYZ_TO_SRGB @ bradford_matrix(xy_to_xyz(D50_XY), xy_to_xyz(SRGB_WHITE_XY))


def sidd_xyz_to_srgb_matrix() -> np.ndarray:
    """simple-camera-pipeline's XYZ -> sRGB: Lindbloom's D65 matrix with rows normalised to sum 1.

    No chromatic adaptation: XYZ (1, 1, 1) maps to RGB (1, 1, 1). Compatibility only.
    """
    return _SIDD_XYZ_TO_SRGB / _SIDD_XYZ_TO_SRGB.sum(axis=1, keepdims=True)


def apply_matrix(rgb: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """H x W x 3 image times a 3x3 matrix (``out[..., i] = sum_j M[i, j] * rgb[..., j]``), float32."""
    m = np.asarray(matrix, dtype=np.float32)
    out = rgb.astype(np.float32, copy=False) @ m.T
    return np.ascontiguousarray(out, dtype=np.float32)


# -- transfer functions ------------------------------------------------------------------

_OETF_CHUNK = 1 << 16  # samples per chunk of srgb_oetf


def srgb_oetf(x: np.ndarray) -> np.ndarray:
    """sRGB encoding (IEC 61966-2-1): ``12.92 x`` for ``x <= 0.0031308``, else ``1.055 x^(1/2.4) - 0.055``.

    Domain: linear [0, 1] (values above 1 follow the power branch, negatives the
    linear branch). Range: encoded [0, 1]. float32.
    """
    x = np.asarray(x, dtype=np.float32)
    out = np.empty_like(x)
    flat_in, flat_out = x.reshape(-1), out.reshape(-1)
    linear = np.empty(min(_OETF_CHUNK, flat_in.size), dtype=bool)
    # Cache-sized chunks, in place; x^(1/2.4) as exp(log(x)/2.4): 3x faster than
    # float32 np.power at 12 MP, within 4e-7 of the float64 curve (colour.cctf_encoding).
    for s in range(0, flat_in.size, _OETF_CHUNK):
        xi, o = flat_in[s:s + _OETF_CHUNK], flat_out[s:s + _OETF_CHUNK]
        lin = linear[:xi.size]
        np.maximum(xi, np.float32(0.0031308), out=o)
        np.log(o, out=o)
        o *= np.float32(1.0 / 2.4)
        np.exp(o, out=o)
        o *= np.float32(1.055)
        o -= np.float32(0.055)
        np.less_equal(xi, np.float32(0.0031308), out=lin)
        np.multiply(xi, np.float32(12.92), out=o, where=lin)
    return out


def power_encode(x: np.ndarray, exponent: float) -> np.ndarray:
    """``sign(x) * |x|^exponent`` (pure power "gamma", e.g. exponent 1/2.2), float32."""
    x = np.asarray(x, dtype=np.float32)
    y = np.power(np.abs(x), np.float32(exponent))
    y *= np.sign(x)  # in place: the same products as sign(x) * |x|^e, two passes fewer
    return y


# -- tone curves ------------------------------------------------------------------------------

def tone_smoothstep(x: np.ndarray) -> np.ndarray:
    """simple-camera-pipeline's "simple tone curve" ``3 x^2 - 2 x^3`` on ``x`` clipped to [0, 1].

    The cubic is monotonic only on [0, 1], hence the clip. Range [0, 1]. float32.
    """
    x = np.clip(np.asarray(x, dtype=np.float32), 0.0, 1.0)
    t = np.multiply(x, np.float32(2.0))
    np.subtract(np.float32(3.0), t, out=t)  # 3 - 2 x
    y = x * x
    y *= t  # (x x) (3 - 2 x), as x * x * (3.0 - 2.0 * x) evaluates, in float32, without the extra passes
    return y


#: Hable's Uncharted 2 curve constants: shoulder strength A, linear strength B, linear
#: angle C, toe strength D, toe numerator E, toe denominator F, linear white point W,
#: and the exposure bias he applies before the curve.
HABLE = dict(A=0.15, B=0.50, C=0.10, D=0.20, E=0.02, F=0.30, W=11.2, bias=2.0)


def _hable(x):
    a, b, c, d, e, f = (HABLE[k] for k in "ABCDEF")
    return (x * (a * x + c * b) + d * e) / (x * (a * x + b) + d * f) - e / f


def tone_filmic(x: np.ndarray, exposure: float = 0.0, white: float = 1.0) -> np.ndarray:
    """Hable (2010) "Uncharted 2" filmic curve on scene-linear values, per channel, reaching white.

    ``y = H(k x) / H(k white)`` with ``k = 2^exposure * bias``,
    ``H(x) = (x(Ax + CB) + DE) / (x(Ax + B) + DF) - E/F`` and the constants of
    :data:`HABLE`: Hable's linear white point ``W`` is put at the scene value
    ``white`` after exposure (default 1, the white at sensor clipping of a
    normalised capture), so ``white`` maps to display white 1 whatever the
    exposure. ``exposure`` in stops (EV). Negative input is clipped to 0; the
    output is display-linear, in [0, 1] for ``x <= white`` (encode it with a gamma stage).
    """
    if not (np.isfinite(white) and white > 0):
        raise ValueError(f"tone_filmic: white: expected a finite value > 0, got {white}")
    x = np.maximum(np.asarray(x, dtype=np.float32), 0.0)
    k = np.float32(2.0 ** float(exposure) * HABLE["bias"])
    return (_hable(k * x) / np.float32(_hable(k * np.float32(white)))).astype(np.float32)
