"""PNGs whose pixels simcam deflates on threads (simcam.io.png_write) behind OpenImageIO's metadata
chunks: decoded by independent readers (Pillow's own PNG decoder; OpenImageIO's libpng for 16-bit
RGB, which Pillow cannot hold), the metadata chunks those OpenImageIO writes for the whole image,
and the same bytes for any thread count."""

from __future__ import annotations

import numpy as np
import pytest

from simcam.io.images import _oiio_write, _spec, write_image
from simcam.io.png_write import BAND_ROWS, png_chunks

oiio = pytest.importorskip("OpenImageIO")
Image = pytest.importorskip("PIL.Image")


def _image(shape, dtype, seed=0):
    rng = np.random.default_rng(seed)
    top = np.iinfo(dtype).max
    smooth = np.cumsum(rng.integers(-3, 4, shape), axis=1)  # runs and repeats, as in a photograph
    noisy = rng.integers(0, top + 1, shape)
    return np.where(rng.random(shape) < 0.2, noisy, smooth % (top + 1)).astype(dtype)


@pytest.mark.parametrize("shape,dtype", [((2 * BAND_ROWS + 7, 45, 3), np.uint8), ((33, 20), np.uint8),
                                         ((BAND_ROWS + 1, 16, 4), np.uint8), ((70, 31), np.uint16),
                                         ((1, 1, 3), np.uint8)])
def test_pillow_decodes_the_samples(tmp_path, shape, dtype):
    a = _image(shape, dtype)
    p = write_image(tmp_path / "a.png", a)
    with Image.open(p) as im:
        im.load()
        b = np.array(im)
    np.testing.assert_array_equal(b.reshape(a.shape), a)


def test_sixteen_bit_rgb_read_back_by_libpng(tmp_path):
    a = _image((2 * BAND_ROWS + 3, 57, 3), np.uint16, seed=1)
    p = write_image(tmp_path / "a.png", a, kind="display")
    buf = oiio.ImageBuf(str(p))
    np.testing.assert_array_equal(buf.get_pixels(oiio.UINT16), a)


def test_metadata_chunks_are_those_openimageio_writes_for_the_whole_image(tmp_path):
    from simcam.io.dng import read_dng
    from simcam.io.sample_dng import make_test_dng

    meta = read_dng(make_test_dng(tmp_path / "x.dng")).meta  # a camera's EXIF: Make, Model, exposure
    a = _image((150, 64, 3), np.uint8)
    ours = write_image(tmp_path / "ours.png", a, kind="display", meta=meta)
    ref = tmp_path / "ref.png"
    _oiio_write(str(ref), a, _spec(oiio, 64, 150, 3, "uint8", ".png", "zip:1", 95, "display", meta, None, png_level=1), ref)
    ck_ours = png_chunks(ours.read_bytes())
    ck_ref = png_chunks(ref.read_bytes())
    assert [c for c in ck_ours if c[0] != b"IDAT"] == [c for c in ck_ref if c[0] != b"IDAT"]
    assert {k for k, _ in ck_ours} >= {b"iCCP", b"eXIf", b"IHDR", b"IDAT", b"IEND"}


def test_same_bytes_for_any_thread_count(tmp_path, monkeypatch):
    a = _image((5 * BAND_ROWS + 11, 90, 3), np.uint8, seed=2)
    out = []
    for t in ("1", "2", "3"):
        monkeypatch.setenv("SIMCAM_THREADS", t)
        out.append(write_image(tmp_path / f"t{t}.png", a).read_bytes())
    assert out[1] == out[0] and out[2] == out[0]


def test_a_damaged_png_is_refused_by_the_chunk_reader(tmp_path):
    data = write_image(tmp_path / "a.png", _image((20, 20, 3), np.uint8)).read_bytes()
    with pytest.raises(ValueError, match="signature"):
        png_chunks(b"GIF89a" + data[6:])
    bad = bytearray(data)
    bad[40] ^= 0xFF
    with pytest.raises(ValueError, match="CRC|length"):
        png_chunks(bytes(bad))
    with pytest.raises(ValueError, match="truncated|CRC|length"):
        png_chunks(data[:-7])


def test_a_template_of_another_sample_layout_is_refused():
    """The pixels are encoded for the template's IHDR: a template of another bit depth or channel count
    (e.g. an OpenImageIO attribute that changed it) is an error, never a file of wrong pixels."""
    import tempfile
    from pathlib import Path

    from simcam.io.png_write import assemble_png

    with tempfile.TemporaryDirectory() as d:
        t8 = write_image(Path(d) / "t.png", np.zeros((1, 1, 3), np.uint8)).read_bytes()
        assemble_png(t8, np.zeros((4, 4, 3), np.uint8), 1)
        with pytest.raises(ValueError, match="bit depth 8, colour type 2; expected 16-bit samples in 3"):
            assemble_png(t8, np.zeros((4, 4, 3), np.uint16), 1)
        with pytest.raises(ValueError, match="expected 8-bit samples in 4 channels"):
            assemble_png(t8, np.zeros((4, 4, 4), np.uint8), 1)
        from simcam.io.png_write import _SIGNATURE, _chunk

        no_idat = _SIGNATURE + b"".join(_chunk(k, v) for k, v in png_chunks(t8) if k != b"IDAT")
        with pytest.raises(ValueError, match="no IDAT chunk"):
            assemble_png(no_idat, np.zeros((4, 4, 3), np.uint8), 1)
