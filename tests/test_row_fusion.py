"""Runs of row-wise stages (normalize, white_balance, clip) fused on bands in one buffer
(simcam.row_fusion): the pixels of the DNG normalisation formula computed directly in numpy
(DNG 1.7 ch. 5: (DN - black[site]) / (white - black[site]), then the gain of the site's colour,
then the clip), the metadata of the stages run one by one, and the input never written."""

from __future__ import annotations

import numpy as np
import pytest

from simcam.frame import CameraMeta, RawFrame
from simcam.pipeline import Pipeline, build_stage
from simcam import row_fusion

BLACK = np.array([[60.0, 64.0], [66.0, 70.0]])
NEUTRAL = np.array([0.5, 1.0, 0.8])  # AsShotNeutral: gains 2, 1, 1.25


def _frame(h, w, dtype, seed=0, active_area=None):
    rng = np.random.default_rng(seed)
    data = rng.integers(40, 1100, size=(h, w)).astype(dtype)
    meta = CameraMeta(cfa="GRBG", black_level=BLACK.copy(), white_level=1023.0, as_shot_neutral=NEUTRAL.copy(),
                      active_area=active_area)
    return RawFrame(data, meta, kind="raw_dn")


def _expected(data, top=0, left=0, high=1.0):
    """The formula in float32, site by site (GRBG: G at (0,0) and (1,1), R at (0,1), B at (1,0))."""
    d = np.asarray(data)[top:, left:].astype(np.float32)
    out = np.empty(d.shape, np.float32)
    gain = {"R": np.float32(2.0), "G": np.float32(1.0), "B": np.float32(1.25)}
    for dy, dx, c in ((0, 0, "G"), (0, 1, "R"), (1, 0, "B"), (1, 1, "G")):
        b = np.float32(BLACK[(top + dy) % 2, (left + dx) % 2])
        v = (d[dy::2, dx::2] - b) / (np.float32(1023.0) - b)
        out[dy::2, dx::2] = v * gain[c]
    return np.minimum(out, np.float32(high))


def _stages(*nodes):
    return [build_stage(n) for n in nodes]


HEAD = ({"type": "normalize"}, {"type": "crop", "region": "active_area"}, {"type": "white_balance"},
        {"type": "clip", "low": None, "high": 1.0})


@pytest.mark.parametrize("shape", [(37, 26), (1000, 302)])  # odd rows (a black map, not a cell); many bands
@pytest.mark.parametrize("dtype", [np.uint16, np.float32, np.float64])
@pytest.mark.parametrize("band_rows", [32, 7])  # 7: bands that start on odd rows of the CFA
def test_fused_head_is_the_formula_and_the_stages_one_by_one(shape, dtype, band_rows, monkeypatch):
    monkeypatch.setattr(row_fusion, "BAND_ROWS", band_rows)
    frame = _frame(*shape, dtype)
    before = frame.data.copy()
    stages = _stages(*HEAD)
    fused = Pipeline(stages)(frame)
    one_by_one = frame
    for st in stages:
        one_by_one = st(one_by_one)
    assert fused.data.dtype == np.float32
    np.testing.assert_array_equal(fused.data, _expected(frame.data))
    assert fused.data.tobytes() == one_by_one.data.tobytes()
    assert fused.history == one_by_one.history and fused.kind == one_by_one.kind == "raw"
    np.testing.assert_array_equal(fused.meta.white_balance_gains, one_by_one.meta.white_balance_gains)
    assert frame.data.tobytes() == before.tobytes()  # the input is never written


def test_a_column_crop_between_runs_and_progress():
    """An active area that cuts columns: crop copies the normalised frame; the next run works on that."""
    frame = _frame(1000, 400, np.uint16, seed=3, active_area=(2, 4, 1000, 396))
    calls = []
    out = Pipeline(_stages(*HEAD))(frame, progress=calls.append)
    np.testing.assert_array_equal(out.data, _expected(frame.data, 2, 4)[:998, :392])
    assert calls == ["normalize", "crop", "white_balance", "clip"]
    assert out.data.flags.c_contiguous


def test_an_input_float32_frame_is_not_worked_in_place():
    """A raw frame of float32 entering white balance and clip first: the caller's array stays as it was."""
    rng = np.random.default_rng(1)
    data = rng.uniform(-0.1, 1.2, size=(700, 400)).astype(np.float32)
    meta = CameraMeta(cfa="RGGB", black_level=np.zeros((1, 1)), white_level=1.0, as_shot_neutral=NEUTRAL.copy())
    frame = RawFrame(data, meta, kind="raw")
    before = data.copy()
    out = Pipeline(_stages({"type": "white_balance"}, {"type": "clip"}), input_kind="raw")(frame)
    gains = np.array([[2.0, 1.0], [1.0, 1.25]], np.float32)
    np.testing.assert_array_equal(out.data, np.clip(before * np.tile(gains, (350, 200)), 0.0, 1.0))
    assert data.tobytes() == before.tobytes() and not np.shares_memory(out.data, data)


def test_errors_are_the_stages_own():
    frame = _frame(64, 64, np.uint16)
    frame.meta.white_level = 50.0
    with pytest.raises(Exception, match="WhiteLevel: expected white"):
        Pipeline(_stages(*HEAD))(frame)
    frame = _frame(64, 64, np.uint16)
    frame.meta.cfa = None
    with pytest.raises(Exception, match="cfa: a mosaic needs meta.cfa"):
        Pipeline(_stages(*HEAD))(frame)


@pytest.mark.parametrize("active_area", [None, (2, 4, 1000, 396), (3, 1, 999, 397)])  # odd offsets: phase update
def test_a_row_source_gives_every_band_of_the_formula(active_area):
    """``row_source``: any band of rows, made on demand, equals the formula (and the fused head's rows)."""
    frame = _frame(1000, 400, np.uint16, seed=5, active_area=active_area)
    nodes = list(HEAD)
    if active_area is not None and active_area[0] % 2:
        nodes[1] = {"type": "crop", "region": "active_area", "phase": "update"}
    stages = _stages(*nodes)
    calls = []
    rows, planned = row_fusion.row_source(stages, frame, progress=calls.append)
    full = Pipeline(stages)(frame)
    top, left = (0, 0) if active_area is None else active_area[:2]
    assert rows.shape == full.data.shape == planned.data.shape
    assert planned.meta.cfa == full.meta.cfa and planned.kind == full.kind == "raw"
    assert calls == [n["type"] for n in nodes]
    expected = full.data  # the stages run on the whole frame
    if top % 2 == 0 and left % 2 == 0:  # the formula's gains follow GRBG from (0, 0): even offsets only
        np.testing.assert_array_equal(expected, _expected(frame.data, top, left)[:expected.shape[0], :expected.shape[1]])
    for a, b in [(0, 1), (0, 37), (5, 6), (17, 50), (full.data.shape[0] - 3, full.data.shape[0])]:
        assert rows.rows(a, b).tobytes() == expected[a:b].tobytes(), (a, b)
    assert rows.materialize().tobytes() == expected.tobytes()


def test_a_row_source_refuses_what_it_cannot_plan():
    frame = _frame(64, 64, np.uint16)
    noise = {"type": "noise", "model": {"type": "nlf", "beta1": 1e-3, "beta2": 1e-5}}
    assert row_fusion.row_source(_stages({"type": "normalize"}, noise), frame) is None  # random
    from simcam.io.sample_dng import radial_gain_maps

    frame.meta.opcode_list2 = radial_gain_maps(64, 64)  # lens shading that acts: not a row map
    assert row_fusion.row_source(_stages({"type": "normalize"}, {"type": "lens_shading"}), frame) is None
    assert row_fusion.row_source(_stages({"type": "normalize"}, {"type": "opcodes", "list": 1}), frame) is not None
    frame.meta.white_level = 50.0  # the stages' own checks, as when they run
    with pytest.raises(Exception, match="WhiteLevel: expected white"):
        row_fusion.row_source(_stages(*HEAD), frame)
