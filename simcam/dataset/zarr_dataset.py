"""A PyTorch dataset over a training set written by ``simcam synth SOURCES... -o SET.zarr``.

Reads the Zarr v3 group locally or from any fsspec URL (``file://``, ``s3://`` with s3fs, ...);
samples are ``{"noisy", "clean", "meta"}`` like the on-the-fly datasets, so the same training
loop takes either. Rows of items that failed when the set was written are left out.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from ..errors import DatasetError
from ..trainingset import read_manifest


class TrainingSetDataset(torch.utils.data.Dataset):
    """Noisy/clean packed patches of a simcam training set.

    Parameters
    ----------
    url : str
        Path or fsspec URL of the Zarr group.
    storage_options : dict, optional
        Passed to fsspec (credentials, endpoints).
    """

    def __init__(self, url: str, *, storage_options: dict | None = None):
        self.url = str(url)
        self.storage_options = storage_options
        self.manifest = read_manifest(self.url, storage_options)
        rows = [np.arange(*it["rows"]) for it in self.manifest["items"] if it.get("ok")]
        self.rows = np.concatenate(rows) if rows else np.empty(0, np.int64)
        self._group = None

    def _arrays(self):
        if self._group is None:  # opened lazily, so the dataset pickles to DataLoader workers
            import zarr

            self._group = zarr.open_group(self.url, mode="r", storage_options=self.storage_options)
        return self._group

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_group"] = None
        return state

    def __len__(self) -> int:
        return int(self.rows.size)

    def __getitem__(self, index: int) -> dict[str, Any]:
        if not 0 <= index < len(self):
            raise IndexError(f"{self.url}: index {index} outside [0, {len(self)})")
        g, r = self._arrays(), int(self.rows[index])
        noisy, clean = np.asarray(g["noisy"][r]), np.asarray(g["clean"][r])
        if not (np.isfinite(noisy).all() and np.isfinite(clean).all()):
            raise DatasetError(f"{self.url}: row {r}: NaN samples in an item marked done; the set is incomplete")
        return {"noisy": torch.from_numpy(noisy), "clean": torch.from_numpy(clean),
                "meta": {"iso": float(g["iso"][r]), "row": r, "origin": [int(v) for v in g["origin"][r]]}}
