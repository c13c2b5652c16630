"""Image output through OpenImageIO: PNG (8/16-bit), TIFF (8/16-bit, float32), EXR (half/float).

Files are written to a temporary name beside the target and renamed into place,
so a failed write never leaves a partial output, and an input file is never
overwritten.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import ImageIOError
from .atomic import atomic_output

#: Allowed sample types per file extension; the first is the default.
FORMAT_DEPTHS = {
    ".png": ("uint8", "uint16"),
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


def to_samples(data: np.ndarray, depth: str) -> np.ndarray:
    """Convert float data (display range [0, 1]) to the stored sample type.

    Integer types clip to [0, 1] and round; float types are stored as is.
    """
    if not np.all(np.isfinite(data)):
        raise ImageIOError("image data contains NaN or infinite values")
    if depth in ("uint8", "uint16"):
        top = 255 if depth == "uint8" else 65535
        return np.round(np.clip(data, 0.0, 1.0) * top).astype(depth)
    if depth == "half":
        return data.astype(np.float16)
    return data.astype(np.float32)


def write_image(path: str | Path, data: np.ndarray, *, depth: str | int | None = None,
                protect: tuple[str | Path, ...] = (), attributes: dict[str, str] | None = None) -> Path:
    """Write an H x W or H x W x C float image with OpenImageIO.

    Parameters
    ----------
    path : path
        Output file; its extension picks the format.
    data : ndarray
        float, H x W or H x W x C; integer outputs take [0, 1] to full scale.
    depth : str or int, optional
        ``8``/``16``/``32`` or ``uint8``/``uint16``/``float32``/``half``.
    protect : paths
        Files that must never be overwritten (the inputs).
    """
    import OpenImageIO as oiio

    path = Path(path)
    for p in protect:
        if Path(p).exists() and path.exists() and os.path.samefile(p, path):
            raise ImageIOError(f"{path}: refusing to overwrite the input file")
    dtype = resolve_depth(path, depth)
    samples = to_samples(np.asarray(data), dtype)
    if samples.ndim == 2:
        samples = samples[:, :, None]
    h, w, c = samples.shape
    type_desc = {"uint8": oiio.UINT8, "uint16": oiio.UINT16, "float32": oiio.FLOAT, "half": oiio.HALF}[dtype]
    spec = oiio.ImageSpec(w, h, c, type_desc)
    # OpenImageIO stamps TIFF/EXR with the write time unless told otherwise: the same render
    # would give different bytes on every run. No DateTime unless the caller gives one.
    spec.attribute("DateTime", "")
    for k, v in (attributes or {}).items():
        spec.attribute(k, v)
    if not path.parent.exists():
        raise ImageIOError(f"{path}: output folder {path.parent} does not exist")
    with atomic_output(path, suffix=path.suffix) as tmp:
        out = oiio.ImageOutput.create(tmp)
        if out is None or not out.open(tmp, spec):
            raise ImageIOError(f"{path}: cannot open for writing ({oiio.geterror() or (out and out.geterror())})")
        ok = out.write_image(np.ascontiguousarray(samples))
        out.close()
        if not ok:
            raise ImageIOError(f"{path}: write failed ({out.geterror()})")
    return path


def read_image(path: str | Path) -> np.ndarray:
    """Read an image as float32 (integer types scaled to [0, 1]); H x W x C."""
    import OpenImageIO as oiio

    path = Path(path)
    if not path.exists():
        raise ImageIOError(f"{path}: no such file")
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ImageIOError(f"{path}: cannot read image ({oiio.geterror()})")
    try:
        data = inp.read_image(oiio.FLOAT)
    finally:
        inp.close()
    if data is None:
        raise ImageIOError(f"{path}: cannot decode image")
    return np.asarray(data, dtype=np.float32)
