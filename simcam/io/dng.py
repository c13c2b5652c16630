"""Read DNG files: pixels through rawpy (LibRaw), every tag through tifffile.

:func:`read_dng` returns the FULL stored raw image (``kind="raw_dn"``, float32
DN, ``meta.origin == (0, 0)``); cropping to the active area / default crop is
the ``crop`` stage's job. :func:`read_dng_meta` reads the tags only.

Tag semantics follow the DNG 1.6 specification (Adobe, 2023), chapter 4 (tags)
and chapter 5 (mapping raw values). ``meta.cfa`` is the 2x2 pattern of the
stored image's pixel (0, 0): CFAPattern is anchored at the top-left of the
ActiveArea (DNG SDK ``dng_mosaic_info``; LibRaw agrees, see the tests), so an
odd ActiveArea offset shifts it.
"""

from __future__ import annotations

import math
import os
import struct
from pathlib import Path
from typing import Any

import numpy as np

from ..cfa import BAYER_PATTERNS, shift_pattern
from ..errors import DngError
from ..frame import CameraMeta, RawFrame
from .opcodes import parse_opcode_list

# TIFF / DNG tag codes used here (DNG 1.6 spec chapter 4; TIFF 6.0; TIFF/EP).
T = {
    "NewSubfileType": 254, "ImageWidth": 256, "ImageLength": 257, "BitsPerSample": 258,
    "Compression": 259, "PhotometricInterpretation": 262, "Make": 271, "Model": 272,
    "StripOffsets": 273, "Orientation": 274, "SamplesPerPixel": 277, "RowsPerStrip": 278,
    "StripByteCounts": 279, "PlanarConfiguration": 284, "TileWidth": 322, "TileLength": 323,
    "TileOffsets": 324, "TileByteCounts": 325, "SubIFDs": 330,
    "CFARepeatPatternDim": 33421, "CFAPattern": 33422, "ExposureTime": 33434, "ExifTag": 34665,
    "ISOSpeedRatings": 34855,
    "DNGVersion": 50706, "DNGBackwardVersion": 50707, "UniqueCameraModel": 50708,
    "CFAPlaneColor": 50710, "CFALayout": 50711, "LinearizationTable": 50712,
    "BlackLevelRepeatDim": 50713, "BlackLevel": 50714, "BlackLevelDeltaH": 50715,
    "BlackLevelDeltaV": 50716, "WhiteLevel": 50717, "DefaultScale": 50718,
    "DefaultCropOrigin": 50719, "DefaultCropSize": 50720, "ColorMatrix1": 50721,
    "ColorMatrix2": 50722, "CameraCalibration1": 50723, "CameraCalibration2": 50724,
    "AnalogBalance": 50727, "AsShotNeutral": 50728, "AsShotWhiteXY": 50729,
    "BaselineExposure": 50730, "BaselineNoise": 50731, "CameraSerialNumber": 50735,
    "CalibrationIlluminant1": 50778, "CalibrationIlluminant2": 50779, "ActiveArea": 50829,
    "MaskedAreas": 50830, "ProfileName": 50936, "ForwardMatrix1": 50964, "ForwardMatrix2": 50965,
    "OpcodeList1": 51008, "OpcodeList2": 51009, "OpcodeList3": 51022, "NoiseProfile": 51041,
}
PHOTOMETRIC_CFA = 32803
PHOTOMETRIC_LINEAR_RAW = 34892
#: Compression codes LibRaw decodes for DNG CFA data: none, lossless JPEG, deflate.
SUPPORTED_COMPRESSION = {1: "uncompressed", 7: "lossless JPEG", 8: "deflate"}
#: CFAPlaneColor codes (TIFF/EP): 0 red, 1 green, 2 blue, 3 cyan, 4 magenta, 5 yellow, 6 white.
PLANE_COLOR_LETTERS = "RGBCMYW"
RATIONAL_TYPES = (5, 10)  # RATIONAL, SRATIONAL


# ---------------------------------------------------------------------------
# file-level checks
# ---------------------------------------------------------------------------
def _check_path(path: Path) -> None:
    if not path.exists():
        raise DngError(f"{path}: no such file")
    if path.is_dir():
        raise DngError(f"{path}: is a directory; expected a DNG file")


def _open_tiff(path: Path):
    import tifffile

    _check_path(path)
    try:
        return tifffile.TiffFile(str(path))
    except tifffile.TiffFileError as exc:
        raise DngError(f"{path}: not a TIFF/DNG file ({exc})") from None
    except (OSError, ValueError, struct.error) as exc:
        raise DngError(f"{path}: cannot parse the TIFF structure ({exc})") from None


class _Tags:
    """Tag lookup: main raw IFD first, then IFD0, then the EXIF IFD."""

    def __init__(self, path: Path, main, ifd0, exif: dict[str, Any]):
        self.path, self.main, self.ifd0, self.exif = path, main, ifd0, exif

    def tag(self, name: str):
        code = T[name]
        for page in (self.main, self.ifd0):
            t = page.tags.get(code)
            if t is not None:
                return t
        return None

    def where(self, name: str) -> str:
        return f"{self.path}: {name}"

    def raw(self, name: str, default=None):
        t = self.tag(name)
        return default if t is None else t.value

    def numbers(self, name: str) -> np.ndarray | None:
        """Tag value as float64 array (rationals divided), or None if absent."""
        t = self.tag(name)
        if t is None:
            return None
        return _as_numbers(t.value, t.dtype, self.where(name))

    def matrix(self, name: str, rows: int = 3, cols: int = 3) -> np.ndarray | None:
        v = self.numbers(name)
        if v is None:
            return None
        if v.size != rows * cols:
            raise DngError(f"{self.where(name)}: {v.size} values; expected {rows}x{cols} = {rows * cols}")
        return v.reshape(rows, cols)

    def scalar(self, name: str) -> float | None:
        v = self.numbers(name)
        if v is None:
            return None
        if v.size < 1:
            raise DngError(f"{self.where(name)}: empty value; expected one number")
        return float(v[0])

    def text(self, name: str) -> str:
        v = self.raw(name)
        if v is None:
            return ""
        if isinstance(v, bytes):
            v = v.split(b"\0", 1)[0].decode("latin-1")
        return str(v).strip("\0").strip()


def _as_numbers(value: Any, dtype: int, where: str) -> np.ndarray:
    dtype = int(dtype)
    if isinstance(value, (bytes, bytearray)):
        return np.frombuffer(bytes(value), dtype=np.uint8).astype(np.float64)
    vals = np.atleast_1d(np.asarray(value, dtype=np.float64) if not isinstance(value, int) else [value])
    if dtype in RATIONAL_TYPES:
        if vals.size % 2:
            raise DngError(f"{where}: odd number of rational parts ({vals.size})")
        pairs = vals.reshape(-1, 2)
        num, den = pairs[:, 0], pairs[:, 1]
        bad = (den == 0) & (num != 0)
        if np.any(bad):
            raise DngError(f"{where}: rational with zero denominator ({int(num[bad][0])}/0)")
        # 0/0 occurs in real files (e.g. BaselineExposure of Magic Lantern DNGs): read it as 0.
        return np.divide(num, den, out=np.zeros_like(num), where=den != 0)
    return vals.astype(np.float64)


def _main_ifd(tif, path: Path):
    """The IFD holding the main raw image: NewSubfileType == 0 in IFD0 or a SubIFD."""
    ifd0 = tif.pages[0]
    candidates = [ifd0] + list(getattr(ifd0, "pages", None) or [])
    for page in candidates:
        nst = page.tags.get(T["NewSubfileType"])
        if int(nst.value if nst is not None else 0) == 0:
            return page
    raise DngError(f"{path}: NewSubfileType: no IFD with value 0 (main image) in IFD0 or its SubIFDs")


def _check_storage(path: Path, page, tags: _Tags) -> None:
    """Check strip/tile layout against the image size and the file size (truncation)."""
    size = os.path.getsize(path)
    h = int(tags.raw("ImageLength", 0))
    w = int(tags.raw("ImageWidth", 0))
    tiled = T["TileOffsets"] in page.tags
    off_name, cnt_name = ("TileOffsets", "TileByteCounts") if tiled else ("StripOffsets", "StripByteCounts")
    offs, cnts = page.tags.get(T[off_name]), page.tags.get(T[cnt_name])
    if offs is None or cnts is None:
        raise DngError(f"{path}: {off_name}/{cnt_name}: missing in the main image IFD; expected pixel data")
    offs = np.atleast_1d(np.asarray(offs.value, dtype=np.int64))
    cnts = np.atleast_1d(np.asarray(cnts.value, dtype=np.int64))
    if tiled:
        tw, tl = int(page.tags[T["TileWidth"]].value), int(page.tags[T["TileLength"]].value)
        n_expected = math.ceil(w / tw) * math.ceil(h / tl)
        chunk_bytes = tw * tl
    else:
        rps = page.tags.get(T["RowsPerStrip"])
        rps = min(int(rps.value), h) if rps is not None else h
        rps = max(rps, 1)
        n_expected = math.ceil(h / rps)
        chunk_bytes = rps * w
    if offs.size != n_expected or cnts.size != n_expected:
        raise DngError(
            f"{path}: {cnt_name}: {cnts.size} {'tiles' if tiled else 'strips'} for a {w}x{h} image; "
            f"expected {n_expected} (truncated or corrupt pixel data)")
    end = offs + cnts
    if np.any(end > size):
        k = int(np.argmax(end > size))
        raise DngError(
            f"{path}: {cnt_name}: chunk {k} ends at byte {int(end[k])} but the file has {size} bytes "
            f"(truncated pixel data)")
    compression = int(tags.raw("Compression", 1))
    if compression == 1:
        bps = np.atleast_1d(tags.raw("BitsPerSample", 16))[0]
        spp = int(tags.raw("SamplesPerPixel", 1))
        need = math.ceil(chunk_bytes * spp * int(bps) / 8) if tiled else None
        if tiled and np.any(cnts < need):
            raise DngError(f"{path}: {cnt_name}: a tile has fewer than the {need} bytes it needs (truncated pixel data)")
        if not tiled:
            total_need = math.ceil(h * w * spp * int(bps) / 8)
            if int(cnts.sum()) < total_need:
                raise DngError(
                    f"{path}: {cnt_name}: {int(cnts.sum())} bytes of pixel data; expected {total_need} "
                    f"(truncated pixel data)")


def _cfa_pattern(tags: _Tags) -> str:
    dim = tags.raw("CFARepeatPatternDim", (2, 2))
    dim = tuple(int(x) for x in np.atleast_1d(dim))
    if dim != (2, 2):
        raise DngError(f"{tags.where('CFARepeatPatternDim')}: {dim}; expected (2, 2) (a Bayer pattern)")
    pat = tags.raw("CFAPattern")
    if pat is None:
        raise DngError(f"{tags.where('CFAPattern')}: missing; expected a 2x2 Bayer pattern")
    pat = np.frombuffer(bytes(pat), np.uint8) if isinstance(pat, (bytes, bytearray)) else np.atleast_1d(pat)
    plane = tags.raw("CFAPlaneColor", b"\x00\x01\x02")
    plane = list(np.frombuffer(bytes(plane), np.uint8)) if isinstance(plane, (bytes, bytearray)) else list(plane)
    try:
        letters = "".join(PLANE_COLOR_LETTERS[int(plane[int(p)])] for p in pat)
    except (IndexError, ValueError):
        raise DngError(f"{tags.where('CFAPattern')}: values {list(map(int, pat))} do not index "
                       f"CFAPlaneColor {list(map(int, plane))}") from None
    if letters not in BAYER_PATTERNS:
        raise DngError(f"{tags.where('CFAPattern')}: {letters!r}; expected one of {', '.join(BAYER_PATTERNS)}")
    layout = int(tags.raw("CFALayout", 1))
    if layout != 1:
        raise DngError(f"{tags.where('CFALayout')}: {layout}; expected 1 (rectangular)")
    return letters


def _exif(tif) -> dict[str, Any]:
    try:
        ex = tif.pages[0].tags.get(T["ExifTag"])
        return dict(ex.value) if ex is not None and isinstance(ex.value, dict) else {}
    except Exception:  # a broken EXIF IFD must not make the raw unreadable
        return {}


def _first_number(v: Any) -> float | None:
    if v is None:
        return None
    if isinstance(v, (tuple, list)):
        if len(v) == 2 and all(isinstance(x, int) for x in v):  # rational (num, den)
            return v[0] / v[1] if v[1] else None
        v = v[0] if v else None
    try:
        return float(v)
    except (TypeError, ValueError):
        return None


def _first_value(v: Any) -> float | None:
    """First element of a SHORT/LONG tag value (ISOSpeedRatings may hold several)."""
    v = np.atleast_1d(np.asarray(v, dtype=np.float64)) if v is not None else np.zeros(0)
    return float(v[0]) if v.size else None


def _iso_and_exposure(tags: _Tags) -> tuple[float | None, float | None, dict]:
    extra = {}
    iso = None
    t = tags.tag("ISOSpeedRatings")
    if t is not None:
        iso = _first_value(t.value)
    else:
        for key in ("ISOSpeedRatings", "PhotographicSensitivity"):
            if key in tags.exif:
                iso = _first_value(tags.exif[key])
                break
    exp = tags.scalar("ExposureTime")
    if exp is None and "ExposureTime" in tags.exif:
        exp = _first_number(tags.exif["ExposureTime"])
    if iso is not None and iso <= 0:  # EXIF 0 = unknown
        extra["iso_tag"] = iso
        iso = None
    if exp is not None and exp <= 0:
        extra["exposure_time_tag"] = exp
        exp = None
    return iso, exp, extra


def _meta_from_tiff(tif, path: Path) -> tuple[CameraMeta, Any]:
    ifd0 = tif.pages[0]
    if T["DNGVersion"] not in ifd0.tags:
        raise DngError(f"{path}: DNGVersion: tag missing; expected a DNG file (this is a plain TIFF)")
    main = _main_ifd(tif, path)
    tags = _Tags(path, main, ifd0, _exif(tif))
    photometric = int(main.tags[T["PhotometricInterpretation"]].value) if T["PhotometricInterpretation"] in main.tags else -1
    if photometric == PHOTOMETRIC_LINEAR_RAW:
        raise DngError(f"{path}: PhotometricInterpretation: 34892 (LinearRaw); non-Bayer DNG not supported, "
                       f"expected 32803 (CFA)")
    if photometric != PHOTOMETRIC_CFA:
        raise DngError(f"{path}: PhotometricInterpretation: {photometric}; expected 32803 (CFA)")
    compression = int(main.tags[T["Compression"]].value) if T["Compression"] in main.tags else 1
    if compression not in SUPPORTED_COMPRESSION:
        name = " (GoPro VC-5)" if compression == 9 else ""
        raise DngError(f"{path}: Compression: {compression}{name} not supported; expected one of "
                       + ", ".join(f"{k} ({v})" for k, v in SUPPORTED_COMPRESSION.items()))
    spp = int(main.tags[T["SamplesPerPixel"]].value) if T["SamplesPerPixel"] in main.tags else 1
    if spp != 1:
        raise DngError(f"{path}: SamplesPerPixel: {spp}; expected 1 for a CFA image")
    _check_storage(path, main, tags)
    h, w = int(main.tags[T["ImageLength"]].value), int(main.tags[T["ImageWidth"]].value)

    aa = tags.numbers("ActiveArea")
    active_area = None
    if aa is not None:
        if aa.size != 4:
            raise DngError(f"{tags.where('ActiveArea')}: {aa.size} values; expected 4 (top, left, bottom, right)")
        active_area = tuple(int(x) for x in aa)
        t_, l_, b_, r_ = active_area
        if not (0 <= t_ < b_ <= h and 0 <= l_ < r_ <= w):
            raise DngError(f"{tags.where('ActiveArea')}: {list(active_area)}; expected a rectangle inside {h}x{w}")
    cfa_active = _cfa_pattern(tags)
    top, left = (active_area[0], active_area[1]) if active_area else (0, 0)
    cfa = shift_pattern(cfa_active, -top, -left)

    # black / white levels (DNG 1.6 section 5, "Mapping Raw Values ...")
    rep = tags.numbers("BlackLevelRepeatDim")
    rep = (1, 1) if rep is None else tuple(int(x) for x in rep)
    if len(rep) != 2 or min(rep) < 1:
        raise DngError(f"{tags.where('BlackLevelRepeatDim')}: {rep}; expected (rows, cols) >= 1")
    black = black_level_pattern(tags.numbers("BlackLevel"), rep, where=tags.where("BlackLevel"))
    aw = (active_area[3] - active_area[1]) if active_area else w
    ah = (active_area[2] - active_area[0]) if active_area else h
    dh, dv = tags.numbers("BlackLevelDeltaH"), tags.numbers("BlackLevelDeltaV")
    if dh is not None and dh.size != aw:
        raise DngError(f"{tags.where('BlackLevelDeltaH')}: {dh.size} values; expected the active width {aw}")
    if dv is not None and dv.size != ah:
        raise DngError(f"{tags.where('BlackLevelDeltaV')}: {dv.size} values; expected the active height {ah}")
    bps = int(np.atleast_1d(tags.raw("BitsPerSample", 16))[0])
    wl = tags.numbers("WhiteLevel")
    white = float(wl[0]) if wl is not None else float(2 ** bps - 1)
    lin = tags.numbers("LinearizationTable")

    def pair(name):
        v = tags.numbers(name)
        if v is None:
            return None
        if v.size != 2:
            raise DngError(f"{tags.where(name)}: {v.size} values; expected 2 (horizontal, vertical)")
        return (float(v[0]), float(v[1]))

    def vec3(name, n=3):
        v = tags.numbers(name)
        if v is not None and v.size != n:
            raise DngError(f"{tags.where(name)}: {v.size} values; expected {n}")
        return v

    def illuminant(name):
        v = tags.raw(name)
        return None if v is None else int(v)

    noise = tags.numbers("NoiseProfile")
    if noise is not None:
        if noise.size % 2 or noise.size == 0:
            raise DngError(f"{tags.where('NoiseProfile')}: {noise.size} values; expected (S, O) pairs")
        noise = noise.reshape(-1, 2)

    opcode_lists = {}
    for k in (1, 2, 3):
        name = f"OpcodeList{k}"
        v = tags.raw(name)
        opcode_lists[k] = [] if v is None else parse_opcode_list(bytes(v), where=tags.where(name))

    iso, exposure, extra = _iso_and_exposure(tags)
    extra.update({
        "dng_version": list(np.frombuffer(bytes(tags.raw("DNGVersion")), np.uint8).tolist())
        if isinstance(tags.raw("DNGVersion"), (bytes, bytearray)) else tags.raw("DNGVersion"),
        "image_size": [h, w],
        "bits_per_sample": bps,
        "compression": compression,
        "main_ifd": "IFD0" if main is ifd0 else "SubIFD",
        "cfa_pattern_tag": cfa_active,
    })
    for name in ("BaselineNoise", "DefaultScale"):
        v = tags.numbers(name)
        if v is not None:
            extra[name] = v.tolist()
    for name in ("CameraSerialNumber", "ProfileName"):
        s = tags.text(name)
        if s:
            extra[name] = s
    masked = tags.numbers("MaskedAreas")
    if masked is not None:
        extra["MaskedAreas"] = masked.reshape(-1, 4).astype(int).tolist()
    for key in ("FNumber", "FocalLength", "DateTimeOriginal"):
        if key in tags.exif:
            v = tags.exif[key]
            extra[key] = _first_number(v) if key != "DateTimeOriginal" else str(v)

    meta = CameraMeta(
        make=tags.text("Make"),
        model=tags.text("Model"),
        unique_camera_model=tags.text("UniqueCameraModel"),
        cfa=cfa,
        black_level=black,
        black_level_delta_h=dh,
        black_level_delta_v=dv,
        white_level=white,
        linearization_table=lin,
        as_shot_neutral=vec3("AsShotNeutral"),
        as_shot_white_xy=vec3("AsShotWhiteXY", 2),
        color_matrix1=tags.matrix("ColorMatrix1"),
        color_matrix2=tags.matrix("ColorMatrix2"),
        camera_calibration1=tags.matrix("CameraCalibration1"),
        camera_calibration2=tags.matrix("CameraCalibration2"),
        forward_matrix1=tags.matrix("ForwardMatrix1"),
        forward_matrix2=tags.matrix("ForwardMatrix2"),
        analog_balance=vec3("AnalogBalance"),
        calibration_illuminant1=illuminant("CalibrationIlluminant1"),
        calibration_illuminant2=illuminant("CalibrationIlluminant2"),
        baseline_exposure=tags.scalar("BaselineExposure") or 0.0,
        noise_profile=noise,
        iso=iso,
        exposure_time_s=exposure,
        orientation=int(tags.raw("Orientation", 1)),
        active_area=active_area,
        default_crop_origin=pair("DefaultCropOrigin"),
        default_crop_size=pair("DefaultCropSize"),
        opcode_list1=opcode_lists[1],
        opcode_list2=opcode_lists[2],
        opcode_list3=opcode_lists[3],
        origin=(0, 0),
        source=str(path),
        extra=extra,
    )
    return meta, main


def black_level_pattern(values: np.ndarray | None, rep: tuple[int, int], *, where: str,
                        error: type[Exception] = DngError) -> np.ndarray:
    """The BlackLevel tag as a ``rep`` = (rows, cols) array (DNG 1.6, BlackLevel / BlackLevelRepeatDim).

    No tag means 0; a single value fills the pattern; otherwise exactly rows*cols values.
    """
    if values is None:
        return np.zeros(rep)
    if values.size == rep[0] * rep[1]:
        return values.reshape(rep)
    if values.size == 1:
        return np.full(rep, values[0])
    raise error(f"{where}: {values.size} values; expected {rep[0]}x{rep[1]} (BlackLevelRepeatDim)")


def read_dng_meta(path: str | os.PathLike) -> CameraMeta:
    """Read the metadata of a DNG (tags only; no pixel decoding).

    Parameters
    ----------
    path : path-like
        A DNG file with a CFA (Bayer) main image.

    Returns
    -------
    CameraMeta
        Tags in DNG semantics (DNG 1.6 spec ch. 4); ``origin=(0, 0)``;
        ``cfa`` describes the stored image's pixel (0, 0).

    Raises
    ------
    DngError
        Missing file, not a DNG, non-CFA, unsupported compression, truncated
        pixel data, malformed tag.
    """
    path = Path(path)
    tif = _open_tiff(path)
    try:
        if len(tif.pages) == 0:
            raise DngError(f"{path}: IFD0: no readable image file directory; expected a DNG file")
        meta, _ = _meta_from_tiff(tif, path)
    except (IndexError, KeyError, TypeError, ValueError, struct.error) as exc:
        # tifffile's errors on corrupt tag structures; never a traceback for a bad file
        raise DngError(f"{path}: malformed TIFF tag structure ({type(exc).__name__}: {exc})") from None
    finally:
        tif.close()
    return meta


def read_dng(path: str | os.PathLike) -> RawFrame:
    """Read a DNG: the full stored CFA image in DN plus its metadata.

    Parameters
    ----------
    path : path-like
        A DNG file with a CFA (Bayer) main image.

    Returns
    -------
    RawFrame
        ``kind="raw_dn"``; ``data`` float32 H x W DN of the whole stored raw
        image (masked borders included), exactly LibRaw's ``raw_image``;
        ``meta`` as :func:`read_dng_meta`.
    """
    import rawpy

    path = Path(path)
    meta = read_dng_meta(path)
    h, w = meta.extra["image_size"]
    try:
        with rawpy.imread(str(path)) as raw:
            data = np.array(raw.raw_image, dtype=np.float32, copy=True)  # copy inside the with block
    except rawpy.LibRawFileUnsupportedError:
        # LibRaw refuses images whose active area is under 22 px a side; tiny
        # uncompressed files (test fixtures) are read directly with tifffile.
        t, l, b, r = meta.active_area or (0, 0, h, w)
        if min(b - t, r - l) < 22 and meta.extra["compression"] == 1:
            return RawFrame(data=_read_uncompressed(path), meta=meta, kind="raw_dn",
                            history=[f"read_dng({path.name})"])
        raise DngError(f"{path}: pixel data: LibRaw does not support this file") from None
    except (rawpy.LibRawError, OSError) as exc:
        raise DngError(f"{path}: pixel data: LibRaw cannot decode it ({type(exc).__name__}: {exc})") from None
    if data.shape != (h, w):
        raise DngError(f"{path}: pixel data: LibRaw returned {data.shape[0]}x{data.shape[1]}; "
                       f"expected the stored {h}x{w}")
    if meta.linearization_table is not None:
        data = _unlinearize(data, meta.linearization_table, path)
    return RawFrame(data=data, meta=meta, kind="raw_dn", history=[f"read_dng({path.name})"])


def _read_uncompressed(path: Path) -> np.ndarray:
    import tifffile

    with tifffile.TiffFile(str(path)) as tif:
        return np.asarray(_main_ifd(tif, path).asarray(), dtype=np.float32)


def _unlinearize(values: np.ndarray, table: np.ndarray, path: Path) -> np.ndarray:
    """Undo LibRaw's LinearizationTable lookup: smallest stored code with ``table[code] == value``.

    LibRaw applies the table while unpacking; ``raw_dn`` keeps stored codes and
    the table stays in the metadata (the ``normalize`` stage applies it), so
    ``table[result]`` equals LibRaw's output exactly, and ``result`` is the
    stored code whenever the table is strictly increasing.
    """
    t = np.asarray(table, dtype=np.float64)
    order = np.argsort(t, kind="stable")
    st = t[order]
    pos = np.clip(np.searchsorted(st, values, side="left"), 0, st.size - 1)
    if not np.array_equal(st[pos], values):
        raise DngError(f"{path}: LinearizationTable: LibRaw returned values that are not in the table")
    return order[pos].astype(np.float32)
