"""Reusable DNG fixtures for tests (import the names you need into a test module).

``make_dng(name="x.dng", h=32, w=32, cfa="RGGB", **meta_fields)`` writes a small
synthetic DNG under the test's tmp_path (see :func:`simcam.io.sample_dng.make_test_dng`).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from simcam.io.sample_dng import make_test_dng


@pytest.fixture
def make_dng(tmp_path):
    """Factory fixture: ``make_dng(name, h, w, cfa, **kw) -> Path`` of a synthetic DNG in tmp_path."""

    def _make(name: str = "synthetic.dng", h: int = 32, w: int = 32, cfa: str = "RGGB", **kw) -> Path:
        return make_test_dng(tmp_path / name, h, w, cfa, **kw)

    return _make


@pytest.fixture
def synthetic_dng(make_dng) -> Path:
    """A 32x32 RGGB DNG with colour matrices, neutral and NoiseProfile."""
    return make_dng()


def file_sha256(path) -> str:
    """Hash of a file's bytes (to check an input was not modified)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()
