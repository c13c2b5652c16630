"""Capture-set reading and bad input."""

import numpy as np
import pytest
import yaml

from loop_generator import SensorSpec, capture_set, write_capture_set
from simcam.calibration.capture import read_capture_set, read_emva1288
from simcam.errors import DatasetError


@pytest.fixture
def small_set(tmp_path):
    caps = capture_set(SensorSpec(height=16, width=16), n_frames=4, flat_levels=(0.3, 0.6), scene=True)
    return write_capture_set(tmp_path / "cap", caps)


def test_reads_directory(small_set):
    np.save(small_set / "scene" / "clean.npy", np.full((16, 16), 300.0, dtype=np.float32))
    cs = read_capture_set(small_set)
    kinds = {s.name: s.kind for s in cs.sequences}
    assert kinds == {"dark": "dark", "flat_0": "flat", "flat_1": "flat", "scene": "scene"}
    s = cs.sequences[0]
    assert s.frames.shape == (4, 16, 16) and s.iso == 800 and s.cfa == "RGGB"
    assert np.all(s.black_dn == 64.0)
    assert cs.group(800)[-1].clean is not None


def test_two_threads_read_the_same_sequences_in_the_same_order(small_set):
    from simcam.calibration.region import Region

    a = read_capture_set(small_set, region=Region(max_size=8), threads=1)
    b = read_capture_set(small_set, region=Region(max_size=8), threads=2)
    assert [s.name for s in a.sequences] == [s.name for s in b.sequences] == ["dark", "flat_0", "flat_1", "scene"]
    for x, y in zip(a.sequences, b.sequences):
        assert np.array_equal(x.frames, y.frames)
        assert x.frames.shape == (4, 8, 8)
        for f in ("pair_mean", "pair_var", "avg_mean", "avg_var", "temporal_var", "frame_means"):
            assert np.array_equal(getattr(x.summary, f), getattr(y.summary, f)), f


def test_two_threads_raise_the_first_failing_sequence_in_directory_order(small_set):
    for name in ("flat_0", "scene"):  # two broken sequences: flat_0 comes first, whichever thread ends first
        for p in sorted((small_set / name).glob("frame_*.npy"))[1:]:
            p.unlink()
    with pytest.raises(DatasetError, match="flat_0: sequence has 1 frame"):
        read_capture_set(small_set, threads=2)


def test_mixed_size_rejected(small_set):
    np.save(small_set / "dark" / "frame_009.npy", np.zeros((16, 18), np.uint16))
    with pytest.raises(DatasetError, match=r"frame_009.npy: frame size 18x16 differs"):
        read_capture_set(small_set)


def test_mixed_cfa_between_sequences_rejected(small_set):
    meta = yaml.safe_load((small_set / "flat_0" / "sequence.yaml").read_text())
    meta["cfa"] = "BGGR"
    (small_set / "flat_0" / "sequence.yaml").write_text(yaml.safe_dump(meta))
    with pytest.raises(DatasetError, match="cfa 'BGGR' differs"):
        read_capture_set(small_set)


def test_single_frame_rejected(small_set):
    for p in sorted((small_set / "flat_1").glob("frame_*.npy"))[1:]:
        p.unlink()
    with pytest.raises(DatasetError, match="flat_1: sequence has 1 frame; expected >= 2"):
        read_capture_set(small_set)


def test_saturated_flat_rejected(small_set):
    for p in (small_set / "flat_1").glob("frame_*.npy"):
        np.save(p, np.full((16, 16), 1023, np.uint16))
    with pytest.raises(DatasetError, match=r"flat_1: flat is saturated \(100.0% of pixels at white level 1023"):
        read_capture_set(small_set)


def test_no_dark_is_noted(small_set):
    import shutil

    shutil.rmtree(small_set / "dark")
    cs = read_capture_set(small_set)
    assert any("no dark sequence" in n for n in cs.notes)


def test_emva_descriptor_parsing(tmp_path):
    import OpenImageIO as oiio

    (tmp_path / "images").mkdir()
    for name in ("a1", "a2", "d1", "d2"):
        out = oiio.ImageOutput.create("png")
        out.open(str(tmp_path / "images" / f"{name}.png"), oiio.ImageSpec(6, 4, 1, oiio.UINT16))
        out.write_image(np.full((4, 6, 1), 100, np.uint16))
        out.close()
    desc = tmp_path / "EMVA1288_Data.txt"
    desc.write_text("# comment\nv 3.0\nn 12 6 4\nb 1000.0 50.0\ni images\\a1.png\ni images\\a2.png\n"
                    "d 1000.0\ni images\\d1.png\ni images\\d2.png\n")
    cs = read_emva1288(desc)
    assert [(s.kind, s.n, s.photons) for s in cs.sequences] == [("flat", 2, 50.0), ("dark", 2, 0.0)]
    assert cs.sequences[0].white_dn == 4095 and cs.sequences[0].exposure_s == pytest.approx(1e-6)
    assert np.all(cs.sequences[0].frames == 100)
    desc.write_text("n 12 6 4\nb 1000.0 50.0\ni images\\a1.png\n")
    with pytest.raises(DatasetError, match="has 1 image"):
        read_emva1288(desc)
    desc.write_text("n 12 8 4\nb 1000.0 50.0\ni images\\a1.png\ni images\\a2.png\n")
    with pytest.raises(DatasetError, match="image size 6x4; expected 8x4"):
        read_emva1288(desc)


def test_cli_bad_input_is_one_line(small_set, tmp_path, capsys):
    from simcam.cli import main

    for p in sorted((small_set / "flat_1").glob("frame_*.npy"))[1:]:
        p.unlink()
    rc = main(["loop", str(small_set), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.count("\n") == 0 and "expected >= 2 frames" in err


def test_reads_dng_sequences(tmp_path):
    from loop_generator import write_capture_set_dng

    caps = capture_set(SensorSpec(height=32, width=32), n_frames=3, flat_levels=(0.4,))
    root = write_capture_set_dng(tmp_path / "cap", caps)
    cs = read_capture_set(root)
    dark = cs.group(800)[0]
    assert dark.name == "dark" and dark.cfa == "RGGB" and dark.exposure_s == pytest.approx(0.01)
    assert np.all(dark.black_dn == 64.0) and dark.white_dn == 1023
    np.testing.assert_array_equal(dark.frames, caps["dark"][1])


def test_mixed_cfa_within_dng_sequence_rejected(tmp_path):
    from simcam.frame import CameraMeta
    from simcam.io.dng_write import write_dng

    d = tmp_path / "cap" / "dark"
    d.mkdir(parents=True)
    for i, cfa in enumerate(("RGGB", "RGGB", "BGGR")):
        write_dng(d / f"f{i}.dng", np.full((32, 32), 64.0, np.float32),
                  CameraMeta(cfa=cfa, black_level=np.full((1, 1), 64.0), white_level=1023.0, iso=100.0))
    with pytest.raises(DatasetError, match="f2.dng: cfa 'BGGR' differs from f0.dng"):
        read_capture_set(tmp_path / "cap")


def test_reads_sidd_style_scene(tmp_path):
    import shutil

    import scipy.io

    from shared_data import shared_path

    md = shared_path("sidd/0001_METADATA_RAW_010.MAT")
    d = tmp_path / "cap" / "0001_001_S6_00100_00060_3200_L"
    d.mkdir(parents=True)
    shutil.copy(md, d / "0001_METADATA_RAW_010.MAT")  # into the test's temp dir only
    rng = np.random.default_rng(0)
    gt = np.full((32, 32), 0.25)
    for k in ("010", "011"):
        scipy.io.savemat(d / f"0001_NOISY_RAW_{k}.MAT", {"x": gt + rng.normal(0, 0.01, gt.shape)})
    scipy.io.savemat(d / "0001_GT_RAW_010.MAT", {"x": gt})
    cs = read_capture_set(tmp_path / "cap")
    s = cs.sequences[0]
    assert s.kind == "scene" and s.n == 2 and s.cfa == "GRBG" and s.iso == 100
    np.testing.assert_allclose(s.clean, 0.25 * 1023.0)
    assert s.frames.std() == pytest.approx(0.01 * 1023, rel=0.1)
