"""Pipeline construction, validation messages, YAML round trip and seeding."""

from __future__ import annotations

import numpy as np
import pytest

from simcam.errors import PipelineError, SimcamError
from simcam.frame import CameraMeta, RawFrame
from simcam.pipeline import Pipeline, build_stage
from simcam.stages.base import Stage, StageParams, register_stage


@register_stage
class _AddUniform(Stage):
    """Test-only random stage: adds U(0, scale) noise drawn in sample()."""

    type = "_test_add_uniform"
    accepts = frozenset({"raw"})
    random = True

    class Params(StageParams):
        scale: float = 1.0

    def sample(self, rng, frame):
        return {"u": rng.random(frame.data.shape, dtype=np.float32) * np.float32(self.params.scale)}

    def apply(self, frame, drawn=None):
        return frame.evolve(frame.data + drawn["u"])


def dn_frame(h=8, w=10, black=64.0, white=1023.0):
    rng = np.random.default_rng(0)
    meta = CameraMeta(cfa="RGGB", black_level=np.full((2, 2), black), white_level=white)
    return RawFrame(rng.integers(0, 1024, (h, w)).astype(np.float32), meta, kind="raw_dn")


def doc(*stages, **top):
    return {"version": 1, "stages": list(stages), **top}


def test_unknown_stage_names_yaml_path():
    with pytest.raises(PipelineError) as e:
        Pipeline.from_dict(doc({"type": "normalize"}, {"type": "sharpen"}), source="p.yaml")
    msg = str(e.value)
    assert "p.yaml" in msg and "stages[1].type" in msg and "'sharpen'" in msg and "\n" not in msg


def test_wrong_parameter_type_names_field():
    with pytest.raises(PipelineError) as e:
        Pipeline.from_dict(doc({"type": "normalize", "black_level": "high"}), source="p.yaml")
    assert "stages[0]" in str(e.value) and "black_level" in str(e.value)


def test_unknown_parameter_is_an_error():
    with pytest.raises(PipelineError, match=r"stages\[0\].*blacklevel: unknown parameter"):
        Pipeline.from_dict(doc({"type": "normalize", "blacklevel": 3.0}), source="p.yaml")


def test_yaml_exponent_float_without_dot_is_a_number(tmp_path):
    """YAML 1.2 floats: ``1e3`` and ``1e-3`` are numbers (PyYAML's 1.1 resolver reads them as strings)."""
    p = tmp_path / "p.yaml"
    p.write_text("version: 1\nstages:\n  - type: normalize\n    white_level: 1e3\n")
    assert Pipeline.from_yaml(p).stages[0].params.white_level == 1000.0
    pipe = Pipeline.from_yaml("version: 1\nstages:\n  - type: normalize\n    white_level: 1e-3\n")
    assert pipe.stages[0].params.white_level == 0.001


def test_yaml_anchors_and_aliases_are_refused(tmp_path):
    """A billion-laughs document is refused before anything is expanded."""
    lines = ["version: 1", "a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    lines += [f"a{i}: &a{i} [*a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}]"
              for i in range(1, 10)]
    lines += ["stages:", "  - type: normalize"]
    p = tmp_path / "bomb.yaml"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(PipelineError) as e:
        Pipeline.from_yaml(p)
    msg = str(e.value)
    assert str(p) in msg and "line 2" in msg and "aliases" in msg and "\n" not in msg


def test_yaml_exponent_float_with_dot_is_accepted():
    pipe = Pipeline.from_yaml("version: 1\nstages:\n  - type: normalize\n    white_level: 1.0e+3\n")
    assert pipe.stages[0].params.white_level == 1000.0


def test_int_accepted_for_float_and_list_for_tuple():
    pipe = Pipeline.from_dict(doc({"type": "normalize", "white_level": 1023},
                                  {"type": "crop", "region": "explicit", "rect": [0, 0, 4, 4]}))
    assert pipe.stages[0].params.white_level == 1023.0
    assert pipe.stages[1].params.rect == (0, 0, 4, 4)


def test_impossible_order_is_refused():
    with pytest.raises(PipelineError, match=r"stages\[1\] \(normalize\): impossible order"):
        Pipeline.from_dict(doc({"type": "normalize"}, {"type": "normalize"}), source="p.yaml")


def test_version_and_shape_checks():
    with pytest.raises(PipelineError, match="version"):
        Pipeline.from_dict({"version": 2, "stages": [{"type": "normalize"}]})
    with pytest.raises(PipelineError, match="stages"):
        Pipeline.from_dict({"version": 1, "stages": []})
    with pytest.raises(PipelineError, match="unknown top-level"):
        Pipeline.from_dict({"version": 1, "stages": [{"type": "normalize"}], "stagse": []})
    with pytest.raises(PipelineError, match="invalid YAML"):
        Pipeline.from_yaml("version: 1\nstages: [\n")


def test_yaml_round_trip():
    pipe = Pipeline.from_dict(doc({"type": "normalize", "white_level": 4095.0},
                                  {"type": "crop", "region": "explicit", "rect": [2, 2, 6, 8]}),
                              source="x")
    again = Pipeline.from_yaml(pipe.to_yaml())
    assert again.to_dict() == pipe.to_dict()
    assert again.to_yaml() == pipe.to_yaml()


def test_normalize_and_crop_semantics():
    frame = dn_frame()
    pipe = Pipeline.from_dict(doc({"type": "normalize"},
                                  {"type": "crop", "region": "explicit", "rect": [2, 4, 6, 10]}))
    out = pipe(frame)
    expected = (frame.data[2:6, 4:10] - 64.0) / (1023.0 - 64.0)
    np.testing.assert_allclose(out.data, expected, rtol=0, atol=1e-7)
    assert out.kind == "raw" and out.meta.origin == (2, 4) and out.meta.cfa == "RGGB"
    assert (out.data < 0).any(), "normalisation must keep negatives"


def test_crop_breaking_cfa_phase_is_refused_or_relabelled():
    frame = dn_frame()
    bad = Pipeline.from_dict(doc({"type": "crop", "region": "explicit", "rect": [1, 0, 5, 6]}), source="c.yaml")
    with pytest.raises(SimcamError, match="breaks the CFA phase of RGGB"):
        bad(frame)
    ok = Pipeline.from_dict(doc({"type": "crop", "region": "explicit", "rect": [1, 1, 5, 7], "phase": "update"}))
    assert ok(frame).meta.cfa == "BGGR"


def test_seeded_randomness_is_reproducible_and_per_sample():
    pipe = Pipeline.from_dict(doc({"type": "normalize"}, {"type": "_test_add_uniform", "scale": 0.5}))
    f = dn_frame()
    a = pipe(f, seed=7, epoch=0, index=3).data
    b = pipe(f, seed=7, epoch=0, index=3).data
    c = pipe(f, seed=7, epoch=0, index=4).data
    d = pipe(f, seed=7, epoch=1, index=3).data
    assert a.tobytes() == b.tobytes()
    assert not np.array_equal(a, c) and not np.array_equal(a, d)
    with pytest.raises(PipelineError, match="seed"):
        pipe(f)


def test_overrides():
    pipe = Pipeline.from_dict(doc({"type": "normalize"}, {"type": "_test_add_uniform"}))
    p2 = pipe.with_overrides({"_test_add_uniform.scale": 0.25})
    assert p2.stages[1].params.scale == 0.25
    with pytest.raises(PipelineError, match="has no stage 'gamma'"):
        pipe.with_overrides({"gamma.curve": "srgb"})
    with pytest.raises(PipelineError, match="scale"):
        pipe.with_overrides({"_test_add_uniform.scale": "big"})


def test_build_stage_requires_type():
    with pytest.raises(PipelineError, match="'type' key"):
        build_stage({"method": "x"}, where="stages[0]")


def test_warm_in_background_runs_the_stages_warm_up_and_swallows_its_failure(monkeypatch):
    """Menon 2007's demosaic loads its compiled kernel on a thread while the input is read (numba's
    once-per-process set-up); pipelines without such a stage start no thread; a warm-up that fails is
    left to the stage's own call (no traceback from the thread)."""
    import threading

    from simcam.stages.demosaic import Demosaic

    assert Pipeline.from_yaml("srgb").warm_in_background() is None
    sidd = Pipeline.from_yaml("sidd-srgb")
    t = sidd.warm_in_background()
    assert isinstance(t, threading.Thread) and t.daemon
    t.join(120)
    assert not t.is_alive()
    import numba  # noqa: F401  (imported by the warm-up)

    def boom():
        raise RuntimeError("no compiler here")

    monkeypatch.setattr(Demosaic, "warm_up", lambda self: boom)
    errors = []
    monkeypatch.setattr(threading, "excepthook", lambda args: errors.append(args))
    t = sidd.warm_in_background()
    t.join(30)
    assert errors == []
