"""Gaussian-family models: ``gaussian`` (AWGN) and the shared machinery of ``nlf``.

Both are ``noisy = clean + sd * z``, z ~ N(0, 1) drawn with :func:`kernels.normal_f32`.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import field_validator

from ..errors import NoiseModelError
from .base import (NoiseCondition, NoiseModel, SiteParam, check_clean, check_same_shape, register_model, site_map, site_values,
                   validate_site_param)
from .kernels.vectorised import normal_f32

_LOG_SQRT_2PI = 0.5 * np.log(2.0 * np.pi)


class GaussianFamily(NoiseModel):
    """Base of models whose noise is N(0, var(clean)) per pixel."""

    def _var_map(self, clean: np.ndarray, row0: int, dtype=np.float32) -> np.ndarray:
        raise NotImplementedError

    def _sample_block(self, clean, cond, rng, row0, out):
        sd = self._var_map(clean, row0)
        np.sqrt(sd, out=sd)
        normal_f32(rng, clean.size, out=out)
        out *= sd
        out += clean

    def variance(self, clean, cond: NoiseCondition) -> np.ndarray:
        clean = check_clean(clean)
        return np.broadcast_to(self._var_map(clean.astype(np.float64), 0, np.float64), clean.shape).copy()

    def _sd64(self, clean: np.ndarray, cond: NoiseCondition) -> np.ndarray:
        var = np.broadcast_to(self._var_map(clean.astype(np.float64), 0, np.float64), clean.shape)
        if (var <= 0).any():
            raise NoiseModelError(
                f"{cond.source or 'clean'}: model {self.type!r}: log_prob needs a positive variance, got 0 at "
                f"{int((var <= 0).sum())} pixel(s)")
        return np.sqrt(var)

    def log_prob(self, noisy, clean, cond: NoiseCondition) -> np.ndarray:
        """log N(noisy; clean, var(clean)) per pixel (nats)."""
        clean = check_clean(clean, where=f"{cond.source or 'clean'}")
        self.check_cond(cond, clean.shape)
        x = check_same_shape(noisy, clean).astype(np.float64)
        sd = self._sd64(clean, cond)
        r = (x - clean) / sd
        return -0.5 * r * r - np.log(sd) - _LOG_SQRT_2PI

    def cdf(self, x, clean, cond: NoiseCondition, *, log: bool = False, upper: bool = False) -> np.ndarray:
        """P(noisy <= x) (or P(noisy > x) with ``upper``), optionally as a log."""
        clean = check_clean(clean)
        sd = self._sd64(clean, cond)
        r = (np.asarray(x, dtype=np.float64) - clean) / sd
        if upper:
            r = -r
        from scipy.special import log_ndtr, ndtr

        return log_ndtr(r) if log else ndtr(r)


@register_model
class Gaussian(GaussianFamily):
    """Additive white Gaussian noise: ``noisy = clean + N(0, sigma^2)``.

    Parameters
    ----------
    sigma : float or 4 floats
        Standard deviation, normalised raw units, per CFA site or for all; >= 0.
    """

    type: Literal["gaussian"] = "gaussian"
    sigma: SiteParam

    @field_validator("sigma")
    @classmethod
    def _chk(cls, v):
        return validate_site_param(v, "sigma")

    def read_split(self):
        s = site_values(self.sigma, name="sigma")
        return self.model_copy(update={"sigma": 0.0}), [float(v * v) for v in s]

    def _var_map(self, clean, row0, dtype=np.float32):
        s = site_map(self.sigma, clean.shape, row0, name="sigma", dtype=dtype)
        return np.broadcast_to(s * s, clean.shape).astype(dtype)
