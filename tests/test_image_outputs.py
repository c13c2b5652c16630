"""Image outputs read back with independent readers (tifffile, Pillow + LittleCMS, OpenImageIO):
colour tags (ICC profiles, EXR chromaticities), camera EXIF, compression, JPEG quality, thumbnails."""

from __future__ import annotations

import io

import numpy as np
import pytest
import tifffile
from PIL import Image, ImageCms

from simcam.errors import ImageIOError
from simcam.frame import CameraMeta, RawFrame
from simcam.io.icc import srgb_icc_profile
from simcam.io.images import read_image, to_samples, write_image


def _frame(kind="display", h=24, w=36):
    rng = np.random.default_rng(0)
    meta = CameraMeta(make="Acme", model="Cam 1", iso=400.0, exposure_time_s=0.005,
                      extra={"DateTimeOriginal": "2021:05:06 07:08:09"})
    return RawFrame(rng.uniform(0, 1, (h, w, 3)).astype(np.float32), meta, kind=kind)


def _srgb64(x):
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


@pytest.mark.parametrize("linear", [False, True])
def test_icc_profiles_convert_like_the_srgb_curve(linear):
    # LittleCMS (through Pillow) converts through the profile to its own sRGB profile
    prof = ImageCms.ImageCmsProfile(io.BytesIO(srgb_icc_profile(linear)))
    ref = ImageCms.createProfile("sRGB")
    v = np.array([0, 16, 64, 128, 200, 255], np.uint8)
    img = Image.fromarray(np.stack([v, v, v], -1)[None])
    out = np.asarray(ImageCms.applyTransform(img, ImageCms.buildTransform(prof, ref, "RGB", "RGB")))[0, :, 1]
    expect = np.round(_srgb64(v / 255.0) * 255) if linear else v
    assert np.abs(out.astype(int) - expect).max() <= 1, (out, expect)
    # primaries: pure red stays pure red in sRGB
    red = Image.fromarray(np.array([[[255, 0, 0]]], np.uint8))
    r = np.asarray(ImageCms.applyTransform(red, ImageCms.buildTransform(prof, ref, "RGB", "RGB")))[0, 0]
    assert r[0] >= 254 and r[1] <= 1 and r[2] <= 1


def test_tiff_carries_icc_exif_and_is_uncompressed(tmp_path):
    f = _frame("display")
    p = write_image(tmp_path / "o.tif", f, depth=16)
    with tifffile.TiffFile(p) as t:
        page = t.pages[0]
        assert page.dtype == np.uint16 and page.compression == 1
        tags = page.tags
        assert tags["Make"].value == "Acme" and tags["Model"].value == "Cam 1"
        assert bytes(tags["InterColorProfile"].value) == srgb_icc_profile(False)
        exif = tags["ExifTag"].value
        assert exif["DateTimeOriginal"] == "2021:05:06 07:08:09"
        num, den = exif["ExposureTime"]
        assert num / den == pytest.approx(0.005, rel=1e-3)
        assert exif["ISOSpeedRatings"] == 400
        np.testing.assert_array_equal(page.asarray(), to_samples(f.data, "uint16"))


@pytest.mark.parametrize("compression", [None, "zip:9", "lzw"])
def test_tiff_exif_read_by_openimageio_and_pillow(tmp_path, compression):
    # two more independent readers of the EXIF IFD (tifffile's writer leaves it to simcam; LZW goes
    # through OpenImageIO's writer)
    import OpenImageIO as oiio

    f = _frame("display")
    p = write_image(tmp_path / "o.tif", f, depth=16, compression=compression)
    inp = oiio.ImageInput.open(str(p))
    spec = inp.spec()
    pixels = inp.read_image(oiio.UINT16)
    inp.close()
    assert spec.getattribute("Make") == "Acme" and spec.getattribute("Model") == "Cam 1"
    assert spec.getattribute("ExposureTime") == pytest.approx(0.005, rel=1e-6)
    assert spec.getattribute("Exif:DateTimeOriginal") == "2021:05:06 07:08:09"
    np.testing.assert_array_equal(pixels, to_samples(f.data, "uint16"))
    with Image.open(p) as im:
        assert im.info["icc_profile"] == srgb_icc_profile(False)
        sub = im.getexif().get_ifd(0x8769)
        assert sub[0x9003] == "2021:05:06 07:08:09" and float(sub[0x829A]) == pytest.approx(0.005, rel=1e-3)
        if compression != "lzw":  # OpenImageIO's TIFF writer leaves ISO out of the EXIF IFD
            assert sub[0x8827] == 400


def test_tiff_mono_and_8bit(tmp_path):
    rng = np.random.default_rng(1)
    g = rng.uniform(0, 1, (20, 30)).astype(np.float32)
    p = write_image(tmp_path / "g.tif", g, depth=8)
    with tifffile.TiffFile(p) as t:
        assert t.pages[0].photometric == 1 and t.pages[0].dtype == np.uint8
        np.testing.assert_array_equal(t.pages[0].asarray(), to_samples(g, "uint8"))
        assert "ExifTag" not in t.pages[0].tags and "ImageDescription" not in t.pages[0].tags


@pytest.mark.parametrize("bigtiff", [False, True])
def test_tiff_writer_exif_ifd_classic_and_big(tmp_path, bigtiff):
    from simcam.io.tiff_write import write_tiff

    s = np.arange(5 * 7 * 3, dtype=np.uint16).reshape(5, 7, 3)
    p = tmp_path / "t.tif"
    write_tiff(p, s, tags={"Make": "M", "Software": "simcam", "DateTime": "2020:01:02 03:04:05"}, bigtiff=bigtiff,
               exif={"ExposureTime": 1 / 250, "FNumber": 2.8, "PhotographicSensitivity": 1600, "FocalLength": 4.25,
                     "DateTimeOriginal": "2020:01:02 03:04:05"})
    with tifffile.TiffFile(p) as t:
        assert t.is_bigtiff == bigtiff
        tags = t.pages[0].tags
        assert tags["Make"].value == "M" and tags["DateTime"].value == "2020:01:02 03:04:05"
        exif = tags["ExifTag"].value
        assert exif["ExposureTime"] == (1, 250) and exif["FNumber"] == (14, 5) and exif["FocalLength"] == (17, 4)
        assert exif["ISOSpeedRatings"] == 1600 and exif["DateTimeOriginal"] == "2020:01:02 03:04:05"
        assert exif["ExifVersion"] in ("0232", b"0232")
        np.testing.assert_array_equal(t.pages[0].asarray(), s)


def test_tiff_same_bytes_twice(tmp_path):
    f = _frame("display")
    a = write_image(tmp_path / "a.tif", f, depth=16).read_bytes()
    b = write_image(tmp_path / "b.tif", f, depth=16).read_bytes()
    assert a == b


def test_linear_tiff_is_marked_linear(tmp_path):
    p = write_image(tmp_path / "lin.tif", _frame("linear_srgb"), depth=16)
    with tifffile.TiffFile(p) as t:
        assert bytes(t.pages[0].tags["InterColorProfile"].value) == srgb_icc_profile(True)
    prof = ImageCms.ImageCmsProfile(io.BytesIO(srgb_icc_profile(True)))
    assert "gamma 1" in ImageCms.getProfileDescription(prof)


def test_tiff_compression_option(tmp_path):
    f = _frame()
    p = write_image(tmp_path / "z.tif", f, depth=16, compression="zip")
    with tifffile.TiffFile(p) as t:
        assert t.pages[0].compression == 8  # ADOBE_DEFLATE
        np.testing.assert_array_equal(t.pages[0].asarray(), to_samples(f.data, "uint16"))
    with pytest.raises(ImageIOError, match="compression"):
        write_image(tmp_path / "bad.tif", f, compression="jpeg2000")


@pytest.mark.parametrize("name", ["o.png", "o.jpg"])
def test_png_jpeg_carry_icc_and_exif(tmp_path, name):
    f = _frame()
    p = write_image(tmp_path / name, f)
    with Image.open(p) as im:
        assert im.info["icc_profile"] == srgb_icc_profile(False)
        exif = im.getexif()
        assert exif[271] == "Acme" and exif[272] == "Cam 1"
        sub = exif.get_ifd(0x8769)
        assert sub[0x8827] == 400 and sub[0x9003] == "2021:05:06 07:08:09"  # ISO, DateTimeOriginal
        assert float(sub[0x829A]) == pytest.approx(0.005, rel=1e-3)  # ExposureTime
        if name.endswith(".png"):
            np.testing.assert_array_equal(np.asarray(im), to_samples(f.data, "uint8"))


def test_jpeg_quality(tmp_path):
    f = _frame(h=96, w=128)
    lo = write_image(tmp_path / "lo.jpg", f, quality=20)
    hi = write_image(tmp_path / "hi.jpg", f, quality=98)
    assert lo.stat().st_size < hi.stat().st_size
    ref = to_samples(f.data, "uint8").astype(float)
    err = [np.abs(np.asarray(Image.open(p)).astype(float) - ref).mean() for p in (lo, hi)]
    assert err[1] < err[0]
    with pytest.raises(ImageIOError, match="quality"):
        write_image(tmp_path / "x.jpg", f, quality=0)
    with pytest.raises(ImageIOError, match="depth"):
        write_image(tmp_path / "x.jpg", f, depth=16)


def test_exr_chromaticities(tmp_path):
    import OpenImageIO as oiio

    f = _frame("linear_srgb")
    p = write_image(tmp_path / "o.exr", f)
    inp = oiio.ImageInput.open(str(p))
    spec = inp.spec()
    inp.close()
    np.testing.assert_allclose(spec.getattribute("chromaticities"),
                               [0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290], atol=1e-6)
    assert spec.getattribute("Make") == "Acme"
    np.testing.assert_allclose(read_image(p), f.data, atol=0)


def test_thumbnail(tmp_path):
    f = _frame(h=300, w=500)
    write_image(tmp_path / "o.png", f, thumbnail=tmp_path / "t.png", thumbnail_size=100)
    with Image.open(tmp_path / "t.png") as im:
        assert im.size == (100, 60)
        assert im.info["icc_profile"] == srgb_icc_profile(False)
        t = np.asarray(im).astype(float)
    # a box average of the full image's 8-bit samples (5 x 5 blocks), rounded
    ref = to_samples(f.data, "uint8").astype(float).reshape(60, 5, 100, 5, 3).mean(axis=(1, 3))
    assert np.abs(t - ref).max() <= 0.5 + 1e-6
    write_image(tmp_path / "o.tif", f, depth=16, thumbnail=tmp_path / "t.jpg")
    with Image.open(tmp_path / "t.jpg") as im:
        assert im.size == (250, 150) and im.format == "JPEG"


def test_untagged_kinds_and_integer_samples(tmp_path):
    f = _frame("xyz")
    p = write_image(tmp_path / "x.tif", f, depth=16)
    with tifffile.TiffFile(p) as t:
        assert "InterColorProfile" not in t.pages[0].tags
    s = to_samples(_frame().data, "uint8")
    p = write_image(tmp_path / "s.png", s, kind="display")
    assert np.array_equal(np.asarray(Image.open(p)), s)
    with pytest.raises(ImageIOError, match="uint8 samples cannot be written as uint16"):
        write_image(tmp_path / "s16.png", s, depth=16)


def test_cli_render_outputs(tmp_path):
    from shared_data import REPO

    from simcam.cli import main

    dng = REPO / "examples" / "data" / "chart.dng"
    out, thumb = tmp_path / "o.jpg", tmp_path / "t.png"
    assert main(["render", str(dng), "-o", str(out), "--quality", "80", "--thumbnail", str(thumb)]) == 0
    with Image.open(out) as im:
        assert im.size == (600, 400) and im.info["icc_profile"] == srgb_icc_profile(False)
    with Image.open(thumb) as im:
        assert max(im.size) <= 256
    tif = tmp_path / "lin.tif"
    assert main(["render", str(dng), "-o", str(tif), "-p", "linear-srgb", "--depth", "16",
                 "--compression", "zip"]) == 0
    with tifffile.TiffFile(tif) as t:
        assert t.pages[0].compression == 8
        assert bytes(t.pages[0].tags["InterColorProfile"].value) == srgb_icc_profile(True)
    assert main(["render", str(dng), "-o", str(tmp_path / "x.png"), "--compression", "lzw"]) == 2
    assert not (tmp_path / "x.png").exists()


def test_png_zlib_level(tmp_path):
    # a smooth image: level 9 compresses at least as well as level 1, and both read back exactly
    y, x = np.mgrid[0:64, 0:96] / 96.0
    f = RawFrame(np.stack([x, y, x * y], -1).astype(np.float32), CameraMeta(), kind="display")
    p1 = write_image(tmp_path / "l1.png", f, depth=16)
    p9 = write_image(tmp_path / "l9.png", f, depth=16, compression="zip:9")
    assert p9.stat().st_size <= p1.stat().st_size
    for p in (p1, p9):
        np.testing.assert_array_equal(np.round(read_image(p).astype(np.float64) * 65535), to_samples(f.data, "uint16"))
