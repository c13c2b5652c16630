"""The ``demosaic`` stage: kinds, parameters, YAML, errors."""

from __future__ import annotations

import numpy as np
import pytest

from simcam.demosaic import demosaic_bilinear, demosaic_malvar2004
from simcam.errors import PipelineError, StageError
from simcam.frame import CameraMeta, RawFrame
from simcam.pipeline import Pipeline
from simcam.stages.demosaic import Demosaic


def make_frame(cfa="GBRG", kind="raw", shape=(12, 16)):
    data = np.random.default_rng(5).uniform(0, 1, shape).astype(np.float32)
    return RawFrame(data, CameraMeta(cfa=cfa, source="x.dng"), kind=kind)


@pytest.mark.parametrize("method, fn", [("bilinear", demosaic_bilinear), ("malvar2004", demosaic_malvar2004)])
def test_stage_applies_kernel(method, fn):
    frame = make_frame()
    out = Demosaic(method=method)(frame)
    assert out.kind == "camera_rgb" and out.data.shape == (12, 16, 3) and out.data.dtype == np.float32
    np.testing.assert_array_equal(out.data, fn(frame.data, "GBRG"))
    assert out.history[-1] == "demosaic" and out.meta is frame.meta


def test_default_is_malvar_and_yaml_round_trip():
    assert Demosaic().params.method == "malvar2004"
    pipe = Pipeline.from_yaml("version: 1\nstages:\n  - type: normalize\n  - type: demosaic\n    method: bilinear\n")
    assert pipe.output_kind == "camera_rgb"
    again = Pipeline.from_yaml(pipe.to_yaml())
    assert again.to_dict() == pipe.to_dict()


def test_pipeline_runs_normalize_then_demosaic():
    dn = np.full((8, 10), 1000.0, np.float32)
    frame = RawFrame(dn, CameraMeta(cfa="RGGB", black_level=np.array([[200.0]]), white_level=4200.0), kind="raw_dn")
    pipe = Pipeline.from_yaml("version: 1\nstages:\n  - type: normalize\n  - type: demosaic\n")
    out = pipe(frame)
    np.testing.assert_allclose(out.data, 0.2, rtol=1e-6)


def test_bad_method_names_yaml_path():
    with pytest.raises(PipelineError, match=r"stages\[1\] \(demosaic\): method"):
        Pipeline.from_yaml("version: 1\nstages:\n  - type: normalize\n  - type: demosaic\n    method: ahd\n")


def test_demosaic_before_normalize_is_an_impossible_order():
    with pytest.raises(PipelineError, match=r"stages\[0\] \(demosaic\): impossible order"):
        Pipeline.from_yaml("version: 1\nstages:\n  - type: demosaic\n")


def test_wrong_kind_and_missing_cfa():
    with pytest.raises(StageError, match="expected a frame of kind"):
        Demosaic()(make_frame(kind="raw_dn"))
    with pytest.raises(StageError, match=r"x.dng: cfa: demosaic needs a Bayer pattern"):
        Demosaic()(make_frame(cfa=None))


def test_kernel_error_names_the_file():
    with pytest.raises(StageError, match=r"^x.dng: demosaic \(malvar2004\): mosaic: expected at least 2 x 2"):
        Demosaic()(make_frame(shape=(1, 6)))
