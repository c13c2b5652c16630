"""Training sets of noisy/clean packed patches stored as a Zarr v3 group.

Layout (``simcam synth SOURCES... -o set.zarr``): arrays ``noisy`` and ``clean`` of shape
``(N, 4, P/2, P/2)`` float32 (packed RGGB, channels (0,0), (0,1), (1,0), (1,1) of the 2x2 cell,
normalised raw), ``iso`` ``(N,)`` float32 and ``origin`` ``(N, 2)`` int32 (the crop's top-left
in the source mosaic). Source *i* owns rows ``[i K, (i + 1) K)``, one chunk of every array, so
workers write in parallel without sharing a chunk. The group attribute ``simcam`` is the
manifest: format, seed, profile, ISOs, patch size, K and, per item, its source, rows and status.
Rows of a failed item stay NaN and are listed as failed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import DatasetError

FORMAT = "simcam-trainingset/1"


def create_store(url: str, *, sources: list[str], patches: int, patch_size: int, overwrite: bool,
                 storage_options: dict | None = None):
    """Create the group and its empty arrays (or open them for ``--resume``); returns the group."""
    import zarr

    n, h = len(sources) * int(patches), int(patch_size) // 2
    mode = "w" if overwrite else "a"
    group = zarr.open_group(url, mode=mode, storage_options=storage_options)
    spec = {"noisy": ((n, 4, h, h), (patches, 4, h, h), "float32", np.nan),
            "clean": ((n, 4, h, h), (patches, 4, h, h), "float32", np.nan),
            "iso": ((n,), (patches,), "float32", np.nan),
            "origin": ((n, 2), (patches, 2), "int32", -1)}
    for name, (shape, chunks, dtype, fill) in spec.items():
        if name in group:
            arr = group[name]
            if arr.shape != shape or arr.chunks != chunks:
                raise DatasetError(f"{url}: {name}: shape {arr.shape}, chunks {arr.chunks}; expected {shape}, "
                                   f"{chunks} for --resume with these sources and patch settings")
        else:
            group.create_array(name, shape=shape, chunks=chunks, dtype=dtype, fill_value=fill)
    return group


def write_manifest(group, manifest: dict[str, Any]) -> None:
    group.attrs["simcam"] = {"format": FORMAT, **manifest}


def read_manifest(url: str, storage_options: dict | None = None) -> dict[str, Any]:
    import zarr

    try:
        group = zarr.open_group(url, mode="r", storage_options=storage_options)
    except Exception as exc:  # noqa: BLE001 - zarr / fsspec raise many types
        raise DatasetError(f"{url}: not a readable Zarr group ({type(exc).__name__}: {exc})") from None
    man = dict(group.attrs.get("simcam", {}))
    if man.get("format") != FORMAT:
        raise DatasetError(f"{url}: attribute simcam.format is {man.get('format')!r}; expected {FORMAT!r} "
                           "(a training set written by simcam synth -o SET.zarr)")
    return man
