"""The runnable examples in the public entry points' docstrings (doctest)."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = ["simcam.api", "simcam.yamlio", "simcam.io.outputs", "simcam.io.inputs", "simcam.io.npz", "simcam.batch"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    mod = importlib.import_module(name)
    res = doctest.testmod(mod, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert res.attempted > 0 and res.failed == 0, res
