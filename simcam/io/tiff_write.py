"""TIFF output with tifffile: uncompressed (default) or Deflate, an ICC profile and the camera's EXIF.

OpenImageIO's TIFF writer converts and writes 32-row strips one by one; tifffile writes the
samples in one call, about 3x faster for a 12 MP 16-bit image (``benchmarks/render.py``
times the whole command). tifffile writes the baseline tags (TIFF 6.0 part 1: Make 271,
Model 272, Software 305, DateTime 306, the ICC profile 34675 of ICC.1:2010 annex B.4) but
no EXIF IFD, so :func:`write_tiff` appends one (CIPA DC-008-2023 "Exif 3.0" section 4.6.3)
and a copy of the main IFD with the EXIF IFD pointer (tag 34665) added.

No ``ImageDescription`` (tifffile's JSON shape metadata) and no DateTime unless the capture
has one: the same render gives the same bytes on every run.
"""

from __future__ import annotations

import struct
from fractions import Fraction
from pathlib import Path

import numpy as np

#: TIFF field types (TIFF 6.0 section 2): ASCII, SHORT, LONG, RATIONAL, UNDEFINED
_ASCII, _SHORT, _LONG, _RATIONAL, _UNDEFINED = 2, 3, 4, 5, 7
#: the EXIF IFD pointer tag of the main IFD
EXIF_IFD_TAG = 34665
#: compressions this writer takes (the rest go to OpenImageIO)
COMPRESSIONS = ("none", "zip")


def _rational(value: float) -> tuple[int, int]:
    f = Fraction(float(value)).limit_denominator(1_000_000)
    if f.numerator < 0 or f.numerator >= 2**32:
        raise ValueError(f"EXIF rational {value!r} out of range")
    return f.numerator, f.denominator


def exif_entries(exif: dict) -> list[tuple[int, int, bytes, int]]:
    """``(tag, type, payload bytes (little-endian), count)`` of the EXIF IFD, in tag order.

    ``exif`` keys: ``ExposureTime`` (s), ``FNumber``, ``PhotographicSensitivity`` (ISO),
    ``DateTimeOriginal`` ("YYYY:MM:DD HH:MM:SS"), ``FocalLength`` (mm); missing keys are left out.
    """
    out = [(36864, _UNDEFINED, b"0232", 4)]  # ExifVersion: 2.32
    if exif.get("ExposureTime"):
        out.append((33434, _RATIONAL, struct.pack("<II", *_rational(exif["ExposureTime"])), 1))
    if exif.get("FNumber"):
        out.append((33437, _RATIONAL, struct.pack("<II", *_rational(exif["FNumber"])), 1))
    if exif.get("PhotographicSensitivity"):
        iso = int(round(float(exif["PhotographicSensitivity"])))
        out.append((34855, _SHORT, struct.pack("<H", min(iso, 65535)), 1))
    if exif.get("DateTimeOriginal"):
        text = str(exif["DateTimeOriginal"]).encode("ascii", "replace")[:19] + b"\0"
        out.append((36867, _ASCII, text, len(text)))
    if exif.get("FocalLength"):
        out.append((37386, _RATIONAL, struct.pack("<II", *_rational(exif["FocalLength"])), 1))
    return sorted(out)


def _ifd_bytes(entries, start: int, *, big: bool) -> bytes:
    """A little-endian IFD placed at file offset ``start`` (values that do not fit inline follow it)."""
    n = len(entries)
    count_fmt, off_fmt, slot = ("<Q", "<Q", 8) if big else ("<H", "<I", 4)
    entry_size = 20 if big else 12
    head = struct.calcsize(count_fmt)
    data_at = start + head + n * entry_size + slot
    body, extra = [struct.pack(count_fmt, n)], []
    for tag, typ, payload, count in entries:
        if len(payload) <= slot:
            value = payload.ljust(slot, b"\0")
        else:
            value = struct.pack(off_fmt, data_at)
            padded = payload + b"\0" * (len(payload) % 2)
            extra.append(padded)
            data_at += len(padded)
        body.append(struct.pack("<HH", tag, typ) + struct.pack(off_fmt if big else "<I", count) + value)
    body.append(b"\0" * slot)  # no next IFD
    return b"".join(body) + b"".join(extra)


def write_tiff(path: str | Path, samples: np.ndarray | None, *, compression: str = "none", icc: bytes | None = None,
               tags: dict | None = None, exif: dict | None = None, bigtiff: bool | None = None,
               shape: tuple[int, int, int] | None = None, dtype=None) -> int | None:
    """Write H x W x C (C = 1 or 3) ``uint8``/``uint16``/``float32`` samples to a new TIFF at ``path``.

    Returns the file offset of the samples when they are uncompressed (None otherwise). With
    ``samples=None`` (``shape`` and ``dtype`` given, uncompressed) the file gets every tag and a
    region of the samples' size, not written (a hole in the file), at that offset: the same bytes
    once the samples are written there in C order (:class:`simcam.io.tiff_stream.TiffStream`).

    Parameters
    ----------
    compression : {"none", "zip", "zip:N"}
        Deflate (TIFF tag value 8) with a zlib level N (default 6) and the horizontal predictor
        for integer samples.
    icc : bytes, optional
        ICC profile (tag 34675).
    tags : dict, optional
        ``Make``, ``Model``, ``Software``, ``DateTime`` ("YYYY:MM:DD HH:MM:SS").
    exif : dict, optional
        See :func:`exif_entries`.
    bigtiff : bool, optional
        BigTIFF (default: only when the samples come near 4 GiB).
    """
    import tifffile

    tags = tags or {}
    name, _, level = compression.partition(":")
    if name not in COMPRESSIONS:
        raise ValueError(f"write_tiff: compression {compression!r}: expected one of {COMPRESSIONS}")
    if samples is None and (shape is None or dtype is None or name != "none"):
        raise ValueError("write_tiff: samples=None needs shape and dtype, uncompressed")
    h, w, c = samples.shape if samples is not None else shape
    nbytes = h * w * c * np.dtype(samples.dtype if samples is not None else dtype).itemsize
    big = nbytes > 2**32 - 2**26 if bigtiff is None else bool(bigtiff)
    extratags = []
    for code, key in ((271, "Make"), (272, "Model")):
        if tags.get(key):
            extratags.append((code, "s", 0, str(tags[key]), True))
    kwargs: dict = {}
    if name == "zip":
        kwargs.update(compression="zlib", compressionargs={"level": int(level or 6)})
        kwargs["rowsperstrip"] = 64
        if samples.dtype.kind in "ui":
            kwargs["predictor"] = True
    datetime = tags.get("DateTime") or None
    if samples is None:
        kwargs.update(shape=(h, w, c) if c > 1 else (h, w), dtype=np.dtype(dtype))
    else:
        samples = np.ascontiguousarray(samples) if c > 1 else samples[:, :, 0]
    where = tifffile.imwrite(path, samples, photometric="rgb" if c == 3 else "minisblack",
                             planarconfig="contig" if c > 1 else None, software=str(tags.get("Software", "simcam")),
                             datetime=datetime, metadata=None, iccprofile=icc, extratags=extratags, bigtiff=big,
                             byteorder="<", returnoffset=name == "none", **kwargs)
    if exif:
        _add_exif_ifd(path, exif_entries(exif), big=big)
    return int(where[0]) if where else None


def _add_exif_ifd(path, entries, *, big: bool) -> None:
    """Append the EXIF IFD and a copy of the main IFD with the EXIF pointer (tag 34665) added.

    The copy's entries keep their values' offsets; the header then points to the copy (the old
    main IFD stays in the file, unreferenced).
    """
    cfmt, ofmt, esize = ("<Q", "<Q", 20) if big else ("<H", "<I", 12)
    csize, osize = struct.calcsize(cfmt), struct.calcsize(ofmt)
    with open(path, "r+b") as fh:
        head = fh.read(16)
        if head[:2] != b"II":
            raise ValueError("write_tiff: expected a little-endian TIFF from tifffile")
        first = struct.unpack_from(ofmt, head, 8 if big else 4)[0]
        fh.seek(first)
        n = struct.unpack(cfmt, fh.read(csize))[0]
        raw = fh.read(n * esize)
        main = [raw[k * esize:(k + 1) * esize] for k in range(n)]
        if struct.unpack_from(ofmt, fh.read(osize))[0] != 0:
            raise ValueError("write_tiff: expected a single-image TIFF from tifffile")
        end = fh.seek(0, 2)
        end += end % 2
        fh.seek(end)
        exif_ifd = _ifd_bytes(entries, end, big=big)
        fh.write(exif_ifd)
        ifd_at = end + len(exif_ifd)
        ifd_at += ifd_at % 2
        pointer = struct.pack("<HH", EXIF_IFD_TAG, 18 if big else _LONG) + struct.pack(ofmt, 1) + struct.pack(ofmt, end)
        main = sorted(main + [pointer], key=lambda e: struct.unpack_from("<H", e)[0])
        fh.seek(ifd_at)
        fh.write(struct.pack(cfmt, len(main)) + b"".join(main) + b"\0" * osize)
        fh.seek(8 if big else 4)
        fh.write(struct.pack(ofmt, ifd_at))
