"""Run the examples in the docstrings of the main public entry points (``doctest``)."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = [
    "simcam.api",
    "simcam.batch",
    "simcam.cfa",
    "simcam.raw",
    "simcam.yamlio",
    "simcam.io.inputs",
    "simcam.io.normalized",
    "simcam.io.npz",
    "simcam.io.outputs",
    "simcam.noise.base",
    "simcam.denoise.image_metrics",
    "simcam.groundtruth.estimate",
]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0, f"{name}: no examples"
    assert result.failed == 0, f"{name}: {result.failed} of {result.attempted} examples failed"
