"""``spatial_correlation``: crosstalk of the read noise between same-colour neighbours (inside each CFA plane).

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
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from .base import Effect, register_effect


def plane_filter(n: np.ndarray, c: float) -> np.ndarray:
    """Variance-preserving separable ``[c, 1, c]`` filter inside each CFA plane of ``n`` (..., H, W).

    Same-colour neighbours are 2 px apart; rows/columns beyond the border are
    reflected about the plane's edge pixel (numpy ``reflect`` padding by 2 px).
    """
    c32 = np.float32(c)
    out = np.asarray(n, dtype=np.float32)
    for axis in (-2, -1):
        pad = [(0, 0)] * out.ndim
        pad[axis] = (2, 2)
        p = np.pad(out, pad, mode="reflect")
        size = out.shape[axis]
        lo = np.take(p, np.arange(0, size), axis=axis)
        hi = np.take(p, np.arange(4, size + 4), axis=axis)
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
    needs_read = True

    def apply(self, x, ctx):
        if self.coefficient == 0:
            return x
        f = plane_filter(ctx.read, float(self.coefficient))
        x += f - ctx.read  # x = shot + read -> shot + filtered read
        ctx.read[...] = f
        return x
