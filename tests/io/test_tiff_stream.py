"""Uncompressed TIFF outputs written strip by strip during the render (simcam.io.tiff_stream): the same
file bytes as the in-memory render written by write_image, tags read back with tifffile, and nothing
left behind on a failure."""

from __future__ import annotations

import numpy as np
import pytest
from shared_data import REPO, shared_path

from simcam.errors import ImageIOError
from simcam.io.dng import read_dng
from simcam.io.images import write_image
from simcam.io.tiff_stream import TiffStream
from simcam.jobs import render_file
from simcam.pipeline import Pipeline
from simcam.render_samples import render_samples

EXAMPLE = REPO / "examples" / "data" / "chart.dng"


@pytest.fixture
def commits(monkeypatch):
    """The paths a TiffStream committed during the test."""
    seen = []
    orig = TiffStream.commit

    def commit(self):
        seen.append(self.path)
        orig(self)

    monkeypatch.setattr(TiffStream, "commit", commit)
    return seen


def _reference(tmp_path, frame, depth, pipeline="srgb"):
    ref = tmp_path / f"ref-{depth}.tif"
    write_image(ref, render_samples(Pipeline.from_yaml(pipeline), frame, depth), depth=depth)
    return ref.read_bytes()


@pytest.mark.parametrize("depth", ["uint8", "uint16", "float32"])
def test_streamed_tiff_has_the_bytes_of_the_in_memory_render(depth, tmp_path, commits):
    out = tmp_path / "out.tif"
    info = render_file(EXAMPLE, out, depth=depth)
    assert commits == [out]  # streamed
    assert out.read_bytes() == _reference(tmp_path, read_dng(EXAMPLE), depth)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["out.tif", f"ref-{depth}.tif"])  # no temp left
    import tifffile

    with tifffile.TiffFile(out) as tif:
        page = tif.pages[0]
        assert page.shape == (info["height"], info["width"], 3) and page.dtype == np.dtype(depth)
        assert page.compression == 1 and 34675 in page.tags  # uncompressed, the sRGB ICC profile


@pytest.mark.parametrize("name", ["canon_550d_colorchecker", "gopro_hero7_iso252"])
def test_streamed_tiff_of_a_real_dng(name, tmp_path, commits):
    """A camera's DNG: its EXIF and tags in the streamed file as in the written one."""
    dng = shared_path(f"dng/{name}.dng")
    frame = read_dng(dng)
    out = tmp_path / "out.tif"
    render_file(dng, out, depth="uint16", frame=frame)
    assert out.read_bytes() == _reference(tmp_path, frame, "uint16")
    assert commits == ([out] if frame.meta.orientation in (None, 1) else [])


def test_a_turned_output_is_rendered_in_memory(tmp_path, commits):
    frame = read_dng(EXAMPLE)
    frame.meta.orientation = 6  # 90 degrees: the output's rows are the frame's columns
    out = tmp_path / "out.tif"
    info = render_file(EXAMPLE, out, depth="uint16", frame=frame)
    assert commits == [] and out.read_bytes() == _reference(tmp_path, frame, "uint16")
    assert info["width"] < info["height"] or frame.width <= frame.height


def test_other_formats_and_compression_are_not_streamed(tmp_path, commits):
    render_file(EXAMPLE, tmp_path / "a.png", depth="uint16")
    render_file(EXAMPLE, tmp_path / "b.tif", depth="uint16", compression="zip")
    assert commits == []


def test_a_failed_render_leaves_the_old_output_and_no_temporary_file(tmp_path, commits):
    out = tmp_path / "out.tif"
    out.write_bytes(b"previous")
    frame = read_dng(EXAMPLE)
    frame.data[frame.height // 2, frame.width // 2] = np.nan
    with pytest.raises(ImageIOError, match="NaN or infinite"):
        render_file(EXAMPLE, out, depth="uint16", frame=frame)
    assert out.read_bytes() == b"previous" and [p.name for p in tmp_path.iterdir()] == ["out.tif"]
    assert commits == []


def test_the_input_is_never_overwritten(tmp_path):
    import shutil

    dng = tmp_path / "chart.tif"  # a DNG named .tif: the output path is the input
    shutil.copy(EXAMPLE, dng)
    before = dng.read_bytes()
    with pytest.raises(ImageIOError, match="refusing to overwrite the input"):
        render_file(dng, dng, depth="uint16")
    assert dng.read_bytes() == before and [p.name for p in tmp_path.iterdir()] == ["chart.tif"]


def test_write_checks_its_rows(tmp_path):
    s = TiffStream(tmp_path / "x.tif").open((4, 6, 3), np.uint16, "display", None)
    try:
        with pytest.raises(ValueError, match="expected uint16 rows"):
            s.write(0, np.zeros((2, 6, 3), np.uint8))
        with pytest.raises(ValueError, match="expected uint16 rows"):
            s.write(3, np.zeros((2, 6, 3), np.uint16))
        s.write(2, np.full((2, 6, 3), 7, np.uint16))
        s.write(0, np.full((2, 6, 3), 5, np.uint16))
        s.commit()
    finally:
        s.discard()
    import tifffile

    img = tifffile.imread(tmp_path / "x.tif")
    assert img[:2].tolist() == np.full((2, 6, 3), 5).tolist() and img[2:].tolist() == np.full((2, 6, 3), 7).tolist()
