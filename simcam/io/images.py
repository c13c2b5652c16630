"""Image output: PNG (8/16-bit), JPEG (8-bit), TIFF (8/16-bit, float32), EXR (half/float).

OpenImageIO writes every format except uncompressed and Deflate TIFFs of one or three
channels, which tifffile writes (:mod:`simcam.io.tiff_write`: about 3x faster, with the same
tags); LZW and PackBits TIFFs go through OpenImageIO.

Files are written to a temporary name beside the target and renamed into place,
so a failed write never leaves a partial output, and an input file is never
overwritten.

Colour tags: a frame of kind ``display`` is tagged sRGB (IEC 61966-2-1), one of
kind ``linear_srgb`` linear sRGB (Rec. 709 primaries, gamma 1): PNG, JPEG and
TIFF carry an ICC profile (:mod:`simcam.io.icc`), EXR its ``chromaticities``
attribute, and every format OpenImageIO's ``oiio:ColorSpace``. Camera EXIF
(Make, Model, ISO, exposure time, capture date) is written where the metadata
has it. Compression: TIFF and EXR are uncompressed by default (fast), PNG uses
zlib level 1 with the ``sub`` filter; ``compression`` chooses another.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ImageIOError
from .atomic import atomic_output
from .tiff_write import COMPRESSIONS as TIFF_COMPRESSIONS

#: Allowed sample types per file extension; the first is the default.
FORMAT_DEPTHS = {
    ".png": ("uint8", "uint16"),
    ".jpg": ("uint8",),
    ".jpeg": ("uint8",),
    ".tif": ("uint16", "uint8", "float32"),
    ".tiff": ("uint16", "uint8", "float32"),
    ".exr": ("float32", "half"),
}
DEPTH_ALIASES = {"8": "uint8", "16": "uint16", "32": "float32", "float": "float32", "f16": "half"}


def resolve_depth(path: str | Path, depth: str | int | None) -> str:
    """The sample type for ``path`` (``uint8``, ``uint16``, ``float32``, ``half``)."""
    ext = Path(path).suffix.lower()
    if ext not in FORMAT_DEPTHS:
        raise ImageIOError(f"{path}: output format {ext or '(none)'!r} not supported; expected one of {sorted(FORMAT_DEPTHS)}")
    if depth is None:
        return FORMAT_DEPTHS[ext][0]
    d = DEPTH_ALIASES.get(str(depth), str(depth))
    if d not in FORMAT_DEPTHS[ext]:
        raise ImageIOError(f"{path}: depth {depth!r} not supported for {ext}; expected one of {FORMAT_DEPTHS[ext]}")
    return d


#: compression by format when none is asked for (OpenImageIO ``compression`` names)
DEFAULT_COMPRESSION = {".png": "zip:1", ".tif": "none", ".tiff": "none", ".exr": "none"}
#: accepted compression names per format (``zip:N`` also takes a zlib level for PNG/TIFF)
COMPRESSIONS = {
    ".png": ("zip",),
    ".tif": ("none", "zip", "lzw", "packbits"),
    ".tiff": ("none", "zip", "lzw", "packbits"),
    ".exr": ("none", "rle", "zips", "zip", "piz", "pxr24", "b44", "b44a", "dwaa", "dwab"),
}
#: colour space name (OpenImageIO ``oiio:ColorSpace``) by signal kind
COLOUR_SPACES = {"display": "sRGB", "linear_srgb": "lin_srgb"}
#: Rec. 709 / sRGB primaries and D65 white (x, y): red, green, blue, white (EXR chromaticities)
REC709_CHROMATICITIES = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)
_PNG_FILTER_SUB = 0x10


def to_samples(data: np.ndarray, depth: str) -> np.ndarray:
    """Convert float data (display range [0, 1]) to the stored sample type.

    Integer types clip to [0, 1] and round (half to even); float types are stored as is.
    Integer input already of type ``depth`` is returned as is.
    """
    data = np.asarray(data)
    if data.dtype == np.dtype(depth) and depth in ("uint8", "uint16"):
        return data
    if depth in ("uint8", "uint16"):
        from ..colour.display_kernel import quantise

        try:
            return quantise(data, depth)
        except ValueError:
            raise ImageIOError("image data contains NaN or infinite values") from None
    if not np.all(np.isfinite(data)):
        raise ImageIOError("image data contains NaN or infinite values")
    if depth == "half":
        return data.astype(np.float16)
    return data.astype(np.float32)


def resolve_compression(path: str | Path, compression: str | None) -> str | None:
    """The OpenImageIO compression for ``path`` (None for JPEG, which takes ``quality``)."""
    ext = Path(path).suffix.lower()
    if ext in (".jpg", ".jpeg"):
        if compression not in (None, "jpeg"):
            raise ImageIOError(f"{path}: compression {compression!r} not supported for JPEG; use quality")
        return None
    if compression is None:
        return DEFAULT_COMPRESSION[ext]
    name, _, level = str(compression).partition(":")
    if name not in COMPRESSIONS[ext] or (level and not (level.isdigit() and 1 <= int(level) <= 9 and name == "zip")):
        raise ImageIOError(f"{path}: compression {compression!r} not supported for {ext}; expected one of "
                           f"{list(COMPRESSIONS[ext])} (zip:1..9 for a zlib level)")
    return str(compression)


def exif_attributes(meta) -> dict:
    """OpenImageIO attributes for the camera EXIF of ``meta`` (a CameraMeta): only the known fields."""
    out: dict = {}
    if meta is None:
        return out
    if getattr(meta, "make", ""):
        out["Make"] = str(meta.make)
    if getattr(meta, "model", ""):
        out["Model"] = str(meta.model)
    if getattr(meta, "iso", None):
        out["Exif:PhotographicSensitivity"] = round(float(meta.iso))
    if getattr(meta, "exposure_time_s", None):
        out["ExposureTime"] = float(meta.exposure_time_s)
    extra = getattr(meta, "extra", None) or {}
    date = extra.get("DateTimeOriginal")
    if date:
        out["Exif:DateTimeOriginal"] = str(date)
        out["DateTime"] = str(date)
    if extra.get("FNumber"):
        out["FNumber"] = float(extra["FNumber"])
    if extra.get("FocalLength"):
        out["Exif:FocalLength"] = float(extra["FocalLength"])
    return out


def write_image(path: str | Path, data, *, depth: str | int | None = None,
                protect: tuple[str | Path, ...] = (), attributes: dict | None = None,
                kind: str | None = None, meta=None, compression: str | None = None,
                quality: int = 95, thumbnail: str | Path | None = None, thumbnail_size: int = 256) -> Path:
    """Write an image with OpenImageIO, tagged with its colour space and the camera's EXIF.

    Parameters
    ----------
    path : path
        Output file; its extension picks the format (.png, .jpg/.jpeg, .tif/.tiff, .exr).
    data : ndarray, RawFrame or simcam.render_samples.Rendered
        float H x W or H x W x C (integer outputs take [0, 1] to full scale), or
        integer samples already of the output type; a ``RawFrame`` /
        ``Rendered`` also gives ``kind`` and ``meta``.
    depth : str or int, optional
        ``8``/``16``/``32`` or ``uint8``/``uint16``/``float32``/``half``.
    protect : paths
        Files that must never be overwritten (the inputs).
    attributes : dict, optional
        Extra OpenImageIO attributes.
    kind : str, optional
        Signal kind: ``display`` is tagged sRGB, ``linear_srgb`` linear sRGB; others are untagged.
    meta : CameraMeta, optional
        Camera metadata for the EXIF.
    compression : str, optional
        TIFF: none (default), zip[:N], lzw, packbits; PNG: zip:N (default zip:1);
        EXR: none (default), zips, zip, piz, ... .
    quality : int
        JPEG quality 1..100.
    thumbnail : path, optional
        Also write a small 8-bit preview (its longer side ``thumbnail_size``) to this file
        (display kinds only, e.g. ``preview.jpg``).
    """
    from ..frame import RawFrame

    path = Path(path)
    if isinstance(data, RawFrame):
        kind, meta, data = kind or data.kind, meta if meta is not None else data.meta, data.data
    elif hasattr(data, "samples") and hasattr(data, "kind"):
        kind, meta, data = kind or data.kind, meta if meta is not None else data.meta, data.samples
    check_output_path(path, protect)
    if depth is None and np.asarray(data).dtype in (np.uint8, np.uint16, np.float16):
        depth = {"float16": "half"}.get(str(np.asarray(data).dtype), str(np.asarray(data).dtype))
    dtype = resolve_depth(path, depth)
    comp = resolve_compression(path, compression)
    if not 1 <= int(quality) <= 100:
        raise ImageIOError(f"{path}: quality {quality!r}: expected an integer in 1..100")
    data = np.asarray(data)
    if data.dtype.kind in "ui" and data.dtype != np.dtype(dtype):
        raise ImageIOError(f"{path}: {data.dtype} samples cannot be written as {dtype}; pass float data")
    samples = to_samples(data, dtype)
    if samples.ndim == 2:
        samples = samples[:, :, None]
    c = samples.shape[2]
    if ext_is_tiff(path) and c in (1, 3) and not attributes and comp.partition(":")[0] in TIFF_COMPRESSIONS:
        _write_tiff(path, samples, comp, kind if c == 3 else None, meta)
    else:
        _write_oiio(path, samples, dtype, comp, quality, kind if c == 3 else None, meta, attributes)
    if thumbnail is not None:
        write_thumbnail(thumbnail, samples, kind=kind, meta=meta, size=thumbnail_size, protect=protect)
    return path


def _write_oiio(path: Path, samples: np.ndarray, dtype: str, comp: str | None, quality: int, kind: str | None,
                meta, attributes: dict | None) -> None:
    """Any format through OpenImageIO (everything :func:`_write_tiff` does not take); PNG pixels are
    deflated on threads (:mod:`simcam.io.png_write`) behind OpenImageIO's metadata chunks."""
    h, w, c = samples.shape
    import OpenImageIO as oiio

    ext = path.suffix.lower()
    png_level = int(comp.partition(":")[2] or 6) if ext == ".png" else None  # the zlib level
    with atomic_output(path, suffix=path.suffix) as tmp:
        # PNG: simcam deflates the pixels (unless extra OpenImageIO attributes could change how they are
        # stored); OpenImageIO writes the metadata, as the chunks of a 1 x 1 image
        if png_level is not None and not attributes:
            _oiio_write(tmp, np.zeros((1, 1, c), samples.dtype), _spec(oiio, 1, 1, c, dtype, ext, comp, quality, kind,
                                                                       meta, attributes, png_level=0), path)
            from .png_write import write_png

            try:
                write_png(tmp, samples, Path(tmp).read_bytes(), png_level)
            except (OSError, ValueError) as exc:
                raise ImageIOError(f"{path}: write failed ({type(exc).__name__}: {exc})") from None
        else:
            _oiio_write(tmp, samples, _spec(oiio, w, h, c, dtype, ext, comp, quality, kind, meta, attributes,
                                            png_level=png_level), path)


def _spec(oiio, w: int, h: int, c: int, dtype: str, ext: str, comp: str | None, quality: int, kind: str | None,
          meta, attributes: dict | None, png_level: int | None = None):
    """OpenImageIO's specification of a ``w`` x ``h`` x ``c`` output: type, compression (``png_level``: the
    zlib level of a PNG), colour tags, EXIF."""
    type_desc = {"uint8": oiio.UINT8, "uint16": oiio.UINT16, "float32": oiio.FLOAT, "half": oiio.HALF}[dtype]
    spec = oiio.ImageSpec(w, h, c, type_desc)
    # OpenImageIO stamps TIFF/EXR with the write time unless told otherwise: the same render
    # would give different bytes on every run. No DateTime unless the caller (or the capture's
    # DateTimeOriginal, below) gives one.
    spec.attribute("DateTime", "")
    if comp is not None:
        spec.attribute("compression", comp)
    if ext == ".png":  # OpenImageIO's PNG writer takes the zlib level from png:compressionLevel
        spec.attribute("png:compressionLevel", png_level)
        spec.attribute("png:filter", _PNG_FILTER_SUB)
    if ext in (".jpg", ".jpeg"):
        spec.attribute("Compression", f"jpeg:{int(quality)}")
    _colour_tags(spec, ext, kind)
    spec.attribute("Software", "simcam")
    for k, v in exif_attributes(meta).items():
        spec.attribute(k, v)
    for k, v in (attributes or {}).items():
        spec.attribute(k, v)
    return spec


def _oiio_write(tmp, samples: np.ndarray, spec, path: Path) -> None:
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(tmp)
    if out is None or not out.open(tmp, spec):
        raise ImageIOError(f"{path}: cannot open for writing ({oiio.geterror() or (out and out.geterror())})")
    ok = out.write_image(np.ascontiguousarray(samples))
    out.close()
    if not ok:
        raise ImageIOError(f"{path}: write failed ({out.geterror()})")


def ext_is_tiff(path: Path) -> bool:
    return path.suffix.lower() in (".tif", ".tiff")


def _write_tiff(path: Path, samples: np.ndarray, comp: str, kind: str | None, meta) -> None:
    """An uncompressed or Deflate TIFF through :func:`simcam.io.tiff_write.write_tiff` (tifffile)."""
    from .tiff_write import write_tiff

    with atomic_output(path, suffix=path.suffix) as tmp:
        try:
            write_tiff(tmp, samples, compression=comp, **tiff_tags(kind, meta))
        except (OSError, ValueError) as exc:
            raise ImageIOError(f"{path}: write failed ({type(exc).__name__}: {exc})") from None


def tiff_tags(kind: str | None, meta) -> dict:
    """The ``icc``, ``tags`` and ``exif`` arguments of :func:`simcam.io.tiff_write.write_tiff` for
    samples of signal ``kind`` (an ICC profile for the display kinds) from a camera with ``meta``."""
    icc = None
    if kind in COLOUR_SPACES:
        from .icc import srgb_icc_profile

        icc = srgb_icc_profile(linear=kind == "linear_srgb")
    ex = exif_attributes(meta)
    tags = {"Make": ex.get("Make"), "Model": ex.get("Model"), "Software": "simcam", "DateTime": ex.get("DateTime")}
    exif = {"ExposureTime": ex.get("ExposureTime"), "FNumber": ex.get("FNumber"),
            "PhotographicSensitivity": ex.get("Exif:PhotographicSensitivity"),
            "DateTimeOriginal": ex.get("Exif:DateTimeOriginal"), "FocalLength": ex.get("Exif:FocalLength")}
    exif = {k: v for k, v in exif.items() if v}
    return {"icc": icc, "tags": tags, "exif": exif or None}


def check_output_path(path: Path, protect: tuple = ()) -> None:
    """The checks of :func:`write_image` on where it writes: never one of ``protect`` (the inputs), into a
    folder that exists."""
    for p in protect:
        if Path(p).exists() and path.exists() and os.path.samefile(p, path):
            raise ImageIOError(f"{path}: refusing to overwrite the input file")
    if not path.parent.exists():
        raise ImageIOError(f"{path}: output folder {path.parent} does not exist")


def _colour_tags(spec, ext: str, kind: str | None) -> None:
    import OpenImageIO as oiio

    if kind not in COLOUR_SPACES:
        return
    spec.attribute("oiio:ColorSpace", COLOUR_SPACES[kind])
    if ext == ".exr":
        spec.attribute("chromaticities", oiio.TypeDesc("float[8]"), REC709_CHROMATICITIES)
        return
    from .icc import srgb_icc_profile

    icc = np.frombuffer(srgb_icc_profile(linear=kind == "linear_srgb"), dtype=np.uint8)
    spec.attribute("ICCProfile", oiio.TypeDesc(f"uint8[{icc.size}]"), icc)
    if kind == "linear_srgb":
        spec.attribute("oiio:Gamma", 1.0)


def thumbnail_samples(samples: np.ndarray, size: int = 256) -> np.ndarray:
    """An 8-bit preview of ``samples`` (H x W x C) with its longer side at most ``size`` (box average)."""
    if size < 8:
        raise ImageIOError(f"thumbnail size {size}: expected at least 8")
    s = np.asarray(samples)
    if s.dtype == np.uint16:
        x = s.astype(np.float32) / np.float32(65535)
    elif s.dtype == np.uint8:
        x = s.astype(np.float32) / np.float32(255)
    else:
        x = np.clip(s.astype(np.float32), 0.0, 1.0)
    h, w = x.shape[:2]
    f = max(1, -(-max(h, w) // size))
    hh, ww = h // f * f, w // f * f
    x = x[:hh, :ww].reshape(hh // f, f, ww // f, f, -1).mean(axis=(1, 3))
    return np.round(np.clip(x, 0, 1) * 255).astype(np.uint8)


def write_thumbnail(path: str | Path, samples: np.ndarray, *, kind: str | None = "display", meta=None,
                    size: int = 256, protect: tuple[str | Path, ...] = ()) -> Path:
    """Write an 8-bit preview (longer side at most ``size``) of display samples; PNG or JPEG."""
    path = Path(path)
    if path.suffix.lower() not in (".png", ".jpg", ".jpeg"):
        raise ImageIOError(f"{path}: thumbnail format {path.suffix or '(none)'!r} not supported; expected .jpg or .png")
    if kind not in (None, "display"):
        raise ImageIOError(f"{path}: a thumbnail needs display data (kind 'display'), got kind {kind!r}")
    return write_image(path, thumbnail_samples(samples, size), depth="uint8", kind=kind, meta=meta,
                       protect=protect, quality=85)


def decode_image(path: str | Path, fmt: Any = None, *, channels: int | None = None,
                 error: type[Exception] = ImageIOError, undecodable: str = "cannot decode image"):
    """Open an image with OpenImageIO and decode its pixels: ``(pixels, spec)``.

    ``fmt``: the pixel type to decode to (None: the stored one); ``channels``: only the first ones (None:
    all); ``error`` (one line naming the file) when it cannot be opened, or (``undecodable``) decoded.
    """
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise error(f"{path}: cannot read image ({oiio.geterror()})")
    try:
        spec = inp.spec()
        fmt = spec.format if fmt is None else fmt
        data = inp.read_image(fmt) if channels is None else inp.read_image(0, 0, 0, channels, fmt)
    finally:
        inp.close()
    if data is None:
        raise error(f"{path}: {undecodable}")
    return data, spec


def read_image(path: str | Path) -> np.ndarray:
    """Read an image as float32 (integer types scaled to [0, 1]); H x W x C."""
    import OpenImageIO as oiio

    path = Path(path)
    if not path.exists():
        raise ImageIOError(f"{path}: no such file")
    data, _ = decode_image(path, oiio.FLOAT)
    return np.asarray(data, dtype=np.float32)
