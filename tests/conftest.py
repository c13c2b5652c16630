"""Shared test fixtures.

``shared_file("dng/x.dng")`` returns a path under ``../shared/data`` or skips the
test with a reason when it is absent (the data is never copied into the repo).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SHARED_DATA = Path(os.environ.get("SIMCAM_SHARED_DATA", REPO.parent / "shared" / "data"))


def shared_path(rel: str) -> Path:
    p = SHARED_DATA / rel
    if not p.exists():
        pytest.skip(f"shared data file {rel} not found under {SHARED_DATA}")
    return p


@pytest.fixture
def shared_file():
    return shared_path


def pytest_collection_modifyitems(config, items):
    if os.environ.get("SIMCAM_SLOW") == "1":
        return
    skip = pytest.mark.skip(reason="slow test: set SIMCAM_SLOW=1 to run")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
