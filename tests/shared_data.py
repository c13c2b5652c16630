"""Paths the tests share: the repository root and the real files under ``../shared/data``.

A module of its own (not ``conftest``): ``from conftest import ...`` resolves to whichever
``conftest.py`` pytest imported last under that name (``tests/torch/conftest.py`` when the torch
tests are collected first), so helpers imported by tests live here.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SHARED_DATA = Path(os.environ.get("SIMCAM_SHARED_DATA", REPO.parent / "shared" / "data"))


def shared_path(rel: str) -> Path:
    """``SHARED_DATA / rel``, or skip the calling test with a reason when that file is absent."""
    p = SHARED_DATA / rel
    if not p.exists():
        pytest.skip(f"shared data file {rel} not found under {SHARED_DATA}")
    return p
