"""``nlf``: heteroscedastic Gaussian noise, the noise level function (Abdelhamed 2020, eq. 3.7-3.8, 5.2)."""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import field_validator

from .base import SiteParam, register_model, site_map, validate_site_param
from .gaussian import GaussianFamily
from .kernels.vectorised import _W


@register_model
class NLF(GaussianFamily):
    """``noisy = clean + N(0, beta1 * clean + beta2)`` on normalised raw.

    Parameters
    ----------
    beta1 : float or 4 floats
        Signal-dependent (shot) term, normalised raw units (= 1 / electrons at
        full scale, times the gain); per CFA site or for all; >= 0.
    beta2 : float or 4 floats
        Signal-independent (read) variance, normalised raw^2; >= 0.

    These are the (S, O) pairs of the DNG NoiseProfile tag (DNG 1.6 spec,
    tag 51041). Reference: Abdelhamed 2020, eq. 3.8.
    """

    type: Literal["nlf"] = "nlf"
    beta1: SiteParam
    beta2: SiteParam

    @field_validator("beta1", "beta2")
    @classmethod
    def _chk(cls, v, info):
        return validate_site_param(v, info.field_name)

    def read_split(self):
        return self.model_copy(update={"beta2": 0.0}), self.beta2

    def _var_map(self, clean, row0, dtype=np.float32):
        b1 = site_map(self.beta1, clean.shape, row0, name="beta1", dtype=dtype)
        b2 = site_map(self.beta2, clean.shape, row0, name="beta2", dtype=dtype)
        var = _W.get("nlf_var", clean.size, dtype).reshape(clean.shape) if dtype == np.float32 else np.empty(clean.shape, dtype)
        np.multiply(clean, b1, out=var)
        var += b2
        return var
