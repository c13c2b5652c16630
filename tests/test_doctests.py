"""Run the examples in the docstrings of the public entry points (``doctest``), and check that every
entry point has them.

An entry point is a function or class named in the ``__all__`` of ``simcam`` or of one of its
subpackages (:data:`PACKAGES`), or a public function of :mod:`simcam.api`. Each must have a numpydoc
docstring with ``Parameters`` (where it takes any), ``Returns`` (``Yields`` for a generator,
``Attributes`` or ``Returns`` for a class) and ``Examples`` sections; the module that defines it must
be in :data:`MODULES`, so that its examples run.
"""

from __future__ import annotations

import doctest
import importlib
import inspect

import pytest

MODULES = [
    "simcam.api",
    "simcam.batch",
    "simcam.cfa",
    "simcam.errors",
    "simcam.frame",
    "simcam.raw",
    "simcam.registry",
    "simcam.yamlio",
    "simcam.io.inputs",
    "simcam.io.normalized",
    "simcam.io.npz",
    "simcam.io.outputs",
    "simcam.demosaic",
    "simcam.demosaic.bilinear",
    "simcam.demosaic.malvar2004",
    "simcam.demosaic.menon2007",
    "simcam.noise.base",
    "simcam.noise.effects.base",
    "simcam.noise.flow.model",
    "simcam.noise.flow.published",
    "simcam.noise.flow.export",
    "simcam.stages.base",
    "simcam.denoise.image_metrics",
    "simcam.groundtruth.alignment",
    "simcam.groundtruth.burst",
    "simcam.groundtruth.defects",
    "simcam.groundtruth.estimate",
    "simcam.groundtruth.intensity",
    "simcam.groundtruth.robust_mean",
    "simcam.groundtruth.synthetic_burst",
    "simcam.calibration.effects",
    "simcam.calibration.effects.card",
    "simcam.torch.api",
    "simcam.torch.layout",
    "simcam.torch.logprob",
]

#: packages whose ``__all__`` lists entry points
PACKAGES = [
    "simcam",
    "simcam.calibration.effects",
    "simcam.demosaic",
    "simcam.groundtruth",
    "simcam.noise",
    "simcam.noise.effects",
    "simcam.noise.flow",
    "simcam.stages",
    "simcam.torch",
]


def _entry_points() -> list[tuple[str, object]]:
    out = []
    for name in PACKAGES:
        package = importlib.import_module(name)
        for attr in package.__all__:
            obj = getattr(package, attr)
            if inspect.isclass(obj) or inspect.isfunction(obj):
                out.append((f"{name}.{attr}", obj))
    api = importlib.import_module("simcam.api")
    out += [(f"simcam.api.{n}", f) for n, f in vars(api).items()
            if inspect.isfunction(f) and not n.startswith("_") and f.__module__ == "simcam.api"]
    return out


def _takes_parameters(obj) -> bool:
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return True
    return any(p.name not in ("self", "cls") for p in sig.parameters.values())


def _has_section(doc: str, title: str) -> bool:
    return f"\n{title}\n{'-' * len(title)}\n" in f"\n{doc}\n"


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0, f"{name}: no examples"
    assert result.failed == 0, f"{name}: {result.failed} of {result.attempted} examples failed"


@pytest.mark.parametrize("name,obj", _entry_points(), ids=lambda v: v if isinstance(v, str) else "")
def test_entry_point_has_numpydoc_sections(name, obj):
    doc = inspect.getdoc(obj) or ""
    missing = []
    if _takes_parameters(obj) and not _has_section(doc, "Parameters"):
        missing.append("Parameters")
    results = ("Returns", "Attributes") if inspect.isclass(obj) else ("Returns", "Yields")
    if not any(_has_section(doc, t) for t in results):
        missing.append(" or ".join(results))
    if not _has_section(doc, "Examples") or ">>> " not in doc:
        missing.append("Examples")
    assert not missing, f"{name}: docstring lacks {', '.join(missing)}"
    assert obj.__module__ in MODULES, f"{name}: its module {obj.__module__} is not in MODULES (examples not run)"
