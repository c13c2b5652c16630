"""Empirical components: what a calibration measured but no named effect describes.

When a significant residual matches no effect of the vocabulary, the calibration loop can add
an *empirical* component fitted from the data itself (A. Abdelhamed, *Noise Modelling for
Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 3: noise models fitted to
measured statistics): the measured map, the measured distribution, the measured code table, the
measured field. Each is usable by the noise stage and in profiles like a named effect. Maps are
``FILE.npz#KEY`` references (:mod:`simcam.noise.maps`); distributions are quantile tables
sampled by inverse transform (``np.interp`` of uniform draws on the quantiles at equal
probabilities).

* ``empirical_offset`` — an additive offset along ``axis`` (pixel, row, column, frame), fixed
  (a map, or a per-sensor draw from ``quantiles``) or temporal (a fresh draw every frame);
* ``empirical_gain`` — a multiplicative fixed pattern of the expected signal (pixel, row,
  column): a measured PRNU-like map or gain distribution;
* ``empirical_lines`` — a fixed additive pattern along rows or columns given by its measured
  spectral lines (frequency, amplitude), phases drawn once per sensor;
* ``empirical_code`` — the ADC's measured transition levels (DN): the code of each value;
* ``empirical_field`` — a smooth measured dark field in normalised raw per second (glow-like),
  with its Poisson shot noise through ``electron``.
"""

from __future__ import annotations

from typing import Literal, Optional

import numpy as np
from pydantic import Field, model_validator

from ...errors import NoiseModelError
from ..maps import fit_to, load_map
from .base import Effect, register_effect
from .dark import _add_poisson_electrons, exposure_of


def draw_quantiles(quantiles, size, rng: np.random.Generator) -> np.ndarray:
    """``size`` draws from the law whose quantiles at probabilities linspace(0, 1, n) are ``quantiles``."""
    q = np.asarray(quantiles, dtype=np.float64)
    return np.interp(rng.random(size), np.linspace(0.0, 1.0, q.size), q)


class _MapOrQuantiles(Effect):
    map: Optional[str] = None
    quantiles: Optional[list[float]] = None
    scale: float = 1.0

    @model_validator(mode="after")
    def _one(self):
        if (self.map is None) == (self.quantiles is None):
            raise ValueError("give exactly one of map (FILE.npz#KEY) or quantiles (a measured distribution)")
        if self.quantiles is not None:
            if len(self.quantiles) < 2 or any(b < a for a, b in zip(self.quantiles, self.quantiles[1:])):
                raise ValueError("quantiles: expected at least 2 non-decreasing values")
        return self

    def _pattern(self, shape, rng, axis) -> np.ndarray:
        if self.map is not None:
            return self.scale * fit_to(load_map(self.map), shape, axis, where=f"effect {self.type!r}")
        n = {"pixel": shape, "row": (shape[0], 1), "column": (1, shape[1])}[axis]
        return (self.scale * draw_quantiles(self.quantiles, n, rng)).astype(np.float32)


@register_effect
class EmpiricalOffset(_MapOrQuantiles):
    """Measured additive offset (normalised raw) along ``axis``; ``temporal``: a fresh draw each frame."""

    type: Literal["empirical_offset"] = "empirical_offset"
    axis: Literal["pixel", "row", "column", "frame"] = "pixel"
    temporal: bool = False

    @model_validator(mode="after")
    def _axis(self):
        if self.axis == "frame" and not self.temporal:
            raise ValueError("axis: frame needs temporal: true (a fixed frame offset is a black-level offset)")
        if self.temporal and self.map is not None:
            raise ValueError("temporal: a per-frame draw needs quantiles, not a map")
        return self

    def fixed(self, shape, rng):
        return {} if self.temporal else {"offset": self._pattern(shape, rng, self.axis)}

    def frame(self, shape, rng):
        if not self.temporal:
            return {}
        n = {"pixel": shape, "row": (shape[0], 1), "column": (1, shape[1]), "frame": (1, 1)}[self.axis]
        return {"offset": (self.scale * draw_quantiles(self.quantiles, n, rng)).astype(np.float32)}

    def apply(self, x, ctx):
        off = ctx.frame["offset"] if self.temporal else ctx.fixed["offset"]
        x += off[: x.shape[0], : x.shape[1]]  # (H, W), (H, 1), (1, W) or (1, 1)
        return x


@register_effect
class EmpiricalGain(_MapOrQuantiles):
    """Measured multiplicative fixed pattern of the expected signal (values around 1) along ``axis``."""

    type: Literal["empirical_gain"] = "empirical_gain"
    stage = "signal"
    logprob_role = "signal"
    axis: Literal["pixel", "row", "column"] = "pixel"

    def fixed(self, shape, rng):
        return {"gain": self._pattern(shape, rng, self.axis)}

    def apply(self, x, ctx):
        return (x * ctx.fixed["gain"][: x.shape[0], : x.shape[1]]).astype(np.float32)


@register_effect
class EmpiricalLines(Effect):
    """A measured fixed additive pattern along ``axis`` given by its spectral lines: line index ``i``
    (the column for ``axis: column``) gets ``sum_j a_j cos(2 pi f_j i + phi_j)`` (normalised raw), the
    phases ``phi_j`` uniform on [0, 2 pi) and drawn once per sensor. Each line adds ``a_j^2 / 2`` to the
    variance of the line offsets and keeps its frequency whatever the frame's size (a Fourier
    surrogate: measured amplitudes, random phases; J. Theiler et al., "Testing for nonlinearity in time
    series: the method of surrogate data", Physica D 58, 1992)."""

    type: Literal["empirical_lines"] = "empirical_lines"
    axis: Literal["row", "column"] = "column"
    lines: list[tuple[float, float]] = Field(min_length=1)
    stack_ok = True
    logprob_role = "offset"

    @model_validator(mode="after")
    def _lines(self):
        for f, a in self.lines:
            if not (0.0 <= f <= 0.5) or not a >= 0.0:
                raise ValueError(f"lines: ({f}, {a}): expected (frequency in cycles per pixel in [0, 0.5], "
                                 "amplitude >= 0)")
        return self

    def fixed(self, shape, rng):
        n = shape[0] if self.axis == "row" else shape[1]
        i = np.arange(n, dtype=np.float64)
        out = np.zeros(n)
        for f, a in self.lines:
            out += a * np.cos(2 * np.pi * f * i + rng.uniform(0.0, 2 * np.pi))
        out = out.astype(np.float32)
        return {"offset": out[:, None] if self.axis == "row" else out[None, :]}

    def apply(self, x, ctx):
        x += ctx.fixed["offset"][: x.shape[-2], : x.shape[-1]]
        return x


@register_effect
class EmpiricalCode(Effect):
    """The ADC's measured transition levels: ``edges[k]`` (DN) is where code k + ``first_code`` + 1 starts."""

    type: Literal["empirical_code"] = "empirical_code"
    stack_ok = True
    range_dn: float = Field(gt=0)
    offset_dn: float = 0.0
    edges: str | list[float]
    first_code: int = 0

    def fixed(self, shape, rng):
        e = np.asarray(load_map(self.edges) if isinstance(self.edges, str) else self.edges, dtype=np.float64)
        if e.ndim != 1 or e.size < 1 or np.any(np.diff(e) < 0):
            raise NoiseModelError(f"effect {self.type!r}: edges: expected increasing transition levels (DN)")
        return {"edges": e}

    def apply(self, x, ctx):
        analog = x.astype(np.float64) * self.range_dn + self.offset_dn
        code = np.searchsorted(ctx.fixed["edges"], analog, side="right") + self.first_code
        return ((code - self.offset_dn) / self.range_dn).astype(np.float32)


@register_effect
class EmpiricalField(Effect):
    """A measured smooth dark field (normalised raw per second, a low-resolution grid upsampled bilinearly),
    accumulating over the exposure with its Poisson shot noise (``electron``: normalised raw per electron)."""

    type: Literal["empirical_field"] = "empirical_field"
    field: str | list[list[float]]
    electron: float = Field(gt=0)

    def fixed(self, shape, rng):
        from scipy.ndimage import zoom

        g = np.asarray(load_map(self.field) if isinstance(self.field, str) else self.field, dtype=np.float64)
        if g.ndim != 2 or (g < 0).any():
            raise NoiseModelError(f"effect {self.type!r}: field: expected a 2-D grid of rates >= 0")
        full = zoom(g, (shape[0] / g.shape[0], shape[1] / g.shape[1]), order=1, mode="nearest", grid_mode=True)
        return {"rate": full[: shape[0], : shape[1]]}

    def apply(self, x, ctx):
        t = exposure_of(ctx, self.type)
        if t == 0:
            return x
        _add_poisson_electrons(x, ctx.fixed["rate"][: x.shape[0], : x.shape[1]] * t / self.electron, self.electron,
                               ctx)
        return x
