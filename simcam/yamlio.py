"""Reading YAML from untrusted files: plain data only, bounded size.

Pipelines, profiles and capture-set side files are read with :func:`load_yaml`, a
``yaml.SafeLoader`` that

* refuses anchors and aliases (``&a`` / ``*a``): a "billion laughs" document expands a
  few hundred bytes into gigabytes through nested aliases, and simcam's files never need them;
* refuses documents larger than :data:`MAX_YAML_BYTES`;
* reads YAML 1.2 floats such as ``1e-3`` as numbers (PyYAML's YAML 1.1 resolver needs
  ``1.0e-3`` and would otherwise give the string ``"1e-3"``).
"""

from __future__ import annotations

import re
from typing import Any

import yaml

#: Largest YAML document simcam reads (bytes); profiles and pipelines are a few kB.
MAX_YAML_BYTES = 16 * 1024 * 1024

_FLOAT_12 = re.compile(r"""^[-+]?(?:[0-9][0-9_]*\.?[0-9_]*|\.[0-9_]+)(?:[eE][-+]?[0-9]+)?$
                           |^[-+]?\.(?:inf|Inf|INF)$|^\.(?:nan|NaN|NAN)$""", re.X)


class _DataLoader(yaml.SafeLoader):
    """SafeLoader without anchors/aliases, with YAML 1.2 floats."""

    def compose_node(self, parent, index):  # noqa: D102 - yaml.composer API
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent) or getattr(event, "anchor", None) is not None:
            mark = event.start_mark
            raise yaml.constructor.ConstructorError(
                None, None, "anchors and aliases are not allowed; write the value out", mark)
        return super().compose_node(parent, index)


_DataLoader.yaml_implicit_resolvers = {k: list(v) for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()}
_DataLoader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT_12, list("-+0123456789."))


def load_yaml(text: str, *, source: str, error: type[Exception]) -> Any:
    """Parse one YAML document of plain data.

    Parameters
    ----------
    text : str
        The document.
    source : str
        Where it came from (a file path), named in errors.
    error : type
        The :class:`~simcam.errors.SimcamError` subclass to raise.

    Returns
    -------
    object
        dicts, lists, strings, numbers, booleans and None.

    Raises
    ------
    error
        Invalid YAML, anchors/aliases, or a document over :data:`MAX_YAML_BYTES`, in one line
        naming ``source`` and the line.

    Examples
    --------
    >>> from simcam.errors import PipelineError
    >>> load_yaml("gain: 1e-3", source="p.yaml", error=PipelineError)
    {'gain': 0.001}
    """
    if len(text) > MAX_YAML_BYTES:
        raise error(f"{source}: YAML document of {len(text)} bytes; expected at most {MAX_YAML_BYTES} bytes")
    try:
        return yaml.load(text, Loader=_DataLoader)  # noqa: S506 - _DataLoader is a SafeLoader
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        loc = f" line {mark.line + 1}" if mark else ""
        raise error(f"{source}:{loc} invalid YAML ({getattr(exc, 'problem', exc)})") from None
