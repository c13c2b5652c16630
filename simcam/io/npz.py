"""Deterministic ``.npz`` files: the same arrays give the same bytes.

``numpy.savez`` stamps every zip member with the current time, so two runs of the same job
(serial, or on any number of dask workers) write different bytes. :func:`write_npz` writes the
members in the given order with a fixed timestamp (1980-01-01, the zip epoch), through a
temporary file renamed into place; ``numpy.load`` reads the result as usual.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from .atomic import atomic_output

_EPOCH = (1980, 1, 1, 0, 0, 0)


def write_npz(path: str | Path, arrays: dict[str, np.ndarray], *, compressed: bool = True) -> Path:
    """Write ``arrays`` as ``path`` (an ``.npz`` file), byte-identical for identical arrays.

    Parameters
    ----------
    path : path
        Output file.
    arrays : dict
        Name -> array (written as ``name.npy`` members, in this order).
    compressed : bool
        Deflate the members (as ``numpy.savez_compressed``).

    Returns
    -------
    Path

    Examples
    --------
    >>> import tempfile, os
    >>> d = tempfile.mkdtemp()
    >>> a = write_npz(os.path.join(d, "a.npz"), {"x": np.arange(3)})
    >>> b = write_npz(os.path.join(d, "b.npz"), {"x": np.arange(3)})
    >>> a.read_bytes() == b.read_bytes(), np.load(a)["x"].tolist()
    (True, [0, 1, 2])
    """
    path = Path(path)
    method = zipfile.ZIP_DEFLATED if compressed else zipfile.ZIP_STORED
    with atomic_output(path, suffix=".npz") as tmp:
        with zipfile.ZipFile(tmp, "w", compression=method, allowZip64=True) as zf:
            for name, value in arrays.items():
                info = zipfile.ZipInfo(f"{name}.npy", date_time=_EPOCH)
                info.compress_type = method
                info.external_attr = 0o644 << 16
                with zf.open(info, "w", force_zip64=True) as f:
                    np.lib.format.write_array(f, np.asanyarray(value), allow_pickle=False)
    return path
