"""Physical noise effects composable with any base model (see :mod:`.base`)."""

from .base import EFFECT_NAMES, Effect, EffectContext, effect_from_entry, effect_types

__all__ = ["EFFECT_NAMES", "Effect", "EffectContext", "effect_from_entry", "effect_types"]

# The registry: importing each implementation registers it under its ``type``.
from . import adc, correlation, dark, defects, empirical, fixed_pattern, response, temporal  # noqa: E402,F401
