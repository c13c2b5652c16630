"""The fused display tail (simcam.render_samples, simcam.colour.display_kernel) against references:
the IEC 61966-2-1 curve in float64 (closed form) on random data, and the stage-by-stage
render quantised with numpy on the bundled example and the shared DNGs (at most one code apart)."""

from __future__ import annotations

import numpy as np
import pytest
from shared_data import REPO, shared_path

from simcam.colour.display_kernel import encode_display, quantise
from simcam.io.dng import read_dng
from simcam.pipeline import Pipeline
from simcam.render_samples import fusable_tail, render_samples

EXAMPLE = REPO / "examples" / "data" / "chart.dng"
SHARED_DNGS = ["gopro_hero7_iso252", "canon_550d_colorchecker"]


def srgb64(x):
    x = np.asarray(x, np.float64)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.abs(x) ** (1 / 2.4) - 0.055)


def _random(seed=0, shape=(301, 257, 3)):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-0.1, 1.3, shape).astype(np.float32)
    n = min(40, shape[1])
    x[0, :n, 0] = np.linspace(0, 0.004, n, dtype=np.float32)  # around the linear/power joint
    return x


M = np.array([[1.3, -0.2, -0.1], [-0.1, 1.2, -0.1], [0.05, -0.25, 1.2]])


@pytest.mark.parametrize("depth", ["uint8", "uint16"])
def test_encode_display_within_one_code_of_the_curve(depth):
    x = _random()
    top = 255 if depth == "uint8" else 65535
    out = encode_display(x, M, lo=0.0, hi=1.0, depth=depth)
    lin = np.clip(x.astype(np.float64) @ M.T, 0, 1)
    exact = srgb64(lin) * top
    assert out.dtype == depth
    assert np.abs(out - exact).max() <= 0.5 + 1.0  # rounding plus at most one code
    # one code only where the exact value lies next to a code boundary
    off = out != np.round(exact)
    assert off.mean() < (1e-3 if depth == "uint8" else 3e-2)
    # the table's error bound: half a step of 2^16 (8-bit) or 2^20 (16-bit) at the steepest slope, 12.92
    bound = 12.92 * top / (2 * (1 << 16 if depth == "uint8" else 1 << 20))
    assert np.all(np.abs(exact[off] - np.floor(exact[off]) - 0.5) < bound + 1e-3)


@pytest.mark.parametrize("depth", ["uint8", "uint16"])
def test_code_table_equals_its_definition(depth):
    # the table is built from where each code begins; every entry must equal the curve at its grid point
    from simcam.colour.display_kernel import code_table, table_steps

    n, top = table_steps(depth), (255 if depth == "uint8" else 65535)
    x = np.arange(n + 1, dtype=np.float64) / n
    y = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(np.maximum(x, 0.0031308), 1 / 2.4) - 0.055)
    np.testing.assert_array_equal(code_table(depth), np.round(np.clip(y, 0, 1) * top).astype(depth))


def test_encode_display_float_and_linear():
    x = _random(1)
    y = encode_display(x, M, lo=None, hi=None, depth="float32")
    lin = x.astype(np.float64) @ M.T
    ref = np.where(lin < 0, 12.92 * lin, srgb64(np.maximum(lin, 0)))
    np.testing.assert_allclose(y, ref, atol=2e-6, rtol=2e-6)
    yl = encode_display(x, M, lo=0.0, hi=None, curve="linear", depth="float32")
    np.testing.assert_allclose(yl, np.maximum(lin, 0), atol=1e-6, rtol=1e-6)
    q = encode_display(x, M, lo=0.0, hi=None, curve="linear", depth="uint16")
    assert np.abs(q - np.clip(lin, 0, 1) * 65535).max() <= 0.5 + 0.02


@pytest.mark.parametrize("depth", ["uint8", "uint16", "float32"])
def test_encode_display_same_bytes_for_any_thread_count(depth, monkeypatch):
    x = _random(2, (513, 129, 3))
    outs = []
    for t in ("1", "2", "5"):
        monkeypatch.setenv("SIMCAM_THREADS", t)
        outs.append(encode_display(x, M, lo=0.0, hi=1.0, depth=depth).tobytes())
        outs.append(quantise(x, "uint16").tobytes())
    assert outs[0::2] == [outs[0]] * 3 and outs[1::2] == [outs[1]] * 3


def test_encode_display_rejects_nan():
    x = _random(3, (4, 5, 3))
    x[2, 3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        encode_display(x, M, depth="uint8")


def test_quantise_matches_numpy():
    x = _random(4).reshape(-1)
    for depth, top in (("uint8", 255), ("uint16", 65535)):
        assert np.array_equal(quantise(x, depth), np.round(np.clip(x, 0, 1) * np.float32(top)).astype(depth))


def test_fusable_tail_of_builtin_pipelines():
    srgb = Pipeline.from_yaml("srgb")
    types = [s.type for s in srgb.stages[fusable_tail(srgb.stages):]]
    assert types == ["camera_to_xyz", "xyz_to_srgb", "tone", "clip", "gamma", "orientation"]
    filmic = srgb.with_overrides({"tone.curve": "filmic"})
    assert [s.type for s in filmic.stages[fusable_tail(filmic.stages):]] == []
    sidd = Pipeline.from_yaml("sidd-srgb")  # power gamma + smoothstep: not fused
    assert fusable_tail(sidd.stages) == len(sidd.stages)


def _check_pipeline_on(frame, name, overrides=None):
    pipe = Pipeline.from_yaml(name)
    if overrides:
        pipe = pipe.with_overrides(overrides)
    for depth in ("uint8", "uint16"):
        fused = render_samples(pipe, frame, depth)
        ref_frame = pipe(frame)
        top = 255 if depth == "uint8" else 65535
        ref = np.round(np.clip(ref_frame.data, 0, 1) * top)
        assert fused.samples.shape == ref.shape and fused.kind == ref_frame.kind
        assert np.abs(fused.samples - ref).max() <= 1
        # 8-bit: rare one-code differences; 16-bit: the 2^20-step table moves values that lie
        # within 0.4 code of a rounding boundary (a few per cent), never by more than one code
        assert (fused.samples != ref).mean() < (1e-2 if depth == "uint8" else 0.1)


@pytest.mark.parametrize("name,overrides", [("srgb", None), ("linear-srgb", None),
                                            ("srgb", {"tone.exposure": 0.5, "orientation.value": 6})])
def test_fused_render_matches_stage_by_stage_on_example(name, overrides):
    _check_pipeline_on(read_dng(EXAMPLE), name, overrides)


@pytest.mark.shared_data
@pytest.mark.parametrize("dng", SHARED_DNGS)
def test_fused_render_matches_stage_by_stage_on_shared(dng):
    frame = read_dng(shared_path(f"dng/{dng}.dng"))
    _check_pipeline_on(frame, "srgb")


def test_banded_tail_of_pipelines():
    from simcam.render_samples import banded_tail

    sidd = Pipeline.from_yaml("sidd-srgb")
    assert [s.type for s in sidd.stages[banded_tail(sidd.stages):]] == [
        "camera_to_xyz", "clip", "xyz_to_srgb", "clip", "orientation", "gamma", "tone"]
    filmic = Pipeline.from_yaml("srgb").with_overrides({"tone.curve": "filmic"})
    assert next(s.type for s in filmic.stages[banded_tail(filmic.stages):]) == "camera_to_xyz"


@pytest.mark.parametrize("name,overrides", [("sidd-srgb", None), ("srgb", {"tone.curve": "filmic", "tone.exposure": 1.0}),
                                            ("sidd-srgb", {"orientation.value": 5})])
@pytest.mark.parametrize("depth", ["uint8", "uint16", "float32"])
def test_banded_render_equals_stage_by_stage(name, overrides, depth, monkeypatch):
    pipe = Pipeline.from_yaml(name)
    if overrides:
        pipe = pipe.with_overrides(overrides)
    frame = read_dng(EXAMPLE)
    ref = pipe(frame)
    if depth == "float32":
        expect = ref.data
    else:
        top = 255 if depth == "uint8" else 65535
        expect = np.round(np.clip(ref.data, 0, 1) * np.float32(top)).astype(depth)
    outs = []
    for t in ("1", "2"):
        monkeypatch.setenv("SIMCAM_THREADS", t)
        r = render_samples(pipe, frame, depth)
        outs.append(r.samples.tobytes())
        assert r.kind == ref.kind and r.samples.shape == expect.shape and r.meta.orientation == ref.meta.orientation
        # the same stage code on the same pixels: equal up to the 3x3 products' float32 rounding
        assert np.abs(r.samples.astype(float) - expect).max() <= (1 if depth != "float32" else 1e-6)
        assert (r.samples != expect).mean() < 1e-3
    assert outs[0] == outs[1]


def test_render_samples_on_a_raw_pipeline():
    pipe = Pipeline.from_dict({"version": 1, "stages": [{"type": "normalize"}, {"type": "clip", "low": 0.0, "high": 1.0}]})
    frame = read_dng(EXAMPLE)
    r = render_samples(pipe, frame, "uint16")
    ref = pipe(frame)
    assert r.kind == ref.kind and np.array_equal(r.samples, np.round(np.clip(ref.data, 0, 1) * np.float32(65535)))


def _streamed_pipeline(method, rect, orientation=1):
    return Pipeline.from_dict({"version": 1, "name": "streamed", "stages": [
        {"type": "normalize"}, {"type": "white_balance", "source": "as_shot"}, {"type": "clip", "low": None, "high": 1.0},
        {"type": "demosaic", "method": method}, {"type": "opcodes", "list": 3},
        {"type": "crop", "region": "explicit", "rect": list(rect)},
        {"type": "camera_to_xyz"}, {"type": "xyz_to_srgb"}, {"type": "clip", "low": 0.0, "high": 1.0},
        {"type": "gamma", "curve": "srgb"}, {"type": "orientation", "value": orientation}]}, source="<test>")


@pytest.mark.parametrize("method", ["malvar2004", "bilinear", "menon2007"])
@pytest.mark.parametrize("threads", ["1", "2"])
def test_streamed_demosaic_equals_the_stage_by_stage_frame_byte_for_byte(method, threads, monkeypatch):
    """The demosaic's strips go straight into the display tail (render_demosaic_tail): the samples are
    those of the fused tail on the frame the stages make one by one (same kernels, same pixels), for
    an odd-sized mosaic, a crop at odd offsets cutting strips, orientation, any thread count."""
    from simcam.frame import RawFrame
    from simcam.render_samples import render_tail, streamed_demosaic

    monkeypatch.setenv("SIMCAM_THREADS", threads)
    full = read_dng(EXAMPLE)
    frame = RawFrame(full.data[:97, :131], full.meta, kind="raw_dn")  # odd height and width
    pipe = _streamed_pipeline(method, (5, 3, 90, 128), orientation=6)
    start = fusable_tail(pipe.stages)
    assert streamed_demosaic(pipe.stages, start) == 3  # the demosaic stage
    for depth in ("uint8", "uint16", "float32"):
        got = render_samples(pipe, frame, depth)
        ref_frame = frame
        for st in pipe.stages[:start]:
            ref_frame = st(ref_frame)
        ref = render_tail(pipe.stages[start:], ref_frame, depth)
        assert got.samples.dtype == ref.samples.dtype and got.samples.shape == ref.samples.shape == (125, 85, 3)
        assert got.samples.tobytes() == ref.samples.tobytes()
        assert got.kind == ref.kind and got.meta.origin == ref.meta.origin and got.meta.orientation == 1


def test_streamed_demosaic_errors_and_opcode_fallback():
    """A NaN in the mosaic is one ImageIOError naming the file; a crop outside the frame is the crop's
    own StageError; a list-3 opcode list in the file makes the stages run one by one (same samples)."""
    from simcam.errors import ImageIOError, StageError
    from simcam.frame import RawFrame

    full = read_dng(EXAMPLE)
    data = full.data.copy()
    data[40, 50] = np.nan
    with pytest.raises(ImageIOError, match="chart.dng: image data contains NaN or infinite values"):
        render_samples(_streamed_pipeline("malvar2004", (0, 0, 64, 64)), RawFrame(data, full.meta, kind="raw_dn"),
                       "uint8")
    with pytest.raises(StageError, match=r"crop \(explicit\) rect \[0, 0, 9999, 64\] is outside"):
        render_samples(_streamed_pipeline("malvar2004", (0, 0, 9999, 64)), full, "uint8")
    pipe = _streamed_pipeline("bilinear", (2, 2, 60, 70))
    plain = render_samples(pipe, full, "uint16")
    meta = full.meta.copy()
    meta.opcode_list3 = [object()]  # stands for a list the file holds: the stage would have to apply it
    seen = []

    class Opcodes3:  # the opcodes stage, run on the whole image (not streamed) and leaving the pixels as they are
        type = "opcodes"

        def __init__(self, st):
            self.st, self.params = st, st.params

        def __call__(self, frame, rng=None):
            seen.append(frame.data.shape)
            return frame.evolve(step="opcodes3")

        def __getattr__(self, name):
            return getattr(self.st, name)

    stages = list(pipe.stages)
    stages[4] = Opcodes3(stages[4])
    pipe.stages = stages
    again = render_samples(pipe, RawFrame(full.data, meta, kind="raw_dn"), "uint16")
    assert seen == [full.data.shape[:2] + (3,)]  # it got the whole demosaiced image
    assert again.samples.tobytes() == plain.samples.tobytes()


@pytest.mark.parametrize("threads", ["1", "2"])
@pytest.mark.parametrize("orientation", [1, 5])
def test_demosaic_streamed_into_a_banded_tail_equals_the_banded_render_byte_for_byte(threads, orientation, monkeypatch):
    """sidd-srgb's Menon 2007 hands its bands straight to the per-pixel tail (render_demosaic_banded):
    the samples are render_banded's on the demosaicked frame, byte for byte, for an odd-sized mosaic
    taller than several of the demosaic's bands, any thread count; a NaN is one ImageIOError."""
    from simcam.demosaic.menon2007 import BAND
    from simcam.errors import ImageIOError
    from simcam.frame import RawFrame
    from simcam.render_samples import banded_tail, render_banded

    monkeypatch.setenv("SIMCAM_THREADS", threads)
    frame = read_dng(EXAMPLE)
    pipe = Pipeline.from_yaml("sidd-srgb").with_overrides({  # an odd-sized crop, 397 x 597
        "crop.region": "explicit", "crop.rect": [2, 2, 399, 599], "orientation.convention": "exif",
        "orientation.value": orientation})
    assert 397 > 3 * BAND
    start = banded_tail(pipe.stages)
    assert pipe.stages[start - 1].type == "demosaic" and pipe.stages[start - 1].params.method == "menon2007"
    for depth in ("uint8", "uint16", "float32"):
        got = render_samples(pipe, frame, depth)
        ref_frame = frame
        for st in pipe.stages[:start]:
            ref_frame = st(ref_frame)
        ref = render_banded(pipe.stages[start:], ref_frame, depth)
        assert got.samples.dtype == ref.samples.dtype and got.samples.shape == ref.samples.shape
        assert got.samples.tobytes() == ref.samples.tobytes()
        assert got.kind == ref.kind and got.meta.orientation == ref.meta.orientation == 1
    data = frame.data.copy()
    data[BAND + 4, 17] = np.nan
    with pytest.raises(ImageIOError, match="chart.dng: image data contains NaN or infinite values"):
        render_samples(pipe, RawFrame(data, frame.meta, kind="raw_dn"), "uint8")
