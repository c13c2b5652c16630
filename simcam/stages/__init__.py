"""Built-in pipeline stages. Importing this package registers every stage module in it."""

from __future__ import annotations

import importlib
import pkgutil

from .base import Stage, StageParams, get_stage_class, register_stage, stage_types

for _mod in pkgutil.iter_modules(__path__):
    if _mod.name != "base" and not _mod.name.startswith("_"):
        importlib.import_module(f"{__name__}.{_mod.name}")

__all__ = ["Stage", "StageParams", "register_stage", "get_stage_class", "stage_types"]
