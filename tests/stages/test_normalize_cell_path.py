"""normalize's per-cell fast path equals the full black-level-map formula bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from simcam.errors import MetadataError
from simcam.frame import CameraMeta, RawFrame
from simcam.raw import black_level_cell, black_level_map
from simcam.stages.raw import Normalize


def reference(frame: RawFrame) -> np.ndarray:
    black = black_level_map(frame.meta, frame.data.shape)
    white = np.float32(frame.meta.white_level)
    return (frame.data - black) / (white - black)


@pytest.mark.parametrize(
    "black, origin, active, shape",
    [
        ([[64.0]], (0, 0), None, (6, 8)),
        ([[60.0, 61.0], [62.0, 63.0]], (0, 0), None, (6, 8)),
        ([[60.0, 61.0], [62.0, 63.0]], (1, 0), (0, 0, 20, 20), (6, 8)),  # odd origin row: re-phased
        ([[60.0, 61.0], [62.0, 63.0]], (3, 5), (1, 2, 20, 20), (4, 6)),  # active-area anchor
        ([[60.0, 61.5]], (0, 1), None, (5, 8)),  # 1x2 repeat, odd height is fine
        ([[[60.0], [61.0]], [[62.0], [63.0]]], (0, 0), None, (4, 4)),  # (rows, cols, samples)
    ],
)
def test_cell_path_equals_full_map(black, origin, active, shape):
    rng = np.random.default_rng(7)
    meta = CameraMeta(cfa=None, black_level=np.array(black), white_level=1023.0, origin=origin, active_area=active)
    data = rng.uniform(0, 1023, shape).astype(np.float32)
    frame = RawFrame(data, meta, kind="raw_dn")
    assert black_level_cell(meta, shape) is not None
    np.testing.assert_array_equal(Normalize()(frame).data, reference(frame))


def test_fallbacks_to_full_map():
    meta = CameraMeta(cfa=None, black_level=np.array([[60.0, 61.0], [62.0, 63.0]]), white_level=1023.0)
    assert black_level_cell(meta, (5, 8)) is None  # not a whole number of 2x2 cells
    frame = RawFrame(np.full((5, 8), 500.0, np.float32), meta, kind="raw_dn")
    np.testing.assert_array_equal(Normalize()(frame).data, reference(frame))
    meta_d = meta.replace(black_level_delta_v=np.linspace(0, 3, 6))
    assert black_level_cell(meta_d, (6, 8)) is None
    frame = RawFrame(np.full((6, 8), 500.0, np.float32), meta_d, kind="raw_dn")
    np.testing.assert_array_equal(Normalize()(frame).data, reference(frame))


def test_cell_path_keeps_white_check():
    meta = CameraMeta(cfa=None, black_level=np.array([[60.0, 2000.0], [62.0, 63.0]]), white_level=1023.0, source="a.dng")
    with pytest.raises(MetadataError, match=r"a.dng: WhiteLevel: expected white \(1023.0\) above the black level \(max 2000.0\)"):
        Normalize()(RawFrame(np.zeros((4, 4), np.float32), meta, kind="raw_dn"))
