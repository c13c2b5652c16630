"""Stage contract and registry.

A stage is a small class with a pydantic ``Params`` model (``extra="forbid"``,
strict types) that *is* its YAML node, class attributes naming the signal kinds
it accepts and produces, and a deterministic ``apply``. Stages that draw random
numbers set ``random = True`` and implement ``sample(rng, frame) -> dict``; the
pipeline passes what was drawn to ``apply(frame, drawn)``.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict

from ..errors import PipelineError, StageError
from ..frame import RawFrame

_REGISTRY: dict[str, type["Stage"]] = {}


class StageParams(BaseModel):
    """Base of every stage's parameters: unknown keys and loose types are errors."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


class Stage:
    """Base class of pipeline stages (see module docstring)."""

    type: ClassVar[str]
    accepts: ClassVar[frozenset[str]]
    produces: ClassVar[str | None] = None  # None: same kind as the input
    random: ClassVar[bool] = False
    Params: ClassVar[type[StageParams]] = StageParams

    def __init__(self, params: StageParams | None = None, **kwargs: Any):
        if params is None:
            params = self.Params.model_validate_json(_to_json(kwargs))
        elif kwargs:
            raise TypeError("pass either a Params object or keyword parameters, not both")
        self.params = params

    # -- contract ----------------------------------------------------------
    def output_kind(self, kind: str) -> str:
        return self.produces or kind

    def check_input(self, frame: RawFrame) -> None:
        if frame.kind not in self.accepts:
            raise StageError(
                f"stage {self.type!r}: expected a frame of kind {sorted(self.accepts)}, got {frame.kind!r}"
            )

    def sample(self, rng: np.random.Generator, frame: RawFrame) -> dict[str, Any]:
        """Draw this stage's random parameters (random stages only)."""
        return {}

    def apply(self, frame: RawFrame, drawn: dict[str, Any] | None = None) -> RawFrame:
        raise NotImplementedError

    def __call__(self, frame: RawFrame, rng: np.random.Generator | None = None) -> RawFrame:
        self.check_input(frame)
        drawn = None
        if self.random:
            if rng is None:
                raise StageError(f"stage {self.type!r} is random: pass rng= (np.random.Generator)")
            drawn = self.sample(rng, frame)
        return self.apply(frame, drawn)

    # -- serialisation -------------------------------------------------------
    def to_node(self) -> dict[str, Any]:
        return {"type": self.type, **self.params.model_dump(mode="json", exclude_defaults=True)}

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params.model_dump(exclude_defaults=True).items())
        return f"{type(self).__name__}({args})"


def register_stage(cls: type[Stage]) -> type[Stage]:
    """Class decorator: register a stage under its stable ``type`` key."""
    key = getattr(cls, "type", None)
    if not key or not isinstance(key, str):
        raise TypeError(f"{cls.__name__} needs a string class attribute 'type'")
    if key in _REGISTRY and _REGISTRY[key] is not cls:
        raise TypeError(f"stage type {key!r} registered twice ({_REGISTRY[key].__name__}, {cls.__name__})")
    _REGISTRY[key] = cls
    return cls


def stage_types() -> dict[str, type[Stage]]:
    """All registered stage classes by ``type`` key."""
    return dict(_REGISTRY)


def get_stage_class(key: str, *, where: str = "type") -> type[Stage]:
    try:
        return _REGISTRY[key]
    except KeyError:
        raise PipelineError(
            f"{where}: unknown stage {key!r}; expected one of {', '.join(sorted(_REGISTRY))}"
        ) from None


def _to_json(obj: Any) -> str:
    import json

    return json.dumps(obj, default=lambda o: o.tolist() if isinstance(o, np.ndarray) else str(o))
