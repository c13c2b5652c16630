"""SIDD-format denoising blocks in MATLAB ``.mat`` files (v5 and v7.3/HDF5), and folders of pairs.

The SIDD benchmark (Abdelhamed 2020, section 5.4) stores blocks as one array per file:
``[N, M, H, W]`` normalised raw (float32; image, block, row, column) or
``[N, M, H, W, 3]`` sRGB (uint8), e.g. ``BenchmarkNoisyBlocksRaw`` of shape
``[40, 32, 256, 256]``. Any N, M, H, W is accepted.

MATLAB v5 files are read and written with :mod:`scipy.io`. MATLAB v7.3 files
are HDF5 with a 512-byte user block holding the MAT header; MATLAB writes
arrays column-major, so an array MATLAB sees as ``[N, M, H, W]`` is stored as
an HDF5 dataset of shape ``[W, H, M, N]``: the reader and writer transpose.
"""

from __future__ import annotations

import os
import re
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from ..errors import DatasetError
from .matlab import is_mat73, list_variables

#: Variable names of the SIDD benchmark/validation files.
SIDD_KEYS = (
    "BenchmarkNoisyBlocksRaw", "BenchmarkNoisyBlocksSrgb",
    "ValidationNoisyBlocksRaw", "ValidationGtBlocksRaw",
    "ValidationNoisyBlocksSrgb", "ValidationGtBlocksSrgb",
)
_MATLAB_CLASS = {
    np.dtype(np.float64): "double", np.dtype(np.float32): "single", np.dtype(np.uint8): "uint8",
    np.dtype(np.uint16): "uint16", np.dtype(np.int16): "int16", np.dtype(np.int32): "int32",
    np.dtype(np.uint32): "uint32", np.dtype(np.bool_): "logical",
}


def read_blocks(path: str | Path, key: str | None = None) -> np.ndarray:
    """Read a block array from a SIDD-style .mat file.

    Parameters
    ----------
    path : path
        MATLAB v5 or v7.3 file.
    key : str, optional
        Variable name; by default the only 4-D or 5-D variable in the file.

    Returns
    -------
    ndarray
        ``[N, M, H, W]`` (raw) or ``[N, M, H, W, 3]`` (sRGB), the stored dtype.
    """
    path = Path(path)
    variables = list_variables(path)
    if key is None:
        cands = [k for k, s in variables.items() if len(s) == 4 or (len(s) == 5 and s[-1] == 3)]
        if len(cands) != 1:
            raise DatasetError(
                f"{path}: variable: expected exactly one [N, M, H, W] or [N, M, H, W, 3] array, found "
                f"{ {k: list(s) for k, s in variables.items()} }; pass key=")
        key = cands[0]
    if key not in variables:
        raise DatasetError(f"{path}: variable {key!r} not found; the file holds {sorted(variables)}")
    if is_mat73(path):
        import h5py

        with h5py.File(path, "r") as f:
            arr = np.asarray(f[key][()])
        arr = np.ascontiguousarray(arr.transpose(tuple(range(arr.ndim - 1, -1, -1))))
    else:
        import scipy.io

        arr = scipy.io.loadmat(str(path), variable_names=[key], squeeze_me=False)[key]
        arr = np.ascontiguousarray(arr)
    return check_blocks(arr, f"{path}: {key}")


def check_blocks(arr: np.ndarray, where: str) -> np.ndarray:
    """Return ``arr`` if it is ``[N, M, H, W]`` or ``[N, M, H, W, 3]``, else raise."""
    arr = np.asarray(arr)
    if not (arr.ndim == 4 or (arr.ndim == 5 and arr.shape[-1] == 3)):
        raise DatasetError(f"{where}: expected an [N, M, H, W] or [N, M, H, W, 3] block array, got shape {arr.shape}")
    if arr.dtype.kind not in "fui":
        raise DatasetError(f"{where}: expected a numeric array, got dtype {arr.dtype}")
    return arr


def write_blocks(path: str | Path, blocks: np.ndarray, key: str,
                 *, format: Literal["v5", "v7.3"] = "v5", protect: tuple = ()) -> Path:
    """Write a block array as MATLAB v5 (scipy.io) or v7.3 (HDF5, transposed like MATLAB).

    The file is written to a temporary name and renamed into place; a path in
    ``protect`` (an input) is never overwritten.
    """
    path = Path(path)
    blocks = check_blocks(blocks, f"{path}: {key}")
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]{0,62}", key):
        raise DatasetError(f"{path}: key {key!r}: expected a MATLAB variable name")
    for p in protect:
        if Path(p).exists() and path.exists() and os.path.samefile(p, path):
            raise DatasetError(f"{path}: refusing to overwrite an input file")
    fd, tmp = tempfile.mkstemp(suffix=".mat", dir=str(path.parent or "."))
    os.close(fd)
    try:
        if format == "v5":
            import scipy.io

            scipy.io.savemat(tmp, {key: blocks}, do_compression=False)
        elif format == "v7.3":
            _write_mat73(tmp, key, blocks)
        else:
            raise DatasetError(f"{path}: format: expected 'v5' or 'v7.3', got {format!r}")
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def _write_mat73(path: str, key: str, arr: np.ndarray) -> None:
    import h5py

    with h5py.File(path, "w", userblock_size=512) as f:
        ds = f.create_dataset(key, data=arr.transpose(tuple(range(arr.ndim - 1, -1, -1))))
        ds.attrs["MATLAB_class"] = np.bytes_(_MATLAB_CLASS.get(arr.dtype, "double"))
    text = (f"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: "
            f"{time.strftime('%a %b %d %H:%M:%S %Y', time.gmtime())} HDF5 schema 1.00 .").encode()
    header = text.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM"
    with open(path, "r+b") as fh:
        fh.write(header.ljust(512, b"\x00"))


@dataclass
class ImagePair:
    """One noisy/ground-truth pair of a folder (blocks ``[M, H, W]`` or ``[M, H, W, 3]``)."""

    name: str
    noisy: np.ndarray
    gt: np.ndarray
    noisy_path: Path
    gt_path: Path


_NOISY = re.compile(r"noisy", re.IGNORECASE)


def read_pair_folder(folder: str | Path) -> list[ImagePair]:
    """Pairs of a folder: files whose name contains ``NOISY`` matched to the same name with ``GT``.

    SIDD names its files ``0001_NOISY_RAW_010.MAT`` / ``0001_GT_RAW_010.MAT``;
    ``noisy/`` and ``gt/`` sub-folders with equal file names work too.
    Supported files: ``.npy`` (H x W mosaic or H x W x 3), ``.mat`` (the only
    2-D/3-D variable, or ``x``), ``.png``/``.tif``/``.tiff`` (scaled to [0, 1]).
    Each image becomes one block (M = 1).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise DatasetError(f"{folder}: expected a folder of noisy/GT pairs")
    pairs: list[tuple[str, Path, Path]] = []
    if (folder / "noisy").is_dir() and (folder / "gt").is_dir():
        for p in sorted((folder / "noisy").iterdir()):
            if p.is_file():
                q = folder / "gt" / p.name
                if not q.exists():
                    raise DatasetError(f"{p}: no ground truth {q}")
                pairs.append((p.stem, p, q))
    else:
        for p in sorted(folder.iterdir()):
            if p.is_file() and _NOISY.search(p.name):
                m = _NOISY.search(p.name)
                gt_name = p.name[:m.start()] + ("GT" if m.group(0).isupper() else "gt") + p.name[m.end():]
                q = p.with_name(gt_name)
                if not q.exists():
                    raise DatasetError(f"{p}: no ground-truth file {q.name} beside it")
                pairs.append((p.name[:m.start()].rstrip("_-") or p.stem, p, q))
    if not pairs:
        raise DatasetError(f"{folder}: no noisy/GT pairs found (expected *NOISY* files or noisy/ and gt/ folders)")
    out = []
    for name, p, q in pairs:
        a, b = read_single_image(p), read_single_image(q)
        if a.shape != b.shape:
            raise DatasetError(f"{p}: shape {a.shape} differs from its ground truth {q.name} {b.shape}")
        out.append(ImagePair(name, a[None], b[None], p, q))
    return out


def read_single_image(path: Path) -> np.ndarray:
    """One image file as float32 H x W or H x W x 3."""
    suffix = path.suffix.lower()
    if suffix == ".npy":
        arr = np.load(path, allow_pickle=False)
    elif suffix == ".mat":
        variables = list_variables(path)
        keys = [k for k, s in variables.items() if len(s) in (2, 3)]
        key = "x" if "x" in variables else (keys[0] if len(keys) == 1 else None)
        if key is None:
            raise DatasetError(f"{path}: expected one 2-D or 3-D variable, found {sorted(variables)}")
        if is_mat73(path):
            import h5py

            with h5py.File(path, "r") as f:
                arr = np.asarray(f[key][()]).T
        else:
            import scipy.io

            arr = scipy.io.loadmat(str(path), variable_names=[key])[key]
    elif suffix in (".png", ".tif", ".tiff", ".exr"):
        from .images import read_image

        arr = read_image(path)
        if arr.ndim == 3 and arr.shape[2] == 1:
            arr = arr[..., 0]
        elif arr.ndim == 3 and arr.shape[2] == 4:
            arr = arr[..., :3]
    else:
        raise DatasetError(f"{path}: unsupported file type {suffix!r}; expected .npy, .mat, .png, .tif or .exr")
    arr = np.asarray(arr)
    if arr.dtype == np.uint8:
        arr = arr.astype(np.float32) / 255.0
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] == 3)):
        raise DatasetError(f"{path}: expected an H x W or H x W x 3 image, got shape {arr.shape}")
    return np.ascontiguousarray(arr, dtype=np.float32)
