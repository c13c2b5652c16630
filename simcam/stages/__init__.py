"""Built-in pipeline stages, one module each, imported when a pipeline first names one of their types
(:data:`simcam.stages.base.BUILTIN_STAGES`; :func:`stage_types` imports them all)."""

from __future__ import annotations

from .base import BUILTIN_STAGES, Stage, StageParams, get_stage_class, register_stage, stage_types

__all__ = ["BUILTIN_STAGES", "Stage", "StageParams", "register_stage", "get_stage_class", "stage_types"]
