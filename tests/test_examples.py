"""Examples are executed by the tests: the bundled DNG is exactly what its generator makes."""

from __future__ import annotations

import runpy
import sys

import numpy as np
import rawpy

from shared_data import REPO

EXAMPLE = REPO / "examples" / "data" / "chart.dng"


def test_chart_generator_reproduces_bundled_dng(tmp_path, monkeypatch):
    out = tmp_path / "chart.dng"
    monkeypatch.setattr(sys, "argv", ["make_chart_dng.py", str(out)])
    runpy.run_path(str(REPO / "examples" / "make_chart_dng.py"), run_name="__main__")
    assert out.read_bytes() == EXAMPLE.read_bytes()


def test_bundled_dng_opens_in_libraw():
    with rawpy.imread(str(EXAMPLE)) as raw:
        img = raw.raw_image.copy()
        pattern = raw.raw_pattern.copy()
        desc = raw.color_desc.decode()
    assert img.shape == (400, 600) and img.dtype == np.uint16
    assert "".join(desc[i] for i in pattern.ravel()) == "RGGB"
    assert 256 <= np.median(img) < 4095
