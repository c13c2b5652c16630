"""Rendering with a DNG camera profile: the kernels of the ``dcp`` stage (float32, vectorised).

What the DNG Specification 1.7.0.0 defines and simcam implements:

* chapter 6, "Mapping Camera Color Space to CIE XYZ Space": camera RGB -> XYZ (D50) with the
  profile's ColorMatrix / ForwardMatrix interpolated for the white's CCT
  (:mod:`simcam.colour.dng`); the hue/saturation/value tables are interpolated between
  ProfileHueSatMapData1 and ProfileHueSatMapData2 with the *same* weight as the matrices
  (:func:`mix_tables`);
* chapter 4, tags ProfileHueSatMapDims/Data1/Data2/Encoding and ProfileLookTableDims/Data/
  Encoding: tables of (hue shift in degrees, saturation scale, value scale) indexed by the
  hue (6 units per turn, hue divisions spread evenly, wrapping around), saturation and
  value of a linear ProPhoto RGB (ROMM RGB, D50) colour, stored value-major, then hue, then
  saturation; with encoding 1 the value axis is indexed (and the new value decoded) in
  sRGB gamma (:func:`apply_hsv_table`);
* chapter 4, ProfileToneCurve: (input, output) pairs from (0, 0) to (1, 1) joined by a
  cubic spline (:func:`spline_table`), applied in linear ProPhoto RGB;
* chapter 4, BaselineExposure + BaselineExposureOffset and DefaultBlackRender.

What the specification leaves to the renderer is done as the Adobe DNG SDK's reference
renderer (``dng_render``) does it, the behaviour Adobe Camera Raw, RawTherapee
(``rtengine/dcp.cc``) and other DCP-aware converters follow:

1. camera values clipped at the camera white, matrix to linear ProPhoto RGB, clipped to [0, 1];
2. HueSatMap (trilinear in hue, saturation and value; hue and saturation from the HSV of the
   linear values, the value axis possibly sRGB-encoded; saturation and value clipped to 1);
3. exposure ramp (:func:`exposure_ramp`): total exposure ``E`` = BaselineExposure +
   BaselineExposureOffset + user exposure; white at ``2^-max(E, 0)``, black at
   ``shadows / 1000`` with a quadratic toe, clipped at 1;
4. LookTable, as 2.;
5. tone curve, hue-preserving "RGB tone" (:func:`rgb_tone`: the curve is applied to the
   largest and smallest channel, the middle one keeps its relative position), the curve being
   the profile's (natural cubic spline) preceded, for ``E < 0``, by the SDK's darkening curve
   (:func:`exposure_tone`);
6. ProPhoto RGB -> XYZ (D50) (then sRGB in the pipeline's next stages).

Where simcam deviates: the SDK and RawTherapee decode the value of a *2.5D* table
(ValueDivisions = 1) through the sRGB curve when the encoding tag is 1 although the value
was never encoded (a no-op table then darkens the image); the tag only concerns indexing
the value axis (chapter 4), so simcam ignores the encoding of 2.5D tables. The SDK reads
the curves through 4096-entry tables; simcam evaluates the ramp and the encoding in closed
form and tabulates only the spline (4096 intervals, linear interpolation).

References: Adobe, *Digital Negative (DNG) Specification* 1.7.0.0 (2023), chapters 4 and 6;
Adobe DNG SDK 1.7 ``dng_render.cpp``, ``dng_reference.cpp`` (order of operations);
ISO 22028-2:2013 (ROMM RGB primaries); IEC 61966-2-1:1999 (sRGB transfer curve).
"""

from __future__ import annotations

import numpy as np

from .dng import D50_XY, xy_to_xyz

#: ROMM RGB (ProPhoto RGB) primaries, CIE 1931 xy (ISO 22028-2); white D50.
PROPHOTO_PRIMARIES = np.array([[0.7347, 0.2653], [0.1596, 0.8404], [0.0366, 0.0001]])
#: Table size of the tone curve (intervals), as the DNG SDK's ``dng_1d_table``.
TONE_TABLE_SIZE = 4096


def rgb_to_xyz_matrix(primaries, white_xy) -> np.ndarray:
    """RGB -> XYZ (white Y = 1) of an RGB space given its primaries' and white's xy (3x3 float64)."""
    p = np.asarray(primaries, dtype=np.float64)
    cols = np.stack([xy_to_xyz(xy) for xy in p], axis=1)  # XYZ of each primary, Y = 1
    scale = np.linalg.solve(cols, xy_to_xyz(white_xy))
    return cols * scale


#: Linear ProPhoto RGB -> XYZ D50 (and its inverse); white D50 maps to R = G = B = 1.
PROPHOTO_TO_XYZ_D50 = rgb_to_xyz_matrix(PROPHOTO_PRIMARIES, D50_XY)
XYZ_D50_TO_PROPHOTO = np.linalg.inv(PROPHOTO_TO_XYZ_D50)


# -- sRGB transfer (table encoding) ------------------------------------------------------------

def srgb_encode(x: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 encoding of linear ``x`` in [0, 1] (float32)."""
    x = np.asarray(x, dtype=np.float32)
    hi = np.float32(1.055) * np.power(np.maximum(x, np.float32(0.0031308)), np.float32(1 / 2.4)) - np.float32(0.055)
    return np.where(x <= np.float32(0.0031308), x * np.float32(12.92), hi).astype(np.float32, copy=False)


def srgb_decode(y: np.ndarray) -> np.ndarray:
    """Inverse of :func:`srgb_encode` (float32)."""
    y = np.asarray(y, dtype=np.float32)
    hi = np.power((np.maximum(y, np.float32(0.04045)) + np.float32(0.055)) / np.float32(1.055), np.float32(2.4))
    return np.where(y <= np.float32(0.04045), y / np.float32(12.92), hi).astype(np.float32, copy=False)


# -- HSV ----------------------------------------------------------------------------------------

def rgb_to_hsv(r: np.ndarray, g: np.ndarray, b: np.ndarray):
    """(h, s, v) of RGB arrays: hue in [0, 6) (0 red, 2 green, 4 blue), s = (max - min) / max, v = max.

    A grey (max = min) has h = s = 0. Ties are resolved red, then green (the DNG SDK's order).
    """
    v = np.maximum(np.maximum(r, g), b)
    gap = v - np.minimum(np.minimum(r, g), b)
    pos = gap > 0
    inv_gap = np.float32(1.0) / np.where(pos, gap, np.float32(1.0))
    h = np.where(r == v, (g - b) * inv_gap,
                 np.where(g == v, np.float32(2.0) + (b - r) * inv_gap, np.float32(4.0) + (r - g) * inv_gap))
    h = np.where(h < 0, h + np.float32(6.0), h)
    h = np.where(pos, h, np.float32(0.0)).astype(np.float32, copy=False)
    s = np.where(pos & (v > 0), gap / np.where(v > 0, v, np.float32(1.0)), np.float32(0.0)).astype(np.float32, copy=False)
    return h, s, v


def hsv_to_rgb(h: np.ndarray, s: np.ndarray, v: np.ndarray):
    """Inverse of :func:`rgb_to_hsv` for hue in [0, 6): channel ``c = v (1 - s clip(min(k, 4 - k), 0, 1))``
    with ``k = (n + h) mod 6``, n = 5 (red), 3 (green), 1 (blue) — the hexcone sectors in one formula."""
    vs = v * s
    out = []
    for n in (5.0, 3.0, 1.0):
        k = h + np.float32(n)
        k = np.where(k >= 6, k - np.float32(6.0), k)
        w = np.clip(np.minimum(k, np.float32(4.0) - k), np.float32(0.0), np.float32(1.0))
        out.append((v - vs * w).astype(np.float32, copy=False))
    return out[0], out[1], out[2]


# -- hue/saturation/value tables ------------------------------------------------------------------

def mix_tables(data1: np.ndarray, data2: np.ndarray | None, weight1: float) -> np.ndarray:
    """``weight1 * data1 + (1 - weight1) * data2`` entry by entry (DNG 1.7.0.0 ch. 6: the tables are
    interpolated with the colour matrices' weight); ``data1`` when there is no second table."""
    if data2 is None or weight1 >= 1.0:
        return np.asarray(data1, dtype=np.float32)
    if weight1 <= 0.0:
        return np.asarray(data2, dtype=np.float32)
    w = np.float32(weight1)
    return (w * data1 + (np.float32(1.0) - w) * data2).astype(np.float32)


def apply_hsv_table(r: np.ndarray, g: np.ndarray, b: np.ndarray, data: np.ndarray, encoding: int = 0):
    """Apply one hue/saturation/value table to linear RGB in [0, 1]; returns (r, g, b) float32.

    ``data``: float32 (value, hue, saturation, 3) divisions of (hue shift in degrees,
    saturation scale, value scale). Hue index ``h * hue_divisions / 6`` with the last hue
    division interpolating towards the first (wrap-around); saturation index
    ``s * (sat_divisions - 1)``; value index ``v * (val_divisions - 1)``, on sRGB-encoded
    ``v`` when ``encoding`` is 1 (3D tables only, see the module docstring). Trilinear
    (bilinear for ValueDivisions = 1). Then ``h += shift * 6 / 360`` (mod 6),
    ``s = min(s * sat_scale, 1)``, ``v = clip(v * val_scale, 0, 1)``.
    """
    nv, nh, ns, _ = data.shape
    table = np.ascontiguousarray(data, dtype=np.float32).reshape(-1, 3)
    columns = [np.ascontiguousarray(table[:, k]) for k in range(3)]  # hue shift, sat scale, value scale
    one = np.float32(1.0)
    h, s, v = rgb_to_hsv(r, g, b)
    # hue: h * divisions / 6; the last division interpolates towards the first (wrap-around)
    hf = h * np.float32(nh / 6.0 if nh >= 2 else 0.0)
    h0 = hf.astype(np.intp)
    np.minimum(h0, nh - 1, out=h0)
    hf -= h0.astype(np.float32)
    h1 = h0 + 1
    h1[h1 >= nh] = 0
    # saturation: s * (divisions - 1), the last cell closed at s = 1
    sf = s * np.float32(ns - 1)
    s0 = sf.astype(np.intp)
    np.minimum(s0, ns - 2, out=s0)
    sf -= s0.astype(np.float32)
    i0 = h0 * ns
    i0 += s0
    i1 = h1 * ns
    i1 += s0
    hg = one - hf
    sg = one - sf
    corners = [(i0, hg * sg), (i0 + 1, hg * sf), (i1, hf * sg), (i1 + 1, hf * sf)]
    encoded = encoding == 1 and nv > 1
    venc = srgb_encode(np.clip(v, 0, 1)) if encoded else v
    if nv > 1:  # value: v * (divisions - 1) (on the encoded value), then trilinear
        vf = venc * np.float32(nv - 1)
        v0 = vf.astype(np.intp)
        np.minimum(v0, nv - 2, out=v0)
        vf -= v0.astype(np.float32)
        vg = one - vf
        base = v0 * (nh * ns)
        plane = nh * ns
        lower = [(i + base, w * vg) for i, w in corners]
        upper = [(il + plane, w * vf) for (il, _), (_, w) in zip(lower, corners)]
        corners = lower + upper
    e = []
    for col in columns:
        acc = np.take(col, corners[0][0], mode="clip")
        acc *= corners[0][1]
        for idx, w in corners[1:]:
            term = np.take(col, idx, mode="clip")
            term *= w
            acc += term
        e.append(acc)
    e[0] *= np.float32(6.0 / 360.0)
    h += e[0]
    if np.abs(columns[0]).max(initial=0.0) < 360.0:  # one wrap is enough (the usual case)
        h[h < 0] += np.float32(6.0)
        h[h >= 6] -= np.float32(6.0)
    else:
        h = np.mod(h, np.float32(6.0)).astype(np.float32, copy=False)
    h[h >= 6] = 0  # float32 rounding of a wrap can land on 6
    s *= e[1]
    np.clip(s, np.float32(0.0), one, out=s)
    v = venc * e[2]
    np.clip(v, np.float32(0.0), one, out=v)
    if encoded:
        v = srgb_decode(v)
    return hsv_to_rgb(h, s, v)


# -- exposure and tone ---------------------------------------------------------------------------------

def exposure_ramp(x: np.ndarray, exposure: float, black: float) -> np.ndarray:
    """The DNG SDK's exposure/shadows ramp (``dng_function_exposure_ramp``), float32.

    ``white = 2^-max(exposure, 0)``, ``black`` (``shadows / 1000``) limited to ``0.99 white``,
    slope ``1 / (white - black)``: 0 below ``black - r``, ``(x - black) * slope`` (clipped at 1)
    above ``black + r`` and a quadratic toe ``slope / (4 r) * (x - black + r)^2`` between, with
    ``r = min(black / 2, (white - black) / 16)``.
    """
    white = 2.0 ** -max(float(exposure), 0.0)
    black = min(max(float(black), 0.0), 0.99 * white)
    slope = 1.0 / (white - black)
    radius = min(0.5 * black, (1.0 / 16.0) / slope)
    x = np.asarray(x, dtype=np.float32)
    lin = np.minimum((x - np.float32(black)) * np.float32(slope), np.float32(1.0))
    if radius <= 0.0:
        return np.maximum(lin, np.float32(0.0)).astype(np.float32, copy=False)
    q = np.float32(slope / (4.0 * radius)) * np.square(x - np.float32(black - radius))
    out = np.where(x >= black + radius, lin, np.where(x <= black - radius, np.float32(0.0), q))
    return out.astype(np.float32, copy=False)


def exposure_tone(x: np.ndarray, exposure: float) -> np.ndarray:
    """The SDK's darkening for negative exposure (``dng_function_exposure_tone``); identity for ``exposure >= 0``.

    ``x * 2^exposure`` up to 0.25, then the quadratic ``a x^2 + b x + c`` with the same value and
    slope at 0.25 that maps 1 to 1 (``a = 16/9 (1 - k)``, ``b = k - a/2``, ``c = 1 - a - b``, ``k = 2^exposure``).
    """
    x = np.asarray(x, dtype=np.float64)
    if exposure >= 0:
        return x
    k = 2.0 ** float(exposure)
    a = 16.0 / 9.0 * (1.0 - k)
    b = k - 0.5 * a
    c = 1.0 - a - b
    return np.where(x <= 0.25, x * k, (a * x + b) * x + c)


def spline_table(points: np.ndarray | None, exposure: float = 0.0, size: int = TONE_TABLE_SIZE) -> np.ndarray | None:
    """Samples at ``i / size`` (i = 0..size) of the tone curve: :func:`exposure_tone` then the
    natural cubic spline through ``points`` ((n, 2) from (0, 0) to (1, 1); second derivative 0 at
    both ends, constant beyond them, as the DNG SDK's ``dng_spline_solver``). None when the result
    is the identity (no curve, exposure >= 0)."""
    if points is None and exposure >= 0:
        return None
    x = exposure_tone(np.linspace(0.0, 1.0, size + 1), exposure)
    if points is not None:
        from scipy.interpolate import CubicSpline

        p = np.asarray(points, dtype=np.float64)
        if p.shape[0] == 2:
            x = np.interp(x, p[:, 0], p[:, 1])
        else:
            xs = np.clip(x, p[0, 0], p[-1, 0])
            x = CubicSpline(p[:, 0], p[:, 1], bc_type="natural")(xs)
    return np.clip(x, 0.0, 1.0).astype(np.float32)


def _lookup(table: np.ndarray, x: np.ndarray) -> np.ndarray:
    n = table.size - 1
    xs = np.clip(x, np.float32(0.0), np.float32(1.0)) * np.float32(n)
    i = np.minimum(xs.astype(np.int32), n - 1)
    f = xs - i.astype(np.float32)
    t0 = table[i]
    return t0 + f * (table[i + 1] - t0)


def rgb_tone(r: np.ndarray, g: np.ndarray, b: np.ndarray, table: np.ndarray):
    """Hue-preserving tone curve (the DNG SDK's ``RefBaselineRGBTone``): the curve ``table`` (samples
    on [0, 1]) maps the largest and the smallest channel; the middle one keeps its relative
    position between them, ``mid' = lo' + (hi' - lo') (mid - lo) / (hi - lo)``."""
    hi = np.maximum(np.maximum(r, g), b)
    lo = np.minimum(np.minimum(r, g), b)
    thi, tlo = _lookup(table, hi), _lookup(table, lo)
    span = hi - lo
    k = (thi - tlo) / np.where(span > 0, span, np.float32(1.0))
    return tuple((tlo + (c - lo) * k).astype(np.float32, copy=False) for c in (r, g, b))
