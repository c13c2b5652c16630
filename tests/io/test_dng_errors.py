"""Bad inputs: one-line DngError naming file and field; inputs never modified; CLI exits 2."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import tifffile

from shared_data import REPO, shared_path
from dng_fixtures import file_sha256, make_dng  # noqa: F401  (fixture)
from simcam.cli import main
from simcam.errors import DngError
from simcam.io.dng import read_dng, read_dng_meta


def _assert_one_line(exc: pytest.ExceptionInfo, path, field: str):
    msg = str(exc.value)
    assert "\n" not in msg
    assert str(path) in msg and field in msg


@pytest.mark.shared_data
def test_truncated_pixel_data():
    path = shared_path("dng/canon_350d_truncated_pixels.dng")
    before = file_sha256(path)
    for reader in (read_dng, read_dng_meta):
        with pytest.raises(DngError, match="truncated") as exc:
            reader(path)
        _assert_one_line(exc, path, "TileByteCounts")
    assert file_sha256(path) == before


def test_truncated_strip_of_a_written_file(make_dng, tmp_path):  # noqa: F811
    src = make_dng("ok.dng", 32, 32)
    cut = tmp_path / "cut.dng"
    cut.write_bytes(src.read_bytes()[:-100])
    with pytest.raises(DngError, match="truncated") as exc:
        read_dng(cut)
    _assert_one_line(exc, cut, "StripByteCounts")


@pytest.mark.shared_data
def test_vc5_compressed_gpr():
    path = shared_path("dng/gopro_hero7_vc5_compressed.gpr")
    before = file_sha256(path)
    with pytest.raises(DngError, match="Compression: 9") as exc:
        read_dng(path)
    _assert_one_line(exc, path, "not supported")
    assert file_sha256(path) == before


def test_plain_tiff(tmp_path):
    path = tmp_path / "plain.tif"
    tifffile.imwrite(path, np.zeros((8, 8), np.uint16))
    with pytest.raises(DngError, match="plain TIFF") as exc:
        read_dng(path)
    _assert_one_line(exc, path, "DNGVersion")


def test_linear_raw_dng(tmp_path):
    path = tmp_path / "linear.dng"
    tifffile.imwrite(path, np.zeros((8, 8, 3), np.uint16), photometric=34892,
                     extratags=[(50706, 1, 4, b"\x01\x04\x00\x00", True)])
    with pytest.raises(DngError, match="non-Bayer DNG not supported") as exc:
        read_dng(path)
    _assert_one_line(exc, path, "PhotometricInterpretation")


def test_dng_without_color_matrix_reads(make_dng):  # noqa: F811
    path = make_dng("nocm.dng", minimal=True)
    frame = read_dng(path)
    assert frame.meta.color_matrix1 is None and frame.meta.color_matrix2 is None
    assert frame.meta.forward_matrix1 is None and frame.meta.as_shot_neutral is None


def test_missing_file_directory_and_garbage(tmp_path):
    with pytest.raises(DngError, match="no such file") as exc:
        read_dng(tmp_path / "missing.dng")
    _assert_one_line(exc, tmp_path / "missing.dng", "no such file")
    with pytest.raises(DngError, match="is a directory"):
        read_dng(tmp_path)
    junk = tmp_path / "junk.dng"
    junk.write_bytes(b"hello, not a tiff at all")
    with pytest.raises(DngError, match="not a TIFF/DNG") as exc:
        read_dng_meta(junk)
    _assert_one_line(exc, junk, "not a TIFF")


def test_bad_cfa_pattern(tmp_path, make_dng):  # noqa: F811
    """Patch CFAPattern to R R G B (not Bayer) in a written file."""
    path = make_dng("bad.dng", 24, 24, cfa="RGGB")
    raw = bytearray(path.read_bytes())
    with tifffile.TiffFile(str(path)) as tif:
        tag = tif.pages[0].tags[33422]
        offset = tag.valueoffset
    raw[offset:offset + 4] = bytes([0, 0, 1, 2])
    bad = tmp_path / "patched.dng"
    bad.write_bytes(bytes(raw))
    with pytest.raises(DngError, match="CFAPattern") as exc:
        read_dng(bad)
    _assert_one_line(exc, bad, "expected one of")


@pytest.mark.shared_data
def test_cli_info_bad_file_in_process(capsys):
    path = shared_path("dng/gopro_hero7_vc5_compressed.gpr")
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("simcam info: error:") and "Compression" in err[0]


def test_cli_info_bad_inputs(tmp_path, capsys):
    (tmp_path / "x.tif").write_bytes(b"II*\x00garbage")
    for bad in (tmp_path / "missing.dng", tmp_path, tmp_path / "x.tif"):
        assert main(["info", str(bad)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and str(bad) in err[0]


@pytest.mark.shared_data
def test_cli_info_subprocess_exit_code():
    path = shared_path("dng/canon_350d_truncated_pixels.dng")
    before = file_sha256(path)
    proc = subprocess.run([sys.executable, "-m", "simcam", "info", str(path)], cwd=REPO,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "canon_350d_truncated_pixels.dng" in lines[0] and "truncated" in lines[0]
    assert file_sha256(path) == before


def test_cli_info_good_file(make_dng, capsys):  # noqa: F811
    path = make_dng("good.dng", 24, 24, cfa="GBRG")
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "cfa: \"GBRG\"" in out and "noise_profile" in out


def test_a_python_warning_inside_rawpy_is_not_read_as_a_libraw_error(make_dng):  # noqa: F811
    """rawpy warns (a Python RuntimeWarning on stderr) when used in a fork-started process, as in a
    multiprocessing.Pool: that is about the process, not the file, so the file still reads. Run in a
    subprocess so the warning reaches the real stderr (pytest would record it)."""
    path = make_dng("warned.dng", 64, 64)  # large enough for LibRaw (not the tiny-file fallback)
    code = (
        "import sys, warnings, rawpy\n"
        "from simcam.io.dng import read_dng\n"
        "orig = rawpy.imread\n"
        "def imread(*a, **k):\n"
        "    warnings.warn('rawpy is being used in a process created by multiprocessing', RuntimeWarning)\n"
        "    return orig(*a, **k)\n"
        "rawpy.imread = imread\n"
        f"print(read_dng({str(path)!r}).data.shape)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "(64, 64)" and r.stderr == ""
