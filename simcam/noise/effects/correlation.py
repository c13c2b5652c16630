"""``spatial_correlation``: crosstalk of the read noise between same-colour neighbours (inside each CFA plane),
or, with ``neighbours: adjacent``, between adjacent pixels of the mosaic.

Physics. The correlation the calibration loop measures is that of dark-frame
temporal noise between same-colour neighbours (2 px apart on the mosaic) with
none between adjacent, different-colour pixels: coupling in the readout chain
(shared pixel / column circuitry, per-plane processing of the readout), not
charge-domain crosstalk, which would couple adjacent pixels and the signal.
So the effect filters the *read noise*, i.e. the base model's
signal-independent Gaussian part (``NoiseModel.read_split``: beta2 of
``poisson_gaussian`` / ``nlf``, sigma of ``gaussian``) plus any
``heavy_tailed_read`` listed before it; photon shot noise stays white (a
crosstalk that also coupled shot noise would change the row/column statistics
of flat fields, which the loop checks, without any measurement constraining it).

Kernel. Inside each CFA plane the read noise is filtered by the separable
kernel ``[c, 1, c]`` along rows and along columns (4 axial same-colour
neighbours with weight ``c``, 4 diagonal ones with ``c^2``), renormalised by
``1 / (1 + 2 c^2)`` so its per-pixel variance is kept (the dark variance the
base was fitted to, and the photon-transfer curve, do not change). For white
read noise the in-plane autocorrelation at lag ``k`` (plane pixels, along
either axis) is::

    rho(1) = 2 c / (1 + 2 c^2),   rho(2) = c^2 / (1 + 2 c^2),   rho(>2) = 0,

the diagonal one is ``rho(1)^2`` and different-colour neighbours stay
uncorrelated: the lag-1 / lag-2 statistics of
``simcam.calibration.diagnostics.lag1_corr`` / ``lag2_corr`` (diluted by the shot
and quantisation noise in the data). Borders reflect about each plane's edge
pixel. Reference: EMVA 1288 R4.0 sec. 8 (spatial non-white temporal noise).

Domain ``total``. Electrical crosstalk *after* the pixel (between neighbouring column lines or in
the analogue chain) couples everything the pixel puts out, photon shot noise included, not the read
noise alone: with ``domain: total`` (``neighbours: adjacent``) all the temporal noise present at
that point of the read-out (``x - signal``: shot, dark-signal and read noise, and the read-out
effects listed before it) is filtered by the cross kernel ``(1 - 4c) delta + c (4 adjacent)`` of a
charge-conserving coupling, scaled by ``1 / sqrt((1 - 4c)^2 + 4c^2)`` to keep its variance (the
photon-transfer curve the base model was fitted to already contains the coupling). Adjacent pixels'
noise then correlates ``2c(1 - 4c) / ((1 - 4c)^2 + 4c^2)`` in darks and flats alike, where
``charge_crosstalk`` correlates the shot noise of flats only.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from .base import Effect, register_effect


def plane_filter(n: np.ndarray, c: float, stride: int = 2) -> np.ndarray:
    """Variance-preserving separable ``[c, 1, c]`` filter inside each CFA plane of ``n`` (..., H, W).

    Same-colour neighbours are ``stride`` = 2 px apart; ``stride`` = 1 filters the mosaic itself (adjacent,
    different-colour neighbours). Rows/columns beyond the border are reflected about the plane's edge
    pixel (numpy ``reflect`` padding by ``stride`` px).
    """
    c32 = np.float32(c)
    out = np.asarray(n, dtype=np.float32)
    for axis in (-2, -1):
        pad = [(0, 0)] * out.ndim
        pad[axis] = (stride, stride)
        p = np.pad(out, pad, mode="reflect")
        size = out.shape[axis]
        lo = np.take(p, np.arange(0, size), axis=axis)
        hi = np.take(p, np.arange(2 * stride, size + 2 * stride), axis=axis)
        out = out + c32 * (lo + hi)
    return out * np.float32(1.0 / (1.0 + 2.0 * c * c))


@register_effect
class SpatialCorrelation(Effect):
    """Same-colour crosstalk of the read noise with coupling ``coefficient`` (dimensionless, |c| <= 0.5).

    ``coefficient`` c is the weight of each axial same-colour neighbour in the
    separable ``[c, 1, c]`` in-plane kernel (module docstring); the nearest
    same-colour read-noise correlation is ``2 c / (1 + 2 c^2)`` (0.27 for
    c = 0.15) and the per-pixel variance is unchanged. Needs a base with a
    read-noise part (``poisson_gaussian``, ``nlf``, ``gaussian``).
    """

    type: Literal["spatial_correlation"] = "spatial_correlation"
    coefficient: float = Field(ge=-0.5, le=0.5)
    #: ``same_colour``: the in-plane kernel (same-colour neighbours 2 px apart); ``adjacent``: the same kernel on
    #: the mosaic (adjacent, different-colour neighbours correlate 2 c / (1 + 2 c^2), same-colour ones 2 px
    #: apart c^2 / (1 + 2 c^2)), as electrical crosstalk between neighbouring column or row lines gives
    neighbours: Literal["same_colour", "adjacent"] = "same_colour"
    #: ``read``: the read noise is filtered; ``total``: all the noise at read-out (module docstring)
    domain: Literal["read", "total"] = "read"
    needs_read = True

    @model_validator(mode="after")
    def _total_is_adjacent(self):
        if self.domain == "total" and (self.neighbours != "adjacent" or not 0 <= self.coefficient < 0.25):
            raise ValueError(f"domain 'total' couples adjacent pixels with 0 <= coefficient < 0.25; got neighbours "
                             f"{self.neighbours!r}, coefficient {self.coefficient}")
        return self

    def apply(self, x, ctx):
        if self.coefficient == 0:
            return x
        if self.domain == "total":
            c = float(self.coefficient)
            scale = np.float32(1.0 / np.sqrt((1 - 4 * c) ** 2 + 4 * c * c))
            noise = charge_share(x - ctx.signal, c) * scale
            x[...] = ctx.signal + noise
            ctx.read[...] = charge_share(ctx.read, c) * scale
            return x
        f = plane_filter(ctx.read, float(self.coefficient), 2 if self.neighbours == "same_colour" else 1)
        x += f - ctx.read  # x = shot + read -> shot + filtered read
        ctx.read[...] = f
        return x


def charge_share(q: np.ndarray, c: float, diagonal: float = 0.0) -> np.ndarray:
    """Charge-conserving sharing with the 4 adjacent (weight ``c``) and 4 diagonal (``diagonal``) pixels.

    ``out = (1 - 4 c - 4 d) q + c * sum(adjacent q) + d * sum(diagonal q)``; borders reflect.
    """
    q = np.asarray(q, dtype=np.float32)
    p = np.pad(q, [(0, 0)] * (q.ndim - 2) + [(1, 1), (1, 1)], mode="reflect")
    h, w = q.shape[-2:]

    def sh(dy, dx):
        return p[..., 1 + dy:1 + dy + h, 1 + dx:1 + dx + w]

    adj = sh(-1, 0) + sh(1, 0) + sh(0, -1) + sh(0, 1)
    out = np.float32(1.0 - 4.0 * c - 4.0 * diagonal) * q + np.float32(c) * adj
    if diagonal:
        out += np.float32(diagonal) * (sh(-1, -1) + sh(-1, 1) + sh(1, -1) + sh(1, 1))
    return out


@register_effect
class ChargeCrosstalk(Effect):
    """Photo-electrons shared with neighbouring pixels before read-out (charge-domain crosstalk).

    Electrons generated near a pixel's edge diffuse into its neighbours — of the other colours
    on a Bayer mosaic (A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD dissertation,
    York University, 2020, ch. 2, crosstalk). Charge is conserved: the signal *and its shot
    noise* are filtered by ``(1 - 4c - 4d) delta + c (4 adjacent) + d (4 diagonal)`` before the
    read noise is added. So a flat field's mean keeps its level (mixed between the colours), its
    temporal variance drops by ``(1 - 4c - 4d)^2 + 4c^2 + 4d^2`` (the photon-transfer slope
    looks lower than the true gain) and adjacent pixels' noise becomes correlated; dark frames
    (no electrons) are untouched. Acts on ``x - read`` (signal + shot noise, and whatever earlier
    read-out effects added: list it first). Compare ``spatial_correlation``, which couples the
    read noise of same-colour pixels.

    Parameters
    ----------
    coefficient : float
        Share of a pixel's charge going to each adjacent pixel (0 <= c, 4c + 4d < 1).
    diagonal : float
        Share going to each diagonal pixel.
    """

    type: Literal["charge_crosstalk"] = "charge_crosstalk"
    coefficient: float = Field(ge=0, lt=0.25)
    diagonal: float = Field(0.0, ge=0, lt=0.25)
    needs_read = True

    def apply(self, x, ctx):
        if self.coefficient == 0 and self.diagonal == 0:
            return x
        if 4 * (self.coefficient + self.diagonal) >= 1:
            from ...errors import NoiseModelError

            raise NoiseModelError(f"charge_crosstalk: 4 (coefficient + diagonal) = "
                                  f"{4 * (self.coefficient + self.diagonal):g}; expected < 1")
        charge = x - ctx.read
        x[...] = charge_share(charge, float(self.coefficient), float(self.diagonal)) + ctx.read
        return x
