"""Pipelines: an ordered list of stages, checked when built, loaded from and saved to YAML.

YAML form::

    version: 1
    name: srgb            # optional
    input: raw_dn         # optional signal kind of the input frame (default raw_dn)
    stages:
      - type: normalize
      - type: demosaic
        method: malvar2004

Build-time checks: unknown stage type, unknown or wrongly typed parameter, and an
impossible order (a stage that cannot accept the signal kind its predecessor
produces, e.g. noise after demosaic) each fail with one :class:`PipelineError`
naming the file and the YAML path of the culprit, e.g. ``stages[3].gains``.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np
import yaml
from pydantic import ValidationError

from .errors import PipelineError, SimcamError
from .frame import SIGNAL_KINDS, RawFrame
from .row_fusion import run_stages
from .stages.base import Stage, get_stage_class
from .yamlio import load_yaml

PIPELINE_VERSION = 1
_FLOATISH = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+$")
BUILTIN_DIR = Path(__file__).resolve().parent.parent / "pipelines"


class Pipeline:
    """An ordered, validated list of stages.

    Parameters
    ----------
    stages : iterable of Stage
        Stage objects, applied in order.
    input_kind : str
        Signal kind of the frames the pipeline is run on (default ``"raw_dn"``).
    name : str
        Optional display name.
    source : str
        File the pipeline came from (used in error messages).
    """

    def __init__(self, stages: Iterable[Stage], *, input_kind: str = "raw_dn", name: str = "",
                 source: str = ""):
        self.stages = list(stages)
        self.input_kind = input_kind
        self.name = name
        self.source = source
        self.output_kind = self._check_order()

    # -- construction ------------------------------------------------------
    @classmethod
    def from_dict(cls, doc: Any, *, source: str = "<dict>") -> "Pipeline":
        where = source
        if not isinstance(doc, dict):
            raise PipelineError(f"{where}: expected a mapping with 'version' and 'stages', got {type(doc).__name__}")
        unknown = set(doc) - {"version", "name", "input", "stages", "description"}
        if unknown:
            raise PipelineError(f"{where}: unknown top-level key(s) {sorted(unknown)}; expected version, name, input, stages, description")
        version = doc.get("version")
        if version != PIPELINE_VERSION:
            raise PipelineError(f"{where}: version: expected {PIPELINE_VERSION}, got {version!r}")
        input_kind = doc.get("input", "raw_dn")
        if input_kind not in SIGNAL_KINDS:
            raise PipelineError(f"{where}: input: expected one of {SIGNAL_KINDS}, got {input_kind!r}")
        nodes = doc.get("stages")
        if not isinstance(nodes, list) or not nodes:
            raise PipelineError(f"{where}: stages: expected a non-empty list of {{type: ...}} nodes, got {nodes!r}")
        stages = [build_stage(node, where=f"{where}: stages[{i}]") for i, node in enumerate(nodes)]
        return cls(stages, input_kind=input_kind, name=str(doc.get("name", "")), source=source)

    @classmethod
    def from_yaml(cls, text_or_path: str | Path) -> "Pipeline":
        """Load from a YAML file path, a built-in name (``"srgb"``) or YAML text."""
        path = resolve_pipeline_path(text_or_path) if not _looks_like_yaml_text(text_or_path) else None
        if path is not None:
            try:
                text = path.read_text()
            except OSError as exc:
                raise PipelineError(f"{path}: cannot read pipeline ({exc.strerror})") from None
            source = str(path)
        else:
            text, source = str(text_or_path), "<yaml>"
        doc = load_yaml(text, source=source, error=PipelineError)
        return cls.from_dict(doc, source=source)

    def to_dict(self) -> dict[str, Any]:
        doc: dict[str, Any] = {"version": PIPELINE_VERSION}
        if self.name:
            doc["name"] = self.name
        if self.input_kind != "raw_dn":
            doc["input"] = self.input_kind
        doc["stages"] = [s.to_node() for s in self.stages]
        return doc

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.to_dict(), sort_keys=False, default_flow_style=None)

    def with_overrides(self, overrides: dict[str, Any]) -> "Pipeline":
        """A copy with ``{"stage.param": value}`` overrides (stage by type, or ``type[i]``).

        ``param`` may be a dotted path into a nested parameter (``noise.model.beta1``).
        """
        doc = self.to_dict()
        for key, value in overrides.items():
            if "." not in key:
                raise PipelineError(f"--set {key}: expected STAGE.PARAM=VALUE")
            stage_key, param = key.split(".", 1)
            m = re.fullmatch(r"([A-Za-z0-9_]+)(?:\[(\d+)\])?", stage_key)
            if not m:
                raise PipelineError(f"--set {key}: expected STAGE.PARAM=VALUE")
            idxs = [i for i, n in enumerate(doc["stages"]) if n["type"] == m.group(1)]
            if not idxs:
                raise PipelineError(
                    f"--set {key}: pipeline {self.name or self.source!r} has no stage {m.group(1)!r}; "
                    f"its stages are {[n['type'] for n in doc['stages']]}")
            pick = int(m.group(2)) if m.group(2) else 0
            if pick >= len(idxs):
                raise PipelineError(f"--set {key}: only {len(idxs)} stage(s) of type {m.group(1)!r}")
            node = doc["stages"][idxs[pick]]
            *parents, leaf = param.split(".")  # nested: noise.model.beta1 -> node["model"]["beta1"]
            for j, part in enumerate(parents):
                child = node.get(part)
                if child is None:
                    child = node[part] = {}
                if not isinstance(child, dict):
                    raise PipelineError(f"--set {key}: {'.'.join([m.group(1), *parents[:j + 1]])} is "
                                        f"{type(child).__name__} {child!r}; expected a mapping to set {leaf!r} in")
                node = child
            node[leaf] = value
        return Pipeline.from_dict(doc, source=f"{self.source or '<pipeline>'} (with --set)")

    # -- checks ------------------------------------------------------------
    def _check_order(self) -> str:
        kind = self.input_kind
        for i, stage in enumerate(self.stages):
            if kind not in stage.accepts:
                prev = f"after {self.stages[i - 1].type!r}" if i else "as the first stage"
                raise PipelineError(
                    f"{self.source or '<pipeline>'}: stages[{i}] ({stage.type}): impossible order {prev}: "
                    f"it accepts {sorted(stage.accepts)} but gets {kind!r}")
            kind = stage.output_kind(kind)
        return kind

    # -- running -------------------------------------------------------------
    def warm_in_background(self):
        """Start a thread that runs the one-time set-up of the stages that have one (``stage.warm_up()``
        returns it, e.g. loading a compiled kernel), so that it overlaps what the caller does next
        (reading the input); returns the thread (join it before returning) or None when no stage has
        one. A failure there is left to the stage's own call, which raises it with its message."""
        import threading

        fns = [f for f in (getattr(st, "warm_up", lambda: None)() for st in self.stages) if f is not None]
        if not fns:
            return None

        def run():
            for fn in fns:
                try:
                    fn()
                except Exception:  # noqa: BLE001,S110 - the stage's own call reports it
                    pass

        thread = threading.Thread(target=run, name="simcam-warm", daemon=True)
        thread.start()
        return thread

    def __call__(self, frame: RawFrame, *, seed: int | None = None, epoch: int = 0,
                 index: int = 0, progress: Callable[[str], None] | None = None) -> RawFrame:
        """Run the pipeline on one frame.

        Randomness: sample ``index`` of epoch ``epoch`` draws from
        ``np.random.SeedSequence([seed, epoch, index])``; random stage k uses
        the k-th spawned child, so results do not depend on worker count.
        ``progress``, if given, is called with each stage's type after it ran (a progress bar).
        """
        if frame.kind != self.input_kind:
            raise PipelineError(
                f"{self.source or '<pipeline>'}: input: expected a frame of kind {self.input_kind!r}, got {frame.kind!r}")
        random_stages = [s for s in self.stages if s.random]
        rngs: list[np.random.Generator] = []
        if random_stages:
            if seed is None:
                raise PipelineError(f"{self.source or '<pipeline>'}: has random stages "
                                    f"{[s.type for s in random_stages]}: pass seed=")
            children = np.random.SeedSequence([int(seed), int(epoch), int(index)]).spawn(len(self.stages))
            rngs = [np.random.default_rng(c) for c in children]
        return run_stages(self.stages, frame, rngs, progress)

    run = __call__

    def __repr__(self) -> str:
        return f"Pipeline({self.name or self.source!r}, {[s.type for s in self.stages]})"


def build_stage(node: Any, *, where: str = "stage") -> Stage:
    """Build one stage from its ``{type: ..., **params}`` node, or raise PipelineError."""
    if isinstance(node, Stage):
        return node
    if not isinstance(node, dict) or "type" not in node:
        raise PipelineError(f"{where}: expected a mapping with a 'type' key, got {node!r}")
    params = {k: v for k, v in node.items() if k != "type"}
    cls = get_stage_class(node["type"], where=f"{where}.type")
    try:
        p = cls.Params.model_validate_json(json.dumps(params, default=_json_default))
    except ValidationError as exc:
        raise PipelineError(f"{where} ({node['type']}): {_describe_validation_error(exc, params)}") from None
    except SimcamError as exc:
        raise PipelineError(f"{where} ({node['type']}): {exc}") from None
    try:
        return cls(p)
    except SimcamError as exc:
        raise PipelineError(f"{where} ({node['type']}): {exc}") from None


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    return str(o)


def _describe_validation_error(exc: ValidationError, params: dict[str, Any]) -> str:
    err = exc.errors()[0]
    loc = ".".join(str(p) for p in err["loc"]) or "(parameters)"
    value = err.get("input")
    msg = err["msg"]
    if err["type"] == "extra_forbidden":
        return f"{loc}: unknown parameter (value {value!r})"
    hint = ""
    if isinstance(value, str) and _FLOATISH.match(value.strip()):
        hint = (f"; {value!r} is a string because YAML 1.1 (PyYAML) reads exponent floats without a dot and a signed exponent as text: "
                f"write {_dotted(value)}")
    return f"{loc}: {msg}, got {value!r}{hint}"


def _dotted(value: str) -> str:
    """The YAML 1.1 float spelling of ``value``: a dot in the mantissa, a signed exponent."""
    mant, _, exp = value.strip().lower().partition("e")
    if "." not in mant:
        mant += ".0"
    if exp[:1] not in "+-":
        exp = "+" + exp
    return f"{mant}e{exp}"


def _looks_like_yaml_text(s: str | Path) -> bool:
    return isinstance(s, str) and ("\n" in s or s.lstrip().startswith("{"))


def resolve_pipeline_path(name: str | Path) -> Path:
    """A pipeline file path, or the built-in ``pipelines/NAME.yaml`` for a bare name."""
    p = Path(name)
    if p.exists():
        return p
    builtin = BUILTIN_DIR / (p.name if p.suffix else f"{p.name}.yaml")
    if p.parent == Path(".") and builtin.exists():
        return builtin
    raise PipelineError(
        f"{name}: no such pipeline file; built-in pipelines are {builtin_pipelines()}")


def builtin_pipelines() -> list[str]:
    return sorted(p.stem for p in BUILTIN_DIR.glob("*.yaml"))
