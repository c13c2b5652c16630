"""Deterministic response effects: ``channel_gain``, ``nonlinearity``, ``quantization``."""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, field_validator

from ..base import SiteParam, validate_positive_site_param
from .base import Effect, register_effect, site_array


@register_effect
class ChannelGain(Effect):
    """Per-CFA-site gain on the signal (dimensionless, > 0), e.g. a per-channel analog gain error."""

    type: Literal["channel_gain"] = "channel_gain"
    gain: SiteParam
    stage = "signal"
    logprob_role = "signal"

    @field_validator("gain")
    @classmethod
    def _chk(cls, v):
        return validate_positive_site_param(v, "gain")

    def apply(self, x, ctx):
        x *= site_array(self.gain, x.shape, name="gain")
        return x


@register_effect
class Nonlinearity(Effect):
    """Compressive sensor / ADC response on the *noisy* value: ``y = x - strength * x^2``.

    Physics. The charge-to-voltage conversion and the ADC of a real sensor
    respond non-linearly to the charge actually collected, shot noise
    included, and to the read noise added before them; so the response acts on
    the noisy value ``x`` (normalised raw above black: the base model's sample
    plus every readout effect listed *before* it), not on the expected signal.
    By the delta method the noise is then scaled by the local slope,
    ``var(y) ~= (1 - 2 strength mean)^2 var(x)``: the photon-transfer curve
    (variance against mean) bends, which is what EMVA 1288 R4.0 sec. 6.6 and the
    calibration loop's ``ptc_curvature`` diagnostic measure. Put it after the
    temporal readout effects (crosstalk, heavy-tailed read, row and periodic
    noise) and before fixed offsets (DSNU, column FPN, black-level offset) and
    quantization, which come after the response in the signal chain.

    Units. ``x`` and ``y`` in normalised raw (0 = black, 1 = white - black);
    ``strength`` dimensionless: slope 1 at black, full scale compressed to
    ``1 - strength`` at x = 1 (a 2 % compression at white is ``strength: 0.02``).
    Negative values give an expansive response. Monotonic for
    ``x < 1 / (2 strength)``, i.e. beyond 1.1 for every allowed ``strength``
    (|strength| <= 0.45).
    """

    type: Literal["nonlinearity"] = "nonlinearity"
    strength: float = Field(ge=-0.45, le=0.45)
    stage = "readout"
    logprob_role = "response"
    stack_ok = True

    def apply(self, x, ctx):
        x -= np.float32(self.strength) * x * x
        return x

    def inverse(self, y: np.ndarray, fixed: dict | None = None) -> np.ndarray:
        """``x`` with ``apply(x) = y`` on the monotonic branch (float64); ``fixed`` (its fixed-pattern draw,
        empty) is taken for the composite's sake (``empirical_response`` reads its map from it)."""
        y = np.asarray(y, dtype=np.float64)
        s = float(self.strength)
        if s == 0:
            return y
        disc = np.maximum(1.0 - 4.0 * s * y, 0.0)
        return 2.0 * y / (1.0 + np.sqrt(disc))  # = (1 - sqrt(disc)) / (2 s), stable at s -> 0

    def log_slope(self, x: np.ndarray, fixed: dict | None = None) -> np.ndarray:
        """``log |dy/dx|`` at ``x`` (float64), the Jacobian term of ``log_prob``."""
        return np.log(np.abs(1.0 - 2.0 * float(self.strength) * np.asarray(x, dtype=np.float64)))


@register_effect
class Quantization(Effect):
    """ADC quantisation: ``DN = round((x * range_dn + offset_dn) / step_dn) * step_dn``, back to normalised raw.

    ``range_dn`` is white - black in DN, ``offset_dn`` the black level (DN;
    only its fractional part relative to ``step_dn`` matters), ``step_dn`` the
    ADC step in DN (1 for a plain ADC; > 1 models dropped low bits).
    """

    type: Literal["quantization"] = "quantization"
    stack_ok = True
    range_dn: float = Field(gt=0)
    step_dn: float = Field(1.0, gt=0)
    offset_dn: float = 0.0

    def apply(self, x, ctx):
        s = np.float64(self.step_dn)
        dn = np.round((x.astype(np.float64) * self.range_dn + self.offset_dn) / s) * s
        return ((dn - self.offset_dn) / self.range_dn).astype(np.float32)
