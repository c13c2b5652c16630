"""``simcam synth`` and ``simcam profile``: outputs, determinism, one-line errors."""

import json

import numpy as np
import pytest
import tifffile

from simcam.cli import main
from simcam.io.dng import read_dng, read_dng_meta
from simcam.io.sample_dng import make_test_dng
from simcam.noise.noise_profile import noise_profile_site_values
from simcam.profiles.importers import import_darktable
from simcam.pipeline import Pipeline
from simcam.profiles.schema import load_profile
from simcam.stages.raw import Normalize

PROFILE = "profiles/sidd-gp.yaml"


def _norm(path):
    return Normalize()(read_dng(path)).data


def test_synth_from_float_tiff_is_deterministic_and_matches_pipeline(tmp_path, capsys):
    clean = np.tile(np.linspace(0.05, 0.8, 48, dtype=np.float32), (32, 1))
    src = tmp_path / "clean.tif"
    tifffile.imwrite(src, clean)
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    for out, seed in ((a, 3), (b, 3), (c, 4)):
        assert main(["synth", str(src), "-o", str(out), "--profile", PROFILE, "--iso", "800", "--frames", "2",
                     "--seed", str(seed), "--cfa", "GRBG"]) == 0
    assert sorted(p.name for p in a.iterdir()) == ["clean.dng", "frame_000.dng", "frame_001.dng"]
    for name in ("frame_000.dng", "frame_001.dng"):
        assert (a / name).read_bytes() == (b / name).read_bytes()
        assert (a / name).read_bytes() != (c / name).read_bytes()
    meta = read_dng_meta(a / "frame_001.dng")
    assert meta.cfa == "GRBG" and meta.iso == 800
    np.testing.assert_allclose(meta.noise_profile, [[1.764e-3, 1.2e-5]])
    # clean.dng holds the input (16-bit quantised: |error| <= 0.5 DN)
    np.testing.assert_allclose(_norm(a / "clean.dng"), clean, atol=0.5 / (65535 - 1024) + 1e-7)
    # frame i == the noise pipeline at seed, epoch 0, index i (then DN-quantised the same way)
    from simcam.frame import RawFrame

    clean_frame = RawFrame(clean, read_dng_meta(a / "clean.dng"), kind="raw")
    pipe = Pipeline.from_dict({"version": 1, "input": "raw", "stages": [{"type": "noise", "profile": PROFILE, "iso": 800.0}]})
    expect = pipe(clean_frame, seed=3, index=1).data
    got = _norm(a / "frame_001.dng")
    assert np.abs(got - expect).max() <= 0.5 / (65535 - 1024) + 1e-6


def test_synth_linear_srgb_and_dng_input(tmp_path):
    rgb = np.zeros((16, 16, 3), np.uint16)
    rgb[..., 0], rgb[..., 1], rgb[..., 2] = 10000, 20000, 30000
    src = tmp_path / "rgb.tif"
    tifffile.imwrite(src, rgb)
    out = tmp_path / "o"
    assert main(["synth", str(src), "-o", str(out), "--profile", PROFILE, "--iso", "100", "--as", "linear-srgb"]) == 0
    meta = read_dng_meta(out / "clean.dng")
    assert meta.calibration_illuminant1 == 21 and np.allclose(meta.as_shot_neutral, 1)
    c = _norm(out / "clean.dng")
    np.testing.assert_allclose(c[0::2, 0::2], 10000 / 65535, atol=1e-4)  # R site of RGGB
    np.testing.assert_allclose(c[1::2, 1::2], 30000 / 65535, atol=1e-4)  # B site
    dng = make_test_dng(tmp_path / "in.dng", 32, 32, cfa="BGGR")
    out2 = tmp_path / "o2"
    assert main(["synth", str(dng), "-o", str(out2), "--profile", PROFILE, "--iso", "400"]) == 0
    m = read_dng_meta(out2 / "frame_000.dng")
    assert m.cfa == "BGGR" and m.iso == 400 and m.color_matrix1 is not None


@pytest.mark.parametrize("args,msg", [
    (["--iso", "12800"], "outside the calibrated range"),
    (["--iso", "800", "--camera", "XX"], "unknown camera 'XX'"),
    (["--iso", "800", "--as", "srgb"], "--as"),
])
def test_synth_errors_one_line(tmp_path, capsys, args, msg):
    src = tmp_path / "c.tif"
    tifffile.imwrite(src, np.zeros((8, 8), np.float32))
    assert main(["synth", str(src), "-o", str(tmp_path / "o"), "--profile", PROFILE, *args]) == 2
    err = capsys.readouterr().err.strip()
    assert msg in err and "\n" not in err


def test_synth_rejects_negative_clean(tmp_path, capsys):
    src = tmp_path / "c.tif"
    tifffile.imwrite(src, np.full((8, 8), -0.1, np.float32))
    assert main(["synth", str(src), "-o", str(tmp_path / "o"), "--profile", PROFILE, "--iso", "800"]) == 2
    assert ">= 0" in capsys.readouterr().err


def _fake_darktable(path):
    doc = {"version": 0, "noiseprofiles": [{"maker": "Acme", "models": [{"model": "Cam 1", "comment": "test", "profiles": [
        {"name": "a", "iso": 100, "a": [3e-5, 1e-5, 2e-5], "b": [1e-7, 2e-7, -1e-8]},
        {"name": "b", "iso": 400, "a": [1.2e-4, 4e-5, 8e-5], "b": [4e-7, 8e-7, 6e-7]},
        {"name": "c", "iso": 400, "a": [1.4e-4, 4e-5, 8e-5], "b": [4e-7, 8e-7, 6e-7]}]}]}]}
    path.write_text(json.dumps(doc))
    return path


def test_import_darktable_maps_colours_to_sites(tmp_path, capsys):
    src = _fake_darktable(tmp_path / "np.json")
    prof = import_darktable(src, "acme cam 1", cfa="GBRG")
    m = prof.model_for(100)
    assert m.beta1 == [1e-5, 2e-5, 3e-5, 1e-5]  # G B R G
    assert m.beta2 == [2e-7, 0.0, 1e-7, 2e-7]  # negative b clamped (noted in provenance)
    assert prof.model_for(400).beta1[2] == pytest.approx(1.3e-4)  # repeated ISO averaged
    assert "negative b" in prof.provenance.notes and "averaged" in prof.provenance.notes
    out = tmp_path / "p.yaml"
    assert main(["profile", "import-darktable", str(src), "--camera", "Acme Cam 1", "-o", str(out)]) == 0
    assert load_profile(out).model_for(200).type == "nlf"
    assert main(["profile", "import-darktable", str(src), "--camera", "Acme Cam 2"]) == 2
    assert "no camera 'Acme Cam 2'" in capsys.readouterr().err


def test_import_real_darktable_file(shared_file):
    prof = import_darktable(shared_file("noise_params/darktable_noiseprofiles.json"), "Sony ILCE-7M3")
    cam = prof.cameras[0]
    assert cam.iso_range == (50.0, 204800.0) and prof.model_for(3200).beta1[1] == pytest.approx(2.89964065532241e-05)


def test_profile_from_dng(tmp_path, capsys):
    dng = make_test_dng(tmp_path / "x.dng", 32, 32, cfa="GRBG", iso=250.0,
                        noise_profile=np.array([[1e-4, 1e-6], [2e-4, 2e-6], [3e-4, 3e-6]]))
    out = tmp_path / "p.yaml"
    assert main(["profile", "from-dng", str(dng), "-o", str(out)]) == 0
    m = load_profile(out).model_for(250)
    assert m.beta1 == [2e-4, 1e-4, 3e-4, 2e-4]  # G R B G
    nodng = make_test_dng(tmp_path / "y.dng", 32, 32, minimal=True)
    assert main(["profile", "from-dng", str(nodng)]) == 2
    assert "NoiseProfile" in capsys.readouterr().err
    with pytest.raises(Exception, match="expected 1 or 3"):
        noise_profile_site_values(np.ones((2, 2)), "RGGB")


def test_profile_show(capsys):
    assert main(["profile", "show", PROFILE]) == 0
    assert "GP: Google Pixel" in capsys.readouterr().out
    assert main(["profile", "show", PROFILE, "--iso", "1131"]) == 0
    assert "type: nlf" in capsys.readouterr().out
