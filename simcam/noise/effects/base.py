"""Effect contract and registry.

An effect is a pydantic model (its profile entry) with a ``stage``:

``"signal"``
    acts on the expected signal before the base noise model (PRNU, channel
    gain, frame flicker);
``"readout"``
    acts on the noisy value after the base model, in list order (crosstalk,
    heavy-tailed read noise, row/periodic noise, the sensor/ADC response
    ``nonlinearity``, offsets, defects, quantization).

Randomness comes in two kinds. ``fixed(shape, rng)`` draws the *fixed pattern*
(the same for every frame of one sensor): the composite model gives it a
generator seeded by ``SeedSequence([sensor_seed, crc32(type), occurrence])``.
``frame(shape, rng)`` draws per-frame quantities (row offsets, flicker gain)
from the frame key. Per-pixel, per-frame randomness (heavy-tailed read noise)
draws row block by row block (``ctx.block_rng(b)``), so it is independent of
tiling, like the base models.

``logprob_role`` says how ``log_prob`` of a composite sees the effect:
``"signal"`` (a deterministic transform of the signal, given the fixed
pattern), ``"offset"`` (a deterministic additive offset), ``"response"`` (a
monotonic map of the noisy value with ``inverse`` and ``log_slope``: change
of variables), or ``None`` (the effect makes the likelihood intractable: the
composite refuses).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar, Literal

import numpy as np

from ...errors import NoiseModelError
from ...registry import Registry
from ..base import BLOCK_ROWS, ProfileEntryModel, block_rng, from_registry, site_map, site_values

EFFECT_NAMES = ("row_noise", "column_fpn", "dsnu", "prnu", "hot_pixels", "heavy_tail_read", "quantization",
                "spatial_correlation", "periodic_pattern", "black_level_offset", "frame_flicker", "nonlinearity",
                "channel_gain", "dark_current", "amp_glow", "dead_pixels", "adc_dnl", "rtn", "charge_crosstalk",
                "empirical_offset", "empirical_gain", "empirical_lines", "empirical_spectrum", "empirical_code",
                "empirical_field", "empirical_response")

_EFFECTS = Registry("effect type")


@dataclass
class EffectContext:
    """What an effect sees when applied to one frame.

    Parameters
    ----------
    cfa : str or None
        Bayer pattern of the frame.
    key : ndarray or None
        The frame key of per-frame draws (None in ``log_prob``).
    stream : int
        Separates this effect's row-block streams from the base model's.
    fixed, frame : dict
        What :meth:`Effect.fixed` and :meth:`Effect.frame` drew.
    signal, read : ndarray or None
        Expected signal after the signal-stage effects; read noise so far (when needed).
    exposure_s : float or None
        Exposure time of the frame, seconds.

    Attributes
    ----------
    cfa, key, stream, fixed, frame, signal, read, exposure_s
        As the parameters; :meth:`block_rng` gives the generator of a row block.

    Examples
    --------
    >>> ctx = EffectContext(cfa="RGGB", key=None, stream=1)
    >>> ctx.fixed, ctx.exposure_s
    ({}, None)
    """

    cfa: str | None
    key: np.ndarray | None  # frame key (None in log_prob: per-frame draws unavailable)
    stream: int  # separates this effect's block streams from the base model's
    fixed: dict[str, Any] = field(default_factory=dict)
    frame: dict[str, Any] = field(default_factory=dict)
    signal: np.ndarray | None = None  # expected signal after the signal-stage effects
    #: read noise of this frame so far (the base model's signal-independent Gaussian part plus
    #: heavy-tailed read noise), when an effect of the composite ``needs_read``; else None.
    read: np.ndarray | None = None
    #: exposure time of the frame, seconds (exposure-dependent effects: dark_current, amp_glow)
    exposure_s: float | None = None

    def block_rng(self, block: int) -> np.random.Generator:
        if self.key is None:
            raise NoiseModelError("effect needs per-frame randomness but no frame key was given")
        return block_rng(self.key, block, stream=self.stream)


class Effect(ProfileEntryModel):
    """Base class of effects (see module docstring).

    Parameters
    ----------
    type : str
        The effect's name, one of :data:`EFFECT_NAMES` (subclasses fix it as a ``Literal`` default).
    **params
        The effect's own fields (pydantic, ``extra="forbid"``, frozen): its profile entry.

    Attributes
    ----------
    stage : {"signal", "readout"}
        Where it acts: on the expected signal, or on the noisy value after the base model.
    logprob_role : str or None
        How a composite's ``log_prob`` treats it (module docstring).

    Examples
    --------
    >>> import numpy as np
    >>> import simcam.noise
    >>> fpn = effect_from_entry({"type": "column_fpn", "sigma": 0.01})
    >>> fpn.stage, fpn.to_entry()["sigma"]
    ('readout', 0.01)
    """

    stage: ClassVar[Literal["signal", "readout"]] = "readout"
    logprob_role: ClassVar[str | None] = None
    #: True for effects acting on the read noise alone (the composite then samples it apart).
    needs_read: ClassVar[bool] = False
    #: True when ``apply`` is elementwise or broadcasts a fixed (H, W) map, needs no per-frame
    #: draw, and so may be given a whole (n, H, W) stack at once (``Composite.sample_frames``).
    stack_ok: ClassVar[bool] = False

    @classmethod
    def from_entry(cls, entry: dict[str, Any], *, where: str = "effect") -> "Effect":
        return effect_from_entry(entry, where=where)

    def fixed(self, shape: tuple[int, int], rng: np.random.Generator) -> dict[str, Any]:
        """Fixed-pattern draw (sensor seed); empty for effects without one."""
        return {}

    def frame(self, shape: tuple[int, int], rng: np.random.Generator) -> dict[str, Any]:
        """Per-frame draw; empty for effects without one."""
        return {}

    def apply(self, x: np.ndarray, ctx: EffectContext) -> np.ndarray:
        """Return the transformed float32 array (may work in place on ``x``)."""
        raise NotImplementedError

    def role(self) -> str | None:
        """How a composite's ``log_prob`` treats this effect (see module docstring)."""
        return self.logprob_role

    def sensor_stream(self) -> int:
        return zlib.crc32(self.type.encode())


def register_effect(cls: type[Effect]) -> type[Effect]:
    key = cls.model_fields["type"].default
    if key not in EFFECT_NAMES:
        raise TypeError(f"effect {key!r} is not one of the documented names {EFFECT_NAMES}")
    _EFFECTS[key] = cls
    return cls


def effect_types() -> dict[str, type[Effect]]:
    """All registered effect classes by ``type`` name (:mod:`simcam.noise` registers them).

    Returns
    -------
    dict of str to type
        A copy of the registry: ``{name: Effect subclass}``.

    Examples
    --------
    >>> import simcam.noise
    >>> sorted(effect_types())[:3]
    ['adc_dnl', 'amp_glow', 'black_level_offset']
    """
    return _EFFECTS.types()


def effect_from_entry(entry: Any, *, where: str = "effect") -> Effect:
    """Build an effect from its profile entry ``{type: ..., **params}`` or raise NoiseModelError.

    Parameters
    ----------
    entry : dict or Effect
        An entry of a composite model's ``effects:`` list (an effect is returned as is).
    where : str
        Location named in the error message.

    Returns
    -------
    Effect
        An instance of the class registered under ``entry["type"]``.

    Examples
    --------
    >>> import simcam.noise
    >>> effect_from_entry({"type": "row_noise", "sigma": 0.002}).sigma
    0.002
    >>> effect_from_entry({"type": "blur"}, where="profile.yaml: effects[0]")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    simcam.errors.NoiseModelError: profile.yaml: effects[0]...
    """
    return from_registry(entry, _EFFECTS, base=Effect, noun="effect", expected=list(EFFECT_NAMES), where=where)


def per_block(x: np.ndarray, ctx: EffectContext, fn: Callable[[np.ndarray, np.random.Generator], None]) -> None:
    """Call ``fn(rows_view, rng)`` on each BLOCK_ROWS row block of ``x`` (full frame, row 0 first)."""
    for r in range(0, x.shape[0], BLOCK_ROWS):
        fn(x[r:r + BLOCK_ROWS], ctx.block_rng(r // BLOCK_ROWS))


def site_array(value, shape, *, name: str) -> np.ndarray | np.floating:
    """Per-site parameter map for a full frame (row 0 = CFA row 0)."""
    return site_map(value, shape, 0, name=name)


__all__ = ["Effect", "EffectContext", "EFFECT_NAMES", "register_effect", "effect_types", "effect_from_entry",
           "per_block", "site_array", "site_values"]
