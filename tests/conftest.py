"""Shared test fixtures.

``shared_file("dng/x.dng")`` returns a path under ``../shared/data`` or skips the
test with a reason when it is absent (the data is never copied into the repo).
"""

from __future__ import annotations

import os

import pytest
from shared_data import shared_path


@pytest.fixture
def shared_file():
    return shared_path


def pytest_configure(config):
    # the test run already puts one process on each core (pytest -n 2): the calibration loop's replicates run
    # on one thread per process unless a test asks for more (its results do not depend on the count)
    os.environ.setdefault("SIMCAM_LOOP_THREADS", "1")


def pytest_collection_modifyitems(config, items):
    if os.environ.get("SIMCAM_SLOW") == "1":
        return
    skip = pytest.mark.skip(reason="slow test: set SIMCAM_SLOW=1 to run")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
