"""Physical noise effects composable with any base model (see :mod:`.base`)."""

from .base import EFFECT_NAMES, Effect, EffectContext, effect_from_entry, effect_types

__all__ = ["EFFECT_NAMES", "Effect", "EffectContext", "effect_from_entry", "effect_types"]
