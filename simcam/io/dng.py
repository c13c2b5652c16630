"""Read DNG files: pixels through rawpy (LibRaw), every tag through tifffile.

:func:`read_dng` returns the FULL stored raw image (``kind="raw_dn"``, float32
DN, ``meta.origin == (0, 0)``); cropping to the active area / default crop is
the ``crop`` stage's job. :func:`read_dng_meta` reads the tags only.

Tag semantics follow the DNG specification (Adobe, 1.7.0.0), chapter 4 (tags)
and chapter 5 (mapping raw values). ``meta.cfa`` is the 2x2 pattern of the
stored image's pixel (0, 0): CFAPattern is anchored at the top-left of the
ActiveArea (DNG SDK ``dng_mosaic_info``; LibRaw agrees, see the tests), so an
odd ActiveArea offset shifts it.

Bad input is one :class:`DngError` line naming the file and the tag, never a traceback and never
silently wrong pixels: raw IFD entries are checked before tifffile parses them
(:mod:`simcam.io.dng_tags`), every value before use (finite, in range, sizes capped against the
file size and the image size), tifffile's and rawpy's exceptions are wrapped, tifffile's log records
and LibRaw's messages on stderr are captured (folded into the error, never printed).
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import os
import tempfile
import threading
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..cfa import BAYER_PATTERNS, shift_pattern
from ..errors import DngError
from ..frame import COLOUR_MATRIX_TAGS, CameraMeta, RawFrame
from .dcp import embedded_profile_extra
from .dng_tags import T, check_raw_entries
from .opcodes import check_opcode_work, parse_opcode_list

PHOTOMETRIC_CFA = 32803
PHOTOMETRIC_LINEAR_RAW = 34892
#: Compression codes LibRaw decodes for DNG CFA data: none, lossless JPEG, deflate.
SUPPORTED_COMPRESSION = {1: "uncompressed", 7: "lossless JPEG", 8: "deflate"}
#: CFAPlaneColor codes (TIFF/EP): 0 red, 1 green, 2 blue, 3 cyan, 4 magenta, 5 yellow, 6 white.
PLANE_COLOR_LETTERS = "RGBCMYW"
RATIONAL_TYPES = (5, 10)  # RATIONAL, SRATIONAL
#: Largest image side the DNG SDK accepts (``kMaxImageSide``, dng_sdk_limits.h).
MAX_IMAGE_SIDE = 65000
#: Largest BlackLevelRepeatDim rows / columns (DNG SDK ``kMaxBlackPattern``, dng_sdk_limits.h).
MAX_BLACK_PATTERN = 8
#: Best compression ratio of deflate (zlib's documented limit, 1032:1): a cap on the pixels a
#: deflate-compressed file of a given size can hold.
DEFLATE_MAX_RATIO = 1032
#: Messages kept from tifffile's logger or LibRaw's stderr in an error line.
_MAX_LOG_CHARS = 200


# ---------------------------------------------------------------------------
# library output: tifffile's logger and LibRaw's stderr, captured (never printed raw)
# ---------------------------------------------------------------------------
class _LogCapture(logging.Filter):
    """Swallow and keep the records of the ``tifffile`` logger while installed."""

    def __init__(self):
        super().__init__()
        self.messages: list[str] = []

    def filter(self, record: logging.LogRecord) -> bool:
        self.messages.append(" ".join(record.getMessage().split()))
        return False

    def suffix(self) -> str:
        """`` (tifffile: first message)`` or ''."""
        return f" (tifffile: {self.messages[0][:_MAX_LOG_CHARS]})" if self.messages else ""


@contextlib.contextmanager
def _tifffile_log():
    logger = logging.getLogger("tifffile")
    cap = _LogCapture()
    logger.addFilter(cap)
    try:
        yield cap
    finally:
        logger.removeFilter(cap)


class _Fd2Capture:
    """Redirect file descriptor 2 into a temporary file while LibRaw decodes ``name``.

    LibRaw reports corrupt data from C, below Python's ``sys.stderr``, through its data callback:
    ``fprintf(stderr, "%s: Unexpected end of file", fname)`` and ``"%s: data corrupted at %d"`` (LibRaw
    0.21, ``default_data_callback``; its memory callback likewise), always led by the file name it was
    given. :attr:`text` holds the lines led by ``name`` written during this capture. Overlapping captures (threads) share
    one redirection; whatever else reached fd 2 meanwhile (another thread's output: a warning, an
    error line, ``-X importtime``) is not this file's report and is written to the real stderr when
    the redirection ends.
    """

    _lock = threading.Lock()
    _users = 0
    _saved: int | None = None
    _file = None
    _names: set[str] = set()

    def __init__(self, name: str):
        self.name = str(name)

    def __enter__(self) -> "_Fd2Capture":
        cls = type(self)
        self.text, self._active = "", False
        with cls._lock:
            if cls._users == 0:
                _flush_stderr()
                try:
                    saved = os.dup(2)
                except OSError:  # no stderr at all (a daemon): nothing to capture
                    return self
                cls._file, cls._saved = tempfile.TemporaryFile(), saved
                os.dup2(cls._file.fileno(), 2)
            cls._users += 1
            cls._names.add(self.name)
            self._active = True
            self._start = os.lseek(cls._file.fileno(), 0, os.SEEK_END)
        return self

    def __exit__(self, *exc) -> None:
        cls = type(self)
        if not self._active:
            return
        with cls._lock:
            _flush_stderr()
            fd = cls._file.fileno()
            end = os.lseek(fd, 0, os.SEEK_END)
            lead = f"{self.name}: ".encode()
            lines = os.pread(fd, end - self._start, self._start).splitlines(keepends=True)
            self.text = b"".join(ln for ln in lines if ln.startswith(lead)).decode("utf-8", "replace").strip()
            cls._users -= 1
            if cls._users == 0:
                leads = tuple(f"{n}: ".encode() for n in cls._names)
                rest = [ln for ln in os.pread(fd, end, 0).splitlines(keepends=True) if not ln.startswith(leads)]
                with contextlib.suppress(OSError):
                    _write_all(cls._saved, b"".join(rest))
                os.dup2(cls._saved, 2)
                os.close(cls._saved)
                cls._file.close()
                cls._saved = cls._file = None
                cls._names = set()

    def message(self) -> str:
        """The captured text as one short line."""
        return " ".join(self.text.split())[:_MAX_LOG_CHARS]


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def _flush_stderr() -> None:
    import sys

    with contextlib.suppress(Exception):
        sys.stderr.flush()


# ---------------------------------------------------------------------------
# file-level checks
# ---------------------------------------------------------------------------
def _check_path(path: Path) -> None:
    if not path.exists():
        raise DngError(f"{path}: no such file")
    if path.is_dir():
        raise DngError(f"{path}: is a directory; expected a DNG file")


def _tiff_call(path: Path, what: str, fn: Callable[[], Any], log: _LogCapture | None = None):
    """``fn()``, a tifffile call; any error it raises becomes one DngError line naming ``what``."""
    try:
        return fn()
    except DngError:
        raise
    except Exception as exc:  # tifffile raises TypeError, IndexError, ... on corrupt structures
        msg = " ".join(str(exc).split())[:_MAX_LOG_CHARS]
        raise DngError(f"{path}: {what}: tifffile cannot read it ({type(exc).__name__}: {msg})"
                       f"{log.suffix() if log else ''}; expected a valid TIFF structure") from None


@contextlib.contextmanager
def _open_tiff(path: Path):
    """The file opened with tifffile, its raw IFD entries checked first (:mod:`.dng_tags`).

    Yields ``(tif, log)``; tifffile's log records are captured in ``log`` for the whole block.
    """
    import tifffile

    _check_path(path)
    check_raw_entries(path)
    with _tifffile_log() as log:
        try:
            tif = tifffile.TiffFile(str(path))
        except tifffile.TiffFileError as exc:
            raise DngError(f"{path}: not a TIFF/DNG file ({exc}){log.suffix()}") from None
        except Exception as exc:
            raise DngError(f"{path}: IFD0: tifffile cannot parse the TIFF structure "
                           f"({type(exc).__name__}: {' '.join(str(exc).split())[:_MAX_LOG_CHARS]}){log.suffix()}; "
                           f"expected a valid TIFF structure") from None
        try:
            yield tif, log
        finally:
            tif.close()


class _Tags:
    """Tag lookup: main raw IFD first, then IFD0, then the EXIF IFD.

    Every tifffile access goes through :func:`_tiff_call`; values are checked before use.
    """

    def __init__(self, path: Path, main, ifd0, exif: dict[str, Any], log: _LogCapture | None = None):
        self.path, self.main, self.ifd0, self.exif, self.log = path, main, ifd0, exif, log

    def tag(self, name: str, *, main_only: bool = False):
        code = T[name]
        for page in (self.main,) if main_only else (self.main, self.ifd0):
            t = _tiff_call(self.path, name, lambda: page.tags.get(code), self.log)
            if t is not None:
                return t
        return None

    def where(self, name: str) -> str:
        return f"{self.path}: {name}"

    def raw(self, name: str, default=None, *, main_only: bool = False):
        t = self.tag(name, main_only=main_only)
        return default if t is None else _tiff_call(self.path, name, lambda: t.value, self.log)

    def integer(self, name: str, default: int | None = None, *, lo: int = 0, hi: int = 2 ** 32 - 1,
                main_only: bool = False) -> int | None:
        """A one-value integer tag (the first value of a multi-value one) within ``lo .. hi``."""
        v = self.numbers(name, main_only=main_only)
        if v is None:
            return default
        if v.size < 1:
            raise DngError(f"{self.where(name)}: no value; expected an integer {lo} to {hi}")
        x = float(v[0])
        if not (x.is_integer() and lo <= x <= hi):
            raise DngError(f"{self.where(name)}: {x:g}; expected an integer {lo} to {hi}")
        return int(x)

    def numbers(self, name: str, *, main_only: bool = False) -> np.ndarray | None:
        """Tag value as a finite float64 array (rationals divided), or None if absent."""
        t = self.tag(name, main_only=main_only)
        if t is None:
            return None
        value = _tiff_call(self.path, name, lambda: t.value, self.log)
        v = _as_numbers(value, _tiff_call(self.path, name, lambda: t.dtype, self.log), self.where(name))
        if not np.all(np.isfinite(v)):
            raise DngError(f"{self.where(name)}: non-finite value {v[~np.isfinite(v)][0]}; expected finite numbers")
        return v

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
        if isinstance(v, (bytes, bytearray)):
            v = bytes(v).split(b"\0", 1)[0].decode("latin-1")
        return str(v).strip("\0").strip()


def _as_numbers(value: Any, dtype: int, where: str) -> np.ndarray:
    dtype = int(dtype)
    if isinstance(value, (bytes, bytearray)):
        return np.frombuffer(bytes(value), dtype=np.uint8).astype(np.float64)
    try:
        vals = np.atleast_1d(np.asarray(value, dtype=np.float64) if not isinstance(value, int) else [value])
    except (TypeError, ValueError):
        raise DngError(f"{where}: value {str(value)[:40]!r}; expected numbers") from None
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
    return vals.astype(np.float64).ravel()


def _main_ifd(tif, path: Path, log: _LogCapture | None = None):
    """The IFD holding the main raw image: NewSubfileType == 0 in IFD0 or a SubIFD (DNG 1.7.0.0 chapter 3)."""
    ifd0 = _tiff_call(path, "IFD0", lambda: tif.pages[0], log)
    candidates = [ifd0] + list(_tiff_call(path, "SubIFDs", lambda: getattr(ifd0, "pages", None) or [], log))
    for page in candidates:
        nst = _tiff_call(path, "NewSubfileType", lambda: page.tags.get(T["NewSubfileType"]), log)
        if int(_tiff_call(path, "NewSubfileType", lambda: nst.value, log) if nst is not None else 0) == 0:
            return page
    raise DngError(f"{path}: NewSubfileType: no IFD with value 0 (main image) in IFD0 or its SubIFDs")


def _chunk_arrays(path: Path, tags: _Tags, off_name: str, cnt_name: str) -> tuple[np.ndarray, np.ndarray]:
    offs, cnts = tags.numbers(off_name, main_only=True), tags.numbers(cnt_name, main_only=True)
    if offs is None or cnts is None:
        raise DngError(f"{path}: {off_name}/{cnt_name}: missing in the main image IFD; expected pixel data")
    return offs.astype(np.int64), cnts.astype(np.int64)


def _min_stored_bytes(compression: int, samples: int, bps: int) -> int:
    """Fewest bytes ``samples`` samples of ``bps`` bits can be stored in.

    Uncompressed: all their bits. Lossless JPEG: at least one bit per sample (every difference
    has a Huffman code of 1 to 16 bits, ITU-T T.81 annex H). Deflate: at most 1032:1.
    """
    raw = math.ceil(samples * bps / 8)
    if compression == 1:
        return raw
    if compression == 7:
        return math.ceil(samples / 8)
    return math.ceil(raw / DEFLATE_MAX_RATIO)


def _check_jpeg_starts(path: Path, off_name: str, offs: np.ndarray) -> None:
    """Each lossless-JPEG strip or tile must start with the SOI marker FF D8 (ITU-T T.81 annex B).

    LibRaw does not report a strip that is not JPEG data: it returns uninitialised memory.
    """
    with open(path, "rb") as f:
        for k, off in enumerate(offs.tolist()):
            f.seek(off)
            if f.read(2) != b"\xff\xd8":
                raise DngError(f"{path}: {off_name}: chunk {k} at byte {off} does not start with a JPEG SOI marker "
                               f"(FF D8); expected lossless JPEG data (Compression 7)")


def _check_storage(path: Path, tags: _Tags, h: int, w: int, bps: int, compression: int) -> str:
    """Check strip/tile layout against the image size and the file size (TIFF 6.0 sections 3 and 15).

    Catches truncated files, and caps the image size a file can claim: its strips or tiles must be
    able to hold ``h x w`` samples (:func:`_min_stored_bytes`), so a small file cannot ask for
    gigabytes of pixels. Returns the names of the offset / byte-count tags (for LibRaw's errors).
    """
    size = os.path.getsize(path)
    tiled = tags.tag("TileOffsets", main_only=True) is not None
    off_name, cnt_name = ("TileOffsets", "TileByteCounts") if tiled else ("StripOffsets", "StripByteCounts")
    for other in (("StripOffsets", "StripByteCounts") if tiled else ("TileWidth", "TileLength", "TileByteCounts")):
        if tags.tag(other, main_only=True) is not None:  # DNG SDK IsValidDNG: "uses both strips and tiles"
            raise DngError(f"{path}: {other}: present in a {'tiled' if tiled else 'strip'} image ({off_name}); "
                           f"expected strips or tiles, not both")
    offs, cnts = _chunk_arrays(path, tags, off_name, cnt_name)
    if tiled:
        tw = tags.integer("TileWidth", lo=1, hi=2 ** 32 - 1, main_only=True)
        tl = tags.integer("TileLength", lo=1, hi=2 ** 32 - 1, main_only=True)
        if tw is None or tl is None:
            raise DngError(f"{path}: TileWidth/TileLength: missing in a tiled image; expected the tile size")
        n_expected = math.ceil(w / tw) * math.ceil(h / tl)
        chunk_samples = tw * tl
    else:
        rps = tags.integer("RowsPerStrip", h, lo=1, main_only=True)
        rps = min(rps, h)
        n_expected = math.ceil(h / rps)
        chunk_samples = rps * w
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
    if compression == 7:
        _check_jpeg_starts(path, off_name, offs)
    if compression == 1 and tiled:
        need = _min_stored_bytes(1, chunk_samples, bps)
        if np.any(cnts < need):
            raise DngError(f"{path}: {cnt_name}: a tile has fewer than the {need} bytes it needs (truncated pixel data)")
    total_need = _min_stored_bytes(compression, h * w, bps)
    if int(cnts.sum()) < total_need:
        kind = SUPPORTED_COMPRESSION.get(compression, "compressed")
        raise DngError(
            f"{path}: {cnt_name}: {int(cnts.sum())} bytes of {kind} pixel data for a {w}x{h} image; "
            f"expected at least {total_need} (truncated pixel data or an impossible image size)")
    return f"{off_name}/{cnt_name}"


def _cfa_pattern(tags: _Tags) -> str:
    """The 2x2 pattern at the ActiveArea's top-left (CFARepeatPatternDim, CFAPattern, CFAPlaneColor, CFALayout)."""
    dim = tags.raw("CFARepeatPatternDim", (2, 2))
    dim = tuple(int(x) for x in np.atleast_1d(dim))
    if dim != (2, 2):
        raise DngError(f"{tags.where('CFARepeatPatternDim')}: {dim}; expected (2, 2) (a Bayer pattern)")
    pat = tags.raw("CFAPattern")
    if pat is None:
        raise DngError(f"{tags.where('CFAPattern')}: missing; expected a 2x2 Bayer pattern")
    pat = np.frombuffer(bytes(pat), np.uint8) if isinstance(pat, (bytes, bytearray)) else np.atleast_1d(pat)
    if pat.size != 4:
        raise DngError(f"{tags.where('CFAPattern')}: {pat.size} values; expected 4 (a 2x2 Bayer pattern)")
    plane = tags.raw("CFAPlaneColor", b"\x00\x01\x02")
    plane = list(np.frombuffer(bytes(plane), np.uint8)) if isinstance(plane, (bytes, bytearray)) else list(plane)
    try:
        letters = "".join(PLANE_COLOR_LETTERS[int(plane[int(p)])] for p in pat)
    except (IndexError, ValueError):
        raise DngError(f"{tags.where('CFAPattern')}: values {list(map(int, pat))} do not index "
                       f"CFAPlaneColor {list(map(int, plane))}") from None
    if letters not in BAYER_PATTERNS:
        raise DngError(f"{tags.where('CFAPattern')}: {letters!r}; expected one of {', '.join(BAYER_PATTERNS)}")
    layout = tags.integer("CFALayout", 1)
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
    """A finite number from an EXIF value (a rational pair, a sequence, a number), else None."""
    if v is None:
        return None
    if isinstance(v, (tuple, list)):
        if len(v) == 2 and all(isinstance(x, int) for x in v):  # rational (num, den)
            return v[0] / v[1] if v[1] else None
        v = v[0] if v else None
    try:
        x = float(v)
    except (TypeError, ValueError, OverflowError):
        return None
    return x if math.isfinite(x) else None


def _first_value(v: Any) -> float | None:
    """First element of a SHORT/LONG tag value (ISOSpeedRatings may hold several); None if not a finite number."""
    try:
        arr = np.atleast_1d(np.asarray(v, dtype=np.float64)).ravel() if v is not None else np.zeros(0)
    except (TypeError, ValueError):
        return None
    return float(arr[0]) if arr.size and np.isfinite(arr[0]) else None


def _iso_and_exposure(tags: _Tags) -> tuple[float | None, float | None, dict]:
    extra = {}
    iso = None
    v = tags.numbers("ISOSpeedRatings")
    if v is not None:
        iso = _first_value(v)
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


def _image_structure(path: Path, tags: _Tags) -> tuple[int, int, int, int]:
    """(height, width, bits per sample, compression) of the raw IFD, each checked (TIFF 6.0 section 8;
    DNG 1.7.0.0 chapter 3: a CFA image is PhotometricInterpretation 32803, one sample per pixel)."""
    photometric = tags.integer("PhotometricInterpretation", -1, lo=0, hi=65535, main_only=True)
    if photometric == PHOTOMETRIC_LINEAR_RAW:
        raise DngError(f"{path}: PhotometricInterpretation: 34892 (LinearRaw); non-Bayer DNG not supported, "
                       f"expected 32803 (CFA)")
    if photometric != PHOTOMETRIC_CFA:
        raise DngError(f"{path}: PhotometricInterpretation: {photometric}; expected 32803 (CFA)")
    compression = tags.integer("Compression", 1, lo=0, hi=65535, main_only=True)
    if compression not in SUPPORTED_COMPRESSION:
        name = " (GoPro VC-5)" if compression == 9 else ""
        raise DngError(f"{path}: Compression: {compression}{name} not supported; expected one of "
                       + ", ".join(f"{k} ({v})" for k, v in SUPPORTED_COMPRESSION.items()))
    spp = tags.integer("SamplesPerPixel", 1, lo=0, hi=65535, main_only=True)
    if spp != 1:
        raise DngError(f"{path}: SamplesPerPixel: {spp}; expected 1 for a CFA image")
    sample_format = tags.integer("SampleFormat", 1, lo=0, hi=65535, main_only=True)
    if sample_format != 1:
        raise DngError(f"{path}: SampleFormat: {sample_format}; expected 1 (unsigned integer samples)")
    h = tags.integer("ImageLength", lo=1, hi=MAX_IMAGE_SIDE, main_only=True)
    w = tags.integer("ImageWidth", lo=1, hi=MAX_IMAGE_SIDE, main_only=True)
    if h is None or w is None:
        raise DngError(f"{path}: ImageWidth/ImageLength: missing in the main image IFD; expected the image size")
    bps = tags.integer("BitsPerSample", 1, lo=8, hi=16, main_only=True)  # DNG SDK: CFA data 8..32 bits; LibRaw's 16
    planar = tags.integer("PlanarConfiguration", 1, lo=0, hi=65535, main_only=True)
    if planar != 1:
        raise DngError(f"{path}: PlanarConfiguration: {planar}; expected 1 (chunky, DNG SDK ``IsValidDNG``)")
    return h, w, bps, compression


def _active_area(tags: _Tags, h: int, w: int) -> tuple[int, int, int, int] | None:
    """ActiveArea (top, left, bottom, right), a non-empty rectangle inside the stored image."""
    aa = tags.numbers("ActiveArea")
    if aa is None:
        return None
    if aa.size != 4:
        raise DngError(f"{tags.where('ActiveArea')}: {aa.size} values; expected 4 (top, left, bottom, right)")
    active_area = tuple(int(x) for x in aa)
    t_, l_, b_, r_ = active_area
    if not (0 <= t_ < b_ <= h and 0 <= l_ < r_ <= w):
        raise DngError(f"{tags.where('ActiveArea')}: {list(active_area)}; expected a rectangle inside {h}x{w}")
    return active_area  # type: ignore[return-value]


def _black_levels(tags: _Tags, ah: int, aw: int):
    """BlackLevel as a (rows, cols) pattern and BlackLevelDeltaH/V (DNG 1.7.0.0 chapter 4 and chapter 5,
    "Mapping Raw Values to Linear Reference Values"); BlackLevelRepeatDim at most 8 x 8 (DNG SDK
    ``kMaxBlackPattern``), the deltas one per active column / row."""
    rep = tags.numbers("BlackLevelRepeatDim")
    rep = (1, 1) if rep is None else tuple(int(x) for x in rep)
    if len(rep) != 2 or not all(1 <= r <= MAX_BLACK_PATTERN for r in rep):
        raise DngError(f"{tags.where('BlackLevelRepeatDim')}: {rep}; expected (rows, cols) each 1 to "
                       f"{MAX_BLACK_PATTERN}")
    black = black_level_pattern(tags.numbers("BlackLevel"), rep, where=tags.where("BlackLevel"))
    dh, dv = tags.numbers("BlackLevelDeltaH"), tags.numbers("BlackLevelDeltaV")
    if dh is not None and dh.size != aw:
        raise DngError(f"{tags.where('BlackLevelDeltaH')}: {dh.size} values; expected the active width {aw}")
    if dv is not None and dv.size != ah:
        raise DngError(f"{tags.where('BlackLevelDeltaV')}: {dv.size} values; expected the active height {ah}")
    return black, dh, dv


def _white_level(tags: _Tags, bps: int) -> float:
    """WhiteLevel (default 2^BitsPerSample - 1, DNG 1.7.0.0 chapter 4), at least 1."""
    wl = tags.numbers("WhiteLevel")
    if wl is None:
        return float(2 ** bps - 1)
    if wl.size < 1 or wl[0] < 1:
        raise DngError(f"{tags.where('WhiteLevel')}: {wl.tolist()}; expected a positive level")
    return float(wl[0])


def _default_crop(tags: _Tags, ah: int, aw: int):
    """DefaultCropOrigin / DefaultCropSize as (x, y) pairs: finite, inside the active area
    (DNG 1.7.0.0 chapter 4: relative to the ActiveArea's top-left, before DefaultScale)."""
    def pair(name):
        v = tags.numbers(name)
        if v is None:
            return None
        if v.size != 2:
            raise DngError(f"{tags.where(name)}: {v.size} values; expected 2 (horizontal, vertical)")
        return (float(v[0]), float(v[1]))

    origin, size = pair("DefaultCropOrigin"), pair("DefaultCropSize")
    if size is not None and not (size[0] >= 1 and size[1] >= 1):
        raise DngError(f"{tags.where('DefaultCropSize')}: {list(size)}; expected at least 1 x 1 pixel")
    if origin is not None and size is not None:
        x0, y0 = origin
        if round(x0) + round(size[0]) > aw or round(y0) + round(size[1]) > ah:
            raise DngError(f"{tags.where('DefaultCropSize')}: {list(size)} at DefaultCropOrigin {list(origin)} "
                           f"ends outside the {aw}x{ah} active area; expected a crop inside it")
    return origin, size


def _opcode_lists(tags: _Tags, h: int, w: int, ah: int, aw: int) -> dict[int, list]:
    """OpcodeList1/2/3 parsed (DNG 1.7.0.0 chapter 7); GainMaps decoded and checked; the work of each
    list capped against the image it applies to (list 1: the stored image; 2: the active area; 3: the
    active area's three colour planes)."""
    lists = {}
    for k, dims in ((1, (h, w, 1)), (2, (ah, aw, 1)), (3, (ah, aw, 3))):
        name = f"OpcodeList{k}"
        v = tags.raw(name)
        lists[k] = [] if v is None else parse_opcode_list(bytes(v), where=tags.where(name))
        check_opcode_work(lists[k], *dims, where=tags.where(name))
    return lists


def _meta_from_tiff(tif, path: Path, log: _LogCapture | None = None) -> tuple[CameraMeta, Any]:
    ifd0 = _tiff_call(path, "IFD0", lambda: tif.pages[0], log)
    if T["DNGVersion"] not in ifd0.tags:
        raise DngError(f"{path}: DNGVersion: tag missing; expected a DNG file (this is a plain TIFF)")
    main = _main_ifd(tif, path, log)
    tags = _Tags(path, main, ifd0, _exif(tif), log)
    h, w, bps, compression = _image_structure(path, tags)
    pixel_tags = _check_storage(path, tags, h, w, bps, compression)

    active_area = _active_area(tags, h, w)
    cfa_active = _cfa_pattern(tags)
    top, left = (active_area[0], active_area[1]) if active_area else (0, 0)
    cfa = shift_pattern(cfa_active, -top, -left)
    aw = (active_area[3] - active_area[1]) if active_area else w
    ah = (active_area[2] - active_area[0]) if active_area else h

    black, dh, dv = _black_levels(tags, ah, aw)
    lin = tags.numbers("LinearizationTable")
    white = _white_level(tags, bps)
    crop_origin, crop_size = _default_crop(tags, ah, aw)

    def vec3(name, n=3):
        v = tags.numbers(name)
        if v is not None and v.size != n:
            raise DngError(f"{tags.where(name)}: {v.size} values; expected {n}")
        return v

    def illuminant(name):
        return tags.integer(name, None, lo=0, hi=65535)

    noise = tags.numbers("NoiseProfile")
    if noise is not None:
        if noise.size % 2 or noise.size == 0:
            raise DngError(f"{tags.where('NoiseProfile')}: {noise.size} values; expected (S, O) pairs")
        noise = noise.reshape(-1, 2)
    orientation = tags.integer("Orientation", 1, lo=0, hi=65535)
    if orientation > 9:
        raise DngError(f"{tags.where('Orientation')}: {orientation}; expected 1 to 8 (TIFF 6.0), or 0 / 9 (unknown)")
    orientation = 1 if orientation in (0, 9) else orientation  # unknown: upright, as the DNG SDK reads it

    opcode_lists = _opcode_lists(tags, h, w, ah, aw)

    iso, exposure, extra = _iso_and_exposure(tags)
    version = tags.raw("DNGVersion")
    extra.update({
        "dng_version": list(np.frombuffer(bytes(version), np.uint8).tolist())
        if isinstance(version, (bytes, bytearray)) else version,
        "image_size": [h, w],
        "bits_per_sample": bps,
        "compression": compression,
        "pixel_tags": pixel_tags,
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
        if masked.size % 4:
            raise DngError(f"{tags.where('MaskedAreas')}: {masked.size} values; expected rectangles of 4")
        extra["MaskedAreas"] = masked.reshape(-1, 4).astype(int).tolist()
    for key in ("FNumber", "FocalLength", "DateTimeOriginal"):
        if key in tags.exif:
            v = tags.exif[key]
            extra[key] = _first_number(v) if key != "DateTimeOriginal" else str(v)
    extra.update(embedded_profile_extra(ifd0, path))  # camera-profile tags (HueSatMap, LookTable, ...)

    meta = CameraMeta(
        make=tags.text("Make"),
        model=tags.text("Model"),
        unique_camera_model=tags.text("UniqueCameraModel"),
        cfa=cfa,
        black_level=black, black_level_delta_h=dh, black_level_delta_v=dv, white_level=white, linearization_table=lin,
        as_shot_neutral=vec3("AsShotNeutral"),
        as_shot_white_xy=vec3("AsShotWhiteXY", 2),
        **{name: tags.matrix(tag) for name, tag in COLOUR_MATRIX_TAGS.items()},
        analog_balance=vec3("AnalogBalance"),
        calibration_illuminant1=illuminant("CalibrationIlluminant1"),
        calibration_illuminant2=illuminant("CalibrationIlluminant2"),
        baseline_exposure=tags.scalar("BaselineExposure") or 0.0,
        noise_profile=noise,
        iso=iso,
        exposure_time_s=exposure,
        orientation=orientation, active_area=active_area, default_crop_origin=crop_origin, default_crop_size=crop_size,
        opcode_list1=opcode_lists[1], opcode_list2=opcode_lists[2], opcode_list3=opcode_lists[3],
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

    Every tag used is checked before use: its raw IFD entry (type, count, inside the file;
    :mod:`simcam.io.dng_tags`), then its value (finite, in range, consistent with the image size).
    tifffile's errors become :class:`DngError`; its log lines are kept in ``meta.extra["tifffile_log"]``
    (never printed).

    Parameters
    ----------
    path : path-like
        A DNG file with a CFA (Bayer) main image.

    Returns
    -------
    CameraMeta
        Tags in DNG semantics (DNG 1.7.0.0 chapter 4); ``origin=(0, 0)``;
        ``cfa`` describes the stored image's pixel (0, 0).

    Raises
    ------
    DngError
        Missing file, not a DNG, non-CFA, unsupported compression, truncated
        pixel data, malformed tag: one line naming the file and the tag.
    """
    path = Path(path)
    with _open_tiff(path) as (tif, log):
        if _tiff_call(path, "IFD0", lambda: len(tif.pages), log) == 0:
            raise DngError(f"{path}: IFD0: no readable image file directory; expected a DNG file")
        meta, _ = _meta_from_tiff(tif, path, log)
    if log.messages:
        meta.extra["tifffile_log"] = log.messages[:5]
    return meta


def read_dng(path: str | os.PathLike) -> RawFrame:
    """Read a DNG: the full stored CFA image in DN plus its metadata.

    ``path`` is a DNG file with a CFA (Bayer) main image, as for :func:`read_dng_meta`.

    Returns
    -------
    RawFrame
        ``kind="raw_dn"``; ``data`` float32 H x W DN of the whole stored raw
        image (masked borders included), exactly LibRaw's ``raw_image``;
        ``meta`` as :func:`read_dng_meta`.

    Raises
    ------
    DngError
        As :func:`read_dng_meta`, and pixel data LibRaw cannot decode or reports as corrupt
        (its messages, written to stderr from C, are captured into the error line).
    """
    path = Path(path)
    meta = read_dng_meta(path)
    h, w = meta.extra["image_size"]
    data = _decode_pixels(path, meta, h, w)
    if data.shape != (h, w):
        raise DngError(f"{path}: pixel data: LibRaw returned {data.shape[0]}x{data.shape[1]}; "
                       f"expected the stored {h}x{w}")
    if meta.linearization_table is not None:
        data = _unlinearize(data, meta.linearization_table, path)
    return RawFrame(data=data, meta=meta, kind="raw_dn", history=[f"read_dng({path.name})"])


@functools.cache
def _quiet_rawpy_fork_warning() -> None:
    """Silence rawpy's RuntimeWarning about fork-started processes (multiprocessing.Pool workers).

    It is about the process, not the file, and Python prints it to fd 2, where :class:`_Fd2Capture`
    would read it as LibRaw's report of corrupt data. A process-wide filter for that one message
    (not ``warnings.catch_warnings``, whose save/restore of global state is not thread-safe),
    installed once per process.
    """
    import warnings

    warnings.filterwarnings("ignore", message="rawpy is being used in a process created by multiprocessing",
                            category=RuntimeWarning)


def _decode_pixels(path: Path, meta: CameraMeta, h: int, w: int) -> np.ndarray:
    """LibRaw's ``raw_image`` as float32, its stderr captured (:class:`_Fd2Capture`).

    LibRaw refuses images whose active area is under 22 px a side; tiny uncompressed files (test
    fixtures) are then read by :func:`_read_uncompressed`. Anything LibRaw writes to stderr while
    decoding about this file (a line led by its name: LibRaw's data callback) means corrupt data, so it
    is an error even if it returned pixels; other threads' output meanwhile goes on to stderr.
    """
    import rawpy

    _quiet_rawpy_fork_warning()
    unsupported, error = False, None
    with _Fd2Capture(str(path)) as cap:
        try:
            with rawpy.imread(str(path)) as raw:
                data = np.array(raw.raw_image, dtype=np.float32, copy=True)  # copy inside the with block
        except rawpy.LibRawFileUnsupportedError:
            unsupported = True
        except Exception as exc:  # rawpy.LibRawError, OSError, MemoryError from LibRaw's allocations
            error = exc
    said = f"; LibRaw said: {cap.message()}" if cap.text else ""
    what = f"pixel data ({meta.extra.get('pixel_tags', 'strips or tiles')}, Compression {meta.extra['compression']})"
    if unsupported:
        t, l, b, r = meta.active_area or (0, 0, h, w)
        if min(b - t, r - l) < 22 and meta.extra["compression"] == 1:
            return _read_uncompressed(path, meta)
        raise DngError(f"{path}: {what}: LibRaw does not support this file{said}")
    if error is not None:
        msg = " ".join(str(error).split())[:_MAX_LOG_CHARS]
        raise DngError(f"{path}: {what}: LibRaw cannot decode it ({type(error).__name__}: {msg}){said}")
    if cap.text:
        raise DngError(f"{path}: {what}: LibRaw reported {cap.message()!r}; expected complete, uncorrupted "
                       f"pixel data")
    return data


def _read_uncompressed(path: Path, meta: CameraMeta) -> np.ndarray:
    """The main image of a small uncompressed 8- or 16-bit DNG, read with tifffile.

    tifffile unpacks other bit depths only with the optional ``imagecodecs`` package, so they are
    refused with a DngError naming BitsPerSample.
    """
    import tifffile

    bps = meta.extra["bits_per_sample"]
    h, w = meta.extra["image_size"]
    if bps not in (8, 16):
        raise DngError(f"{path}: BitsPerSample: {bps} in a {w}x{h} image LibRaw refuses (under 22 px a side); "
                       f"expected 8 or 16 for simcam's own reader")
    with _tifffile_log() as log:
        def read():
            with tifffile.TiffFile(str(path)) as tif:
                return np.asarray(_main_ifd(tif, path, log).asarray(), dtype=np.float32)

        data = _tiff_call(path, "pixel data", read, log)
    if data.shape != (h, w):
        raise DngError(f"{path}: pixel data: tifffile returned shape {data.shape}; expected the stored {h}x{w}")
    return data


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
