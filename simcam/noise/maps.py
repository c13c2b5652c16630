"""Measured maps referenced by profiles: ``"maps.npz#dsnu"`` (an array in an ``.npz`` beside the profile).

A calibration can keep what it measured — the DSNU or PRNU map of *this* sensor, its column
offsets, its code transition levels, a glow field — in an ``.npz`` file next to
``profile.yaml``; effect entries name an array as ``FILE.npz#KEY``. :func:`resolve_map_refs`
makes relative references absolute against the profile's folder when the profile is loaded;
:func:`load_map` reads the array (``allow_pickle=False``: a map is data, never code) and caches
it per file modification time.
"""

from __future__ import annotations

import re
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import NoiseModelError

MAP_REF = re.compile(r"^(?P<file>.+\.npz)#(?P<key>[A-Za-z0-9_]+)$")


def is_map_ref(value: Any) -> bool:
    return isinstance(value, str) and MAP_REF.match(value) is not None


def resolve_map_refs(node: Any, base: Path) -> Any:
    """A copy of ``node`` (a profile entry) whose relative ``FILE.npz#KEY`` strings are made absolute."""
    if isinstance(node, dict):
        return {k: resolve_map_refs(v, base) for k, v in node.items()}
    if isinstance(node, list):
        return [resolve_map_refs(v, base) for v in node]
    if is_map_ref(node):
        m = MAP_REF.match(node)
        f = Path(m.group("file"))
        return node if f.is_absolute() else f"{(base / f).resolve()}#{m.group('key')}"
    return node


@lru_cache(maxsize=64)
def _load(file: str, key: str, mtime_ns: int, size: int) -> np.ndarray:
    try:
        with np.load(file, allow_pickle=False) as z:
            if key not in z.files:
                raise NoiseModelError(f"{file}#{key}: no array {key!r}; the file holds {sorted(z.files)}")
            arr = np.asarray(z[key])
    except NoiseModelError:
        raise
    except (OSError, ValueError) as exc:
        raise NoiseModelError(f"{file}#{key}: cannot read the map ({type(exc).__name__}: {exc})") from None
    if not np.issubdtype(arr.dtype, np.number) or not np.isfinite(arr).all():
        raise NoiseModelError(f"{file}#{key}: expected finite numbers, got dtype {arr.dtype}")
    arr.setflags(write=False)
    return arr


def load_map(ref: str) -> np.ndarray:
    """The array a ``FILE.npz#KEY`` reference names (read-only, cached).

    Raises
    ------
    NoiseModelError
        A malformed reference, a missing file or key, non-numeric or non-finite values.
    """
    m = MAP_REF.match(str(ref))
    if m is None:
        raise NoiseModelError(f"map {ref!r}: expected FILE.npz#KEY")
    p = Path(m.group("file"))
    try:
        st = p.stat()
    except OSError:
        raise NoiseModelError(f"{ref}: map file {p} not found (relative references are resolved against the "
                              "profile's folder)") from None
    return _load(str(p), m.group("key"), st.st_mtime_ns, st.st_size)


def fit_to(arr: np.ndarray, shape: tuple[int, int], axis: str, *, where: str) -> np.ndarray:
    """A measured map cut to a frame's ``shape``: (H, W) for ``pixel``, (H, 1) ``row``, (1, W) ``column``.

    The map must cover the frame (a frame smaller than the calibrated sensor takes its top-left part).
    """
    h, w = shape
    a = np.asarray(arr, dtype=np.float32)
    need = {"pixel": (h, w), "row": (h,), "column": (w,)}[axis]
    if a.ndim != len(need) or any(s < n for s, n in zip(a.shape, need)):
        raise NoiseModelError(f"{where}: measured {axis} map of shape {a.shape}; expected at least {need} "
                              "for this frame")
    if axis == "pixel":
        return a[:h, :w]
    return a[:h, None] if axis == "row" else a[None, :w]
