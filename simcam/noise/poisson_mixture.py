"""``poisson_mixture``: a two-component Poisson scale mixture plus Gaussian read noise (Abdelhamed 2020, eq. 3.12-3.13).

Per pixel a hidden z picks the Poisson scale ``s = beta1 * z`` (``z = z1`` with
probability ``p1``, else ``z2``); ``noisy = s * Poisson(clean / s) + N(0, beta2)``.
The mean stays ``clean`` and the conditional variance is ``s * clean + beta2``
(our reading of Abdelhamed 2020, eq. 3.12, which scales the Poisson count by ``alpha z``,
made mean-preserving as the ``poisson_gaussian`` model is), so
``var = beta1 * (p1 z1 + (1 - p1) z2) * clean + beta2``.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from ..errors import NoiseModelError
from .base import PoissonScaleModel, check_clean, check_same_shape, register_model
from .poisson_gaussian import pg_logcdf, pg_logpdf, pg_sample


@register_model
class PoissonMixture(PoissonScaleModel):
    """Poisson scale mixture (see module docstring).

    Parameters
    ----------
    beta1 : float or 4 floats
        Base gain (normalised raw per photo-electron), > 0.
    beta2 : float or 4 floats
        Gaussian read variance, normalised raw^2, >= 0 (> 0 for ``log_prob``).
    z1, z2 : float
        Scale multipliers of the two components, > 0.
    p1 : float
        Probability of component 1, in [0, 1].
    """

    type: Literal["poisson_mixture"] = "poisson_mixture"
    z1: float = Field(1.0, gt=0)
    z2: float = Field(2.0, gt=0)
    p1: float = Field(0.5, ge=0, le=1)

    def _sample_block(self, clean, cond, rng, row0, out):
        b1, b2 = self._maps(clean.shape, row0)
        pick1 = rng.random(clean.shape, dtype=np.float32) < np.float32(self.p1)
        z = np.where(pick1, np.float32(self.z1), np.float32(self.z2))
        scale = z * b1
        pg_sample(clean, scale, b2, rng, out, where=f"{cond.source or 'clean'}: poisson_mixture")

    def variance(self, clean, cond):
        clean = check_clean(clean)
        b1, b2 = self._maps(clean.shape, 0, np.float64)
        zbar = self.p1 * self.z1 + (1 - self.p1) * self.z2
        return np.broadcast_to(clean.astype(np.float64) * b1 * zbar + b2, clean.shape).astype(np.float64)

    def _flat(self, clean, cond):
        b1, b2 = self._maps(clean.shape, 0, np.float64)
        b1 = np.broadcast_to(b1, clean.shape).astype(np.float64).ravel()
        b2 = np.broadcast_to(b2, clean.shape).astype(np.float64).ravel()
        if (b2 <= 0).any():
            raise NoiseModelError(f"{cond.source or 'model'}: poisson_mixture: log_prob needs beta2 > 0, got {self.beta2!r}")
        return clean.astype(np.float64).ravel(), b1, b2

    def _components(self):
        comps = []
        if self.p1 > 0:
            comps.append((np.log(self.p1), self.z1))
        if self.p1 < 1:
            comps.append((np.log1p(-self.p1), self.z2))
        return comps

    def log_prob(self, noisy, clean, cond):
        clean = check_clean(clean, where=f"{cond.source or 'clean'}")
        self.check_cond(cond, clean.shape)
        x = check_same_shape(noisy, clean).astype(np.float64).ravel()
        c, b1, b2 = self._flat(clean, cond)
        parts = [lw + pg_logpdf(x, c / (b1 * z), b1 * z, b2) for lw, z in self._components()]
        return np.logaddexp.reduce(np.stack(parts), axis=0).reshape(clean.shape)

    def cdf(self, x, clean, cond, *, log: bool = False, upper: bool = False):
        clean = check_clean(clean)
        xs = np.broadcast_to(np.asarray(x, dtype=np.float64), clean.shape).ravel()
        c, b1, b2 = self._flat(clean, cond)
        parts = [lw + pg_logcdf(xs, c / (b1 * z), b1 * z, b2, upper=upper) for lw, z in self._components()]
        lc = np.logaddexp.reduce(np.stack(parts), axis=0).reshape(clean.shape)
        return lc if log else np.exp(lc)
