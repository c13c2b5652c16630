"""End-to-end rendering: every shipped pipeline on the bundled example and on every
readable shared DNG; bad inputs through ``simcam render`` give one line, exit 2, no output."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from shared_data import REPO, shared_path
from simcam.cli import main
from simcam.io.dng import read_dng
from simcam.io.images import read_image
from simcam.pipeline import Pipeline, builtin_pipelines

EXAMPLE = REPO / "examples" / "data" / "chart.dng"
SHARED_DNGS = ["gopro_hero7_iso252", "gopro_hero6_iso100", "gopro_fusion_front_iso100", "canon_550d_colorchecker"]
BAD_INPUTS = ["canon_350d_truncated_pixels.dng", "gopro_hero7_vc5_compressed.gpr"]


def sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_builtin_pipelines_are_shipped():
    assert {"srgb", "linear-srgb", "sidd-srgb"} <= set(builtin_pipelines())


@pytest.mark.parametrize("pipeline", ["srgb", "linear-srgb", "sidd-srgb"])
def test_render_bundled_example(pipeline, tmp_path):
    out = tmp_path / ("o.exr" if pipeline == "linear-srgb" else "o.png")
    assert main(["render", str(EXAMPLE), "-o", str(out), "-p", pipeline]) == 0
    img = read_image(out)
    assert img.shape == (400, 600, 3)
    assert np.isfinite(img).all()
    # The synthetic chart's grey surround is neutral after white balance + colour (|R-B| small).
    surround = img[5:30, 5:30].reshape(-1, 3).mean(0)
    assert abs(surround[0] - surround[2]) < 0.02 * surround[1] + 0.01, surround


def centre_crop_pipeline(name: str, frame, size=256) -> Pipeline:
    """The shipped pipeline with an even-offset centre crop inserted after normalize
    (keeps the real metadata path, at test cost)."""
    doc = Pipeline.from_yaml(name).to_dict()
    t, l, b, r = frame.meta.active_area or (0, 0, frame.height, frame.width)
    cy, cx = ((t + b) // 2) & ~1, ((l + r) // 2) & ~1
    crop = {"type": "crop", "region": "explicit", "rect": [cy - size // 2, cx - size // 2, cy + size // 2, cx + size // 2]}
    stages = [n for n in doc["stages"] if not (n["type"] == "crop")]
    doc["stages"] = [stages[0], crop] + stages[1:]
    return Pipeline.from_dict(doc, source=f"{name} (centre crop)")


@pytest.mark.shared_data
@pytest.mark.parametrize("pipeline", ["srgb", "linear-srgb", "sidd-srgb"])
@pytest.mark.parametrize("name", SHARED_DNGS)
def test_shared_dngs_render_with_every_pipeline(name, pipeline):
    path = shared_path(f"dng/{name}.dng")
    frame = read_dng(path)
    out = centre_crop_pipeline(pipeline, frame)(frame)
    assert out.data.shape[2] == 3 and np.isfinite(out.data).all()
    assert out.kind == ("linear_srgb" if pipeline == "linear-srgb" else "display")
    if pipeline != "linear-srgb":
        assert out.data.min() >= 0 and out.data.max() <= 1


@pytest.mark.slow
@pytest.mark.shared_data
@pytest.mark.parametrize("pipeline", ["srgb", "linear-srgb", "sidd-srgb"])
@pytest.mark.parametrize("name", SHARED_DNGS)
def test_shared_dngs_full_render(name, pipeline, tmp_path):
    path = shared_path(f"dng/{name}.dng")
    out = tmp_path / ("o.exr" if pipeline == "linear-srgb" else "o.png")
    assert main(["render", str(path), "-o", str(out), "-p", pipeline]) == 0
    assert out.exists()


@pytest.mark.shared_data
@pytest.mark.parametrize("bad", BAD_INPUTS)
def test_render_bad_dng_one_line_exit_2_no_output(bad, tmp_path, capsys):
    path = shared_path(f"dng/{bad}")
    before = sha(path)
    out = tmp_path / "o.png"
    assert main(["render", str(path), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and bad in err and "Traceback" not in err
    assert not out.exists() and not list(tmp_path.iterdir())
    assert sha(path) == before


def test_render_missing_color_matrix_names_field(tmp_path, capsys):
    from simcam.io.sample_dng import make_test_dng

    dng = make_test_dng(tmp_path / "nocm.dng", 32, 32, minimal=True, as_shot_neutral=np.array([0.5, 1.0, 0.6]))
    out = tmp_path / "o.png"
    assert main(["render", str(dng), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "ColorMatrix1" in err and "nocm.dng" in err and err.count("\n") == 0
    assert not out.exists()


def test_render_refuses_to_overwrite_input(tmp_path, capsys):
    import shutil

    src = tmp_path / "in.dng"
    shutil.copy(EXAMPLE, src)
    before = sha(src)
    # A TIFF output named like the input: refused before anything is written.
    assert main(["render", str(src), "-o", str(src), "--depth", "16"]) == 2
    assert sha(src) == before


def test_render_set_override_changes_white_balance(tmp_path):
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    assert main(["render", str(EXAMPLE), "-o", str(a), "-p", "linear-srgb"]) == 0
    assert main(["render", str(EXAMPLE), "-o", str(b), "-p", "linear-srgb",
                 "--set", "white_balance.source=gains", "--set", "white_balance.gains=[1.0,1.0,1.0]"]) == 0
    assert not np.allclose(read_image(a), read_image(b))


def test_render_bad_override_is_one_line(tmp_path, capsys):
    out = tmp_path / "o.png"
    assert main(["render", str(EXAMPLE), "-o", str(out), "--set", "gamma.curve=cubic"]) == 2
    err = capsys.readouterr().err.strip()
    assert "gamma" in err and "curve" in err and err.count("\n") == 0 and not out.exists()



def test_render_neutral_override_on_default_pipeline(tmp_path):
    """The documented example: an explicit neutral overrides the pipeline's as-shot white."""
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    assert main(["render", str(EXAMPLE), "-o", str(a)]) == 0
    assert main(["render", str(EXAMPLE), "-o", str(b), "--set", "white_balance.neutral=[0.66,1.0,0.44]"]) == 0
    ia, ib = read_image(a), read_image(b)
    # neutral (0.66, 1, 0.44) vs the file's (0.42, 1, 0.72): less red gain, more blue gain
    assert ib[..., 0].mean() < ia[..., 0].mean() and ib[..., 2].mean() > ia[..., 2].mean()


def test_white_balance_contradictions_are_refused():
    from simcam.errors import PipelineError

    with pytest.raises(PipelineError, match="not both"):
        Pipeline.from_dict({"version": 1, "input": "raw", "stages": [
            {"type": "white_balance", "neutral": [1.0, 1.0, 1.0], "gains": [1.0, 1.0, 1.0]}]})
    with pytest.raises(PipelineError, match="source: none"):
        Pipeline.from_dict({"version": 1, "input": "raw", "stages": [
            {"type": "white_balance", "source": "none", "gains": [1.0, 1.0, 1.0]}]})
