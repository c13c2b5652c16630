"""The one MATLAB ``.mat`` reader: v5/v7 with :func:`scipy.io.loadmat`, v7.3 (HDF5) with h5py.

MATLAB v7.3 files are HDF5 with a 512-byte user block holding the MAT header; MATLAB writes arrays
column-major, so the readers transpose (an array MATLAB sees as ``[N, M, H, W]`` is stored as an
HDF5 dataset of shape ``[W, H, M, N]``); char arrays are stored as uint16.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DatasetError, SimcamError


def check_file(path: Path, err) -> None:
    if not path.exists():
        raise err(f"{path}: no such file")
    if path.is_dir():
        raise err(f"{path}: is a directory; expected a MATLAB .mat file")


def load_mat(path: Path, err: type[SimcamError] = DatasetError) -> dict[str, Any]:
    """Variables of a .mat file (v5/v7 or v7.3) as plain Python/numpy values (structs -> dicts).

    Parameters
    ----------
    path : Path
        A MATLAB .mat file.
    err : SimcamError subclass
        Raised, with one line naming the file, when it is missing or not a MATLAB file.

    Returns
    -------
    dict
        Variable name -> value; arrays in MATLAB's (row, column) order, char arrays as str.
    """
    import scipy.io

    check_file(path, err)
    try:
        raw = scipy.io.loadmat(str(path), squeeze_me=True, struct_as_record=False, mat_dtype=False)
    except NotImplementedError:  # MATLAB v7.3 = HDF5
        return _load_mat73(path, err)
    except Exception as exc:  # scipy raises ValueError/TypeError/OSError for non-MAT input
        if _is_hdf5(path):
            return _load_mat73(path, err)
        raise err(f"{path}: not a MATLAB .mat file ({type(exc).__name__}: {exc})") from None
    return {k: _from_scipy(v) for k, v in raw.items() if not k.startswith("__")}


def _is_hdf5(path: Path) -> bool:
    with open(path, "rb") as f:
        head = f.read(1024)
    return b"\x89HDF\r\n\x1a\n" in head


def _from_scipy(v: Any) -> Any:
    from scipy.io.matlab import mat_struct

    if isinstance(v, mat_struct):
        return {k: _from_scipy(getattr(v, k)) for k in v._fieldnames}
    if isinstance(v, np.ndarray) and v.dtype == object:
        return [_from_scipy(x) for x in v.ravel()]
    return v


def _load_mat73(path: Path, err) -> dict[str, Any]:
    import h5py

    try:
        f = h5py.File(str(path), "r")
    except OSError as exc:
        raise err(f"{path}: not a MATLAB .mat file ({exc})") from None
    with f:
        return {k: _from_h5(f, f[k]) for k in f.keys() if not k.startswith("#")}


def _from_h5(f, node) -> Any:
    import h5py

    if isinstance(node, h5py.Group):
        return {k: _from_h5(f, node[k]) for k in node.keys()}
    cls = node.attrs.get("MATLAB_class", b"")
    cls = cls.decode() if isinstance(cls, bytes) else str(cls)
    data = node[()]
    if node.attrs.get("MATLAB_empty", 0):
        return np.zeros((0,))
    if node.dtype == h5py.ref_dtype:
        items = [_from_h5(f, f[r]) for r in np.asarray(data).T.ravel()]
        return items[0] if len(items) == 1 else items
    arr = np.asarray(data).T  # MATLAB stores column-major
    if cls == "char":
        return "".join(chr(c) for c in arr.ravel(order="F"))
    if cls == "logical":
        arr = arr.astype(bool)
    return arr.squeeze() if arr.ndim and arr.size == 1 else arr


def is_mat73(path: str | Path) -> bool:
    """True when ``path`` is a MATLAB v7.3 (HDF5) file."""
    import h5py

    return bool(h5py.is_hdf5(str(path)))


def list_variables(path: str | Path) -> dict[str, tuple[int, ...]]:
    """Variable names and MATLAB-order shapes of a .mat file (either version)."""
    path = Path(path)
    if not path.exists():
        raise DatasetError(f"{path}: no such file")
    if is_mat73(path):
        import h5py

        with h5py.File(path, "r") as f:
            return {k: tuple(reversed(v.shape)) for k, v in f.items()
                    if isinstance(v, h5py.Dataset) and not k.startswith("#")}
    import scipy.io

    try:
        return {name: tuple(shape) for name, shape, _ in scipy.io.whosmat(str(path))}
    except Exception as exc:  # scipy raises ValueError/TypeError on garbage
        raise DatasetError(f"{path}: not a MATLAB .mat file ({exc})") from None
