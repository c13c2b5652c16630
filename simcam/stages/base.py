"""Stage contract and registry.

A stage is a small class with a pydantic ``Params`` model (``extra="forbid"``,
strict types) that *is* its YAML node, class keywords naming its ``type`` and the
signal kinds it accepts and produces (``class Gamma(Stage, type="gamma", accepts=...,
produces=...)``), checks of its parameters beyond their types (``check_params``) and
a deterministic ``apply``. Stages that draw random numbers declare ``random=True`` and
implement ``sample(rng, frame) -> dict``; the pipeline passes what was drawn to
``apply(frame, drawn)``. A stage whose output row depends only on the same input row (a
per-pixel or per-site map, e.g. ``normalize``, ``white_balance`` with known gains, ``clip``)
may also describe that map as a :class:`RowOp` (``row_op(frame)``), so that the pipeline can run
several such stages on bands of rows in one buffer (:mod:`simcam.row_fusion`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict

from ..errors import PipelineError, StageError
from ..frame import RawFrame
from ..registry import Registry

_REGISTRY = Registry("stage type", name_both=True)

#: the built-in stage types and the module of :mod:`simcam.stages` that defines each; a module is
#: imported when a pipeline first names one of its types (a render does not pay for the ``dcp`` or
#: ``noise`` stages' imports), and all of them by :func:`stage_types`
BUILTIN_STAGES = {
    "camera_to_xyz": "camera_to_xyz", "clip": "clip", "quantize": "clip", "dcp": "dcp", "demosaic": "demosaic",
    "gamma": "gamma", "highlights": "highlights", "lens_shading": "lens_shading", "noise": "noise",
    "clip_raw": "noise", "opcodes": "opcodes", "orientation": "orientation", "normalize": "raw", "crop": "raw",
    "tone": "tone", "white_balance": "white_balance", "xyz_to_srgb": "xyz_to_srgb",
}


def _load_builtin(key: str) -> None:
    """Import the module that defines the built-in stage ``key`` (if it is one)."""
    mod = BUILTIN_STAGES.get(key)
    if mod is not None:
        import importlib

        importlib.import_module(f"{__package__}.{mod}")


class StageParams(BaseModel):
    """Base of every stage's parameters: unknown keys and loose types are errors.

    Attributes
    ----------
    fields
        Each stage's ``Params`` subclass declares its YAML keys as pydantic fields (strict, frozen).

    Examples
    --------
    >>> class Params(StageParams):
    ...     strength: float = 1.0
    >>> Params(strength=0.5).strength
    0.5
    >>> Params(strenght=0.5)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    pydantic_core._pydantic_core.ValidationError: ...
    """

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


@dataclass(frozen=True)
class RowOp:
    """A stage's action on ``frame`` as a map of rows (see :meth:`Stage.row_op`).

    Attributes
    ----------
    fn : callable
        ``fn(src, dst, r0)`` writes the float32 output rows ``r0 .. r0 + len(src)`` into ``dst``
        from the input rows ``src`` (the same shape; ``dst`` may be ``src`` itself): exactly the
        values :meth:`Stage.apply` gives on those rows.
    result : callable
        ``result(frame, data)``: the frame :meth:`Stage.apply` returns, with ``data`` as its pixels
        (metadata, kind and history as ``apply`` sets them).
    """

    fn: Callable[[np.ndarray, np.ndarray, int], None]
    result: Callable[[RawFrame, np.ndarray], RawFrame]


class Stage:
    """Base class of pipeline stages (see module docstring).

    Parameters
    ----------
    params : StageParams, optional
        The stage's validated ``Params``; or give them as keywords instead.
    **kwargs
        The ``Params`` fields (validated strictly; unknown keys are errors).

    Attributes
    ----------
    type : str
        The stable key of the stage in pipeline YAML.
    accepts, produces : frozenset of str, str or None
        Signal kinds it takes and gives (None: the input's).
    params : StageParams
        Its parameters.

    Examples
    --------
    >>> import numpy as np
    >>> from simcam.frame import CameraMeta, RawFrame
    >>> gamma = get_stage_class("gamma")(curve="power", exponent=0.5)
    >>> frame = RawFrame(np.full((2, 2, 3), 0.25), CameraMeta(), kind="linear_srgb")
    >>> out = gamma(frame)
    >>> out.kind, float(out.data[0, 0, 0]), gamma.to_node()
    ('display', 0.5, {'type': 'gamma', 'curve': 'power', 'exponent': 0.5})
    """

    type: ClassVar[str]
    accepts: ClassVar[frozenset[str]]
    produces: ClassVar[str | None] = None  # None: same kind as the input
    random: ClassVar[bool] = False
    Params: ClassVar[type[StageParams]] = StageParams

    def __init_subclass__(cls, **attrs: Any):
        """A stage declares ``type``, ``accepts``, ``produces`` and ``random`` as keywords of its class
        statement (``class Gamma(Stage, type="gamma", accepts=frozenset({"linear_srgb"}), produces="display")``)."""
        super().__init_subclass__()
        for key, value in attrs.items():
            if key not in ("type", "accepts", "produces", "random"):
                raise TypeError(f"stage {cls.__name__}: unknown class keyword {key!r}")
            setattr(cls, key, value)

    def __init__(self, params: StageParams | None = None, **kwargs: Any):
        if params is None:
            params = self.Params.model_validate_json(_to_json(kwargs))
        elif kwargs:
            raise TypeError("pass either a Params object or keyword parameters, not both")
        self.params = params
        self.check_params(params)

    def check_params(self, p: StageParams) -> None:
        """Checks of the parameters beyond their types (a stage's ranges and combinations): StageError."""

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

    def row_op(self, frame: RawFrame) -> RowOp | None:
        """This stage on ``frame`` as a :class:`RowOp`, or None (the default: it is not a map of rows,
        or not for this frame). Only the frame's metadata, kind, shape and dtype may be read, never its
        pixel values (they may not be computed yet); the checks of :meth:`apply` raise here as there."""
        return None

    def passes_through(self, frame: RawFrame) -> bool:
        """True when :meth:`apply` returns ``frame``'s pixels unchanged (e.g. an opcode list the file does
        not have); False (the default) when it may change them. Reads the metadata only, as :meth:`row_op`."""
        return False

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
    """Class decorator: register a stage under its stable ``type`` key.

    Parameters
    ----------
    cls : type
        A :class:`Stage` subclass with a string class attribute ``type``.

    Returns
    -------
    type
        ``cls`` itself, now found by :func:`get_stage_class` and :func:`stage_types`.

    Examples
    --------
    >>> class Halve(Stage, type="halve_doc_example", accepts=frozenset({"raw"})):
    ...     pass
    >>> register_stage(Halve) is get_stage_class("halve_doc_example")
    True
    >>> _ = _REGISTRY.pop("halve_doc_example")
    """
    key = getattr(cls, "type", None)
    if not key or not isinstance(key, str):
        raise TypeError(f"{cls.__name__} needs a string class attribute 'type'")
    if key in BUILTIN_STAGES and key not in _REGISTRY and cls.__module__ != f"{__package__}.{BUILTIN_STAGES[key]}":
        _load_builtin(key)  # a built-in's name stays taken before its module is imported
    return _REGISTRY.add(key, cls)


def stage_types() -> dict[str, type[Stage]]:
    """All registered stage classes by ``type`` key (importing :mod:`simcam.pipeline` registers the built-in ones).

    Returns
    -------
    dict of str to type
        A copy of the stage registry.

    See Also
    --------
    get_stage_class : one class, with an error that lists the keys.

    Examples
    --------
    >>> import simcam.pipeline
    >>> {"demosaic", "gamma"} <= set(stage_types())
    True
    """
    for key in BUILTIN_STAGES:
        if key not in _REGISTRY:
            _load_builtin(key)
    return _REGISTRY.types()


def get_stage_class(key: str, *, where: str = "type") -> type[Stage]:
    """The stage class registered under ``key``.

    Parameters
    ----------
    key : str
        A stage ``type`` (``"gamma"``, ``"demosaic"``...).
    where : str
        Location named in the error message.

    Returns
    -------
    type
        The :class:`Stage` subclass.

    Raises
    ------
    PipelineError
        No stage has that key (the message lists the known ones).

    Examples
    --------
    >>> import simcam.pipeline
    >>> get_stage_class("gamma").__name__
    'Gamma'
    """
    if key not in _REGISTRY:
        _load_builtin(key)
    try:
        return _REGISTRY[key]
    except KeyError:
        raise PipelineError(
            f"{where}: unknown stage {key!r}; expected one of {', '.join(sorted(stage_types()))}"
        ) from None


def _to_json(obj: Any) -> str:
    import json

    return json.dumps(obj, default=lambda o: o.tolist() if isinstance(o, np.ndarray) else str(o))
