"""``adc_dnl``: an analogue-to-digital converter whose codes have unequal widths.

A real ADC's transition levels sit off their ideal places: code *k* spans
``[k - 1/2 + u_k, k + 1/2 + u_{k+1})`` in DN instead of ``[k - 1/2, k + 1/2)``. The
differential non-linearity of code *k* is its width minus one LSB, ``DNL_k = u_{k+1} - u_k``;
the integral non-linearity is ``u_k`` itself (bounded here: the offsets are drawn independently,
so INL does not wander). Histograms of dark or flat frames then show codes that are too
frequent (wide) or too rare (narrow) — "missing codes" in the extreme. The transition offsets
``u_k ~ N(0, dnl_sigma^2)`` LSB are drawn once per sensor (sorted, so codes never overlap).
Reference: A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD dissertation, York
University, 2020, ch. 2 (quantisation noise); IEEE Std 1241-2010, sec. 4.1.3 (DNL, INL).

It is the capture's ADC: the output is the code, back in normalised raw. A coarse ADC (codes
``step_dn`` DN apart: an ADC of fewer bits scaled to the range, or low bits dropped) has unequal codes
too: its transition levels sit off by fractions of its own code, ``step_dn`` DN wide. Beside a
``quantization`` of the same step, list ``adc_dnl`` first: its codes are on the quantiser's grid, which
then leaves them as they are.

Measured transition levels (``edges_dn``, DN) replace the drawn offsets of the transitions nearest
them: a calibration that located some of this sensor's transitions (``simcam loop``: the one dark
frames straddle, when they sit on two codes of a coarse ADC) keeps them, the others stay random.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from .base import Effect, register_effect


@register_effect
class AdcDnl(Effect):
    """ADC with unequal code widths (differential non-linearity).

    Parameters
    ----------
    range_dn : float
        white - black in DN (normalised raw 1.0).
    offset_dn : float
        The black level in DN (the code of normalised 0).
    bits : int
        ADC resolution: codes 0 .. 2^bits - 1.
    dnl_sigma : float
        Standard deviation of the transition offsets, LSB (DNL std is sqrt(2) times it).
    step_dn : float
        Width of one code in DN (1: codes are DN; a coarse ADC's code is ``step_dn`` DN, its output
        ``code * step_dn`` DN).
    edges_dn : list of float
        Measured transition levels (DN), each replacing the drawn offset of the nearest transition
        (transition k, between codes k and k + 1, ideally at ``(k + 1/2) step_dn``).
    """

    type: Literal["adc_dnl"] = "adc_dnl"
    stack_ok = True
    range_dn: float = Field(gt=0)
    offset_dn: float = 0.0
    bits: int = Field(12, ge=1, le=20)
    dnl_sigma: float = Field(0.2, ge=0, le=2.0)
    step_dn: float = Field(1.0, ge=1.0)
    edges_dn: list[float] = Field(default_factory=list)

    def fixed(self, shape, rng):
        n = 2 ** int(self.bits)
        u = self.dnl_sigma * rng.standard_normal(n - 1)
        for e in self.edges_dn:  # in codes: transition k (between codes k and k + 1) ideally at k + 1/2
            k = int(np.floor(float(e) / self.step_dn))
            if 0 <= k < n - 1:
                u[k] = float(e) / self.step_dn - (k + 0.5)
        return {"edges": np.sort(np.arange(n - 1) + 0.5 + u)}

    def codes(self, x: np.ndarray, edges: np.ndarray) -> np.ndarray:
        """ADC codes of normalised raw ``x`` (in codes: ``code * step_dn`` is the DN)."""
        analog = (x.astype(np.float64) * self.range_dn + self.offset_dn) / self.step_dn
        return np.searchsorted(edges, analog, side="right")

    def apply(self, x, ctx):
        code = self.codes(x, ctx.fixed["edges"])
        return ((code * self.step_dn - self.offset_dn) / self.range_dn).astype(np.float32)
