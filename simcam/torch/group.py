"""Per-sample noise models of a batch, resolved on the host and grouped by structure.

A batch may mix ISOs (and so parameters) from one calibration profile. Every
sample's model is resolved on the host (:meth:`simcam.profiles.CalibrationProfile.model_for`,
which interpolates per-ISO entries linearly in log-ISO); samples whose models
have the same *structure* (model types, effect list, string/bool options) form
one :class:`Group`, whose float parameters become ``[G, ...]`` tensors so the
group is noised in one pass on the device.
"""

from __future__ import annotations

import json
import math
from collections import OrderedDict
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..errors import NoiseModelError
from ..noise import NoiseModel, model_from_entry


def _structure(entry: Any) -> Any:
    """The entry with every number (and every list of numbers) replaced by ``"#"``."""
    if isinstance(entry, bool) or isinstance(entry, str) or entry is None:
        return entry
    if isinstance(entry, (int, float)):
        return "#"
    if isinstance(entry, list):
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in entry):
            return "#"
        return [_structure(v) for v in entry]
    if isinstance(entry, dict):
        return {k: _structure(v) for k, v in entry.items()}
    return repr(entry)


_KEYS: "OrderedDict[int, tuple[Any, str, str]]" = OrderedDict()


def _keys(model: Any) -> tuple[str, str]:
    """(entry key, structure key) of a model, memoised by object (profiles hand out the same objects)."""
    hit = _KEYS.get(id(model))
    if hit is not None and hit[0] is model:
        return hit[1], hit[2]
    entry = model.to_entry()
    keys = (json.dumps(entry, sort_keys=True), json.dumps(_structure(entry), sort_keys=True))
    _KEYS[id(model)] = (model, *keys)  # holds the model, so its id stays its own
    while len(_KEYS) > 512:
        _KEYS.popitem(last=False)
    return keys


def structure_key(model: NoiseModel) -> str:
    """Models with equal keys can be noised together with stacked parameters."""
    return _keys(model)[1]


def entry_key(model: NoiseModel) -> str:
    """The model's entry as a canonical string (distinct models by parameters)."""
    return _keys(model)[0]


class Group:
    """Samples of a batch sharing one model structure.

    Attributes
    ----------
    index : list of int
        Positions of the samples in the batch.
    models : list of NoiseModel
        One per sample (equal structure).
    uniq : list of NoiseModel
        The distinct models (by entry); ``inv[i]`` is sample ``i``'s one.
    """

    def __init__(self, index: list[int], models: list[NoiseModel]):
        self.index = list(index)
        self.models = list(models)
        keys: dict[str, int] = {}
        self.uniq: list[NoiseModel] = []
        inv = []
        for m in models:
            k = entry_key(m)
            if k not in keys:
                keys[k] = len(self.uniq)
                self.uniq.append(m)
            inv.append(keys[k])
        self.inv = np.asarray(inv, dtype=np.int64)

    @property
    def size(self) -> int:
        return len(self.models)

    @property
    def shared(self) -> bool:
        """True when every sample has the same model (parameters broadcast as ``[1, ...]``)."""
        return len(self.uniq) == 1

    def values(self, fn: Callable[[NoiseModel], Any]) -> np.ndarray:
        """``fn`` of each sample's model as a float64 array ``[G, ...]`` (``[1, ...]`` when shared)."""
        u = np.stack([np.asarray(fn(m), dtype=np.float64) for m in self.uniq])
        return u if self.shared else u[self.inv]

    def sub(self, fn: Callable[[NoiseModel], NoiseModel]) -> "Group":
        """The group of a nested model (``base`` of a composite or clipped model)."""
        g = Group.__new__(Group)
        g.index, g.models = self.index, [fn(m) for m in self.models]
        g.uniq, g.inv = [fn(m) for m in self.uniq], self.inv
        return g


def per_sample(value: Any, batch: int, *, name: str) -> list[Any]:
    """A scalar, sequence, numpy array or tensor as ``batch`` Python values (None stays None)."""
    if value is None:
        return [None] * batch
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    if isinstance(value, (str, int, float, np.integer, np.floating)):
        return [value] * batch
    arr = np.asarray(value, dtype=object).reshape(-1)
    if arr.size == 1:
        return [arr[0]] * batch
    if arr.size != batch:
        raise NoiseModelError(f"{name}: expected a scalar or {batch} values (one per sample), got {arr.size}")
    return list(arr)


def resolve_models(source: Any, batch: int, *, iso: Any = None, camera: Any = None,
                   extrapolate: bool = False, cache: dict | None = None) -> list[NoiseModel]:
    """One noise model per sample from a model, an entry, a profile or a profile path.

    Parameters
    ----------
    source : NoiseModel, dict, CalibrationProfile, str, Path or list
        A model (all samples), its profile entry, a calibration profile, a profile YAML path, or a
        list of one model (or entry) per sample.
    batch : int
        Number of samples.
    iso : float or sequence, optional
        Per-sample ISO (required for a profile; looked up with ``model_for``).
    camera : str or sequence, optional
        Camera id in the profile (default: its only camera).
    extrapolate : bool
        Passed to ``model_for``.
    cache : dict, optional
        (iso, camera) -> model memo kept by callers across batches.
    """
    from ..profiles import CalibrationProfile, load_profile

    if isinstance(source, (list, tuple)):
        if len(source) != batch:
            raise NoiseModelError(f"profile_or_model: expected one model per sample ({batch}), got {len(source)}")
        return [model_from_entry(m, where=f"profile_or_model[{i}]") for i, m in enumerate(source)]
    if isinstance(source, (str, Path)):
        source = load_profile(source)
    if isinstance(source, dict):
        source = model_from_entry(source, where="model")
    if isinstance(source, NoiseModel):
        return [source] * batch
    if not isinstance(source, CalibrationProfile):
        raise NoiseModelError(f"profile_or_model: expected a NoiseModel, a model entry, a CalibrationProfile, a "
                              f"profile path or a simcam.noise.flow.NoiseFlow, got {type(source).__name__}")
    isos = per_sample(iso, batch, name="iso")
    cams = per_sample(camera, batch, name="camera")
    memo = {} if cache is None else cache
    out = []
    for i, c in zip(isos, cams):
        if i is None:
            raise NoiseModelError(f"iso: a calibration profile ({source.source or 'profile'}) needs each sample's ISO, got none")
        fi = float(i)
        if not (fi > 0 and math.isfinite(fi)):
            raise NoiseModelError(f"iso: expected positive ISO values, got {i!r}")
        k = (fi, c, bool(extrapolate))
        if k not in memo:
            memo[k] = source.model_for(fi, c, extrapolate=extrapolate)
        out.append(memo[k])
    return out


def group_models(models: Sequence[NoiseModel]) -> list[Group]:
    """Split per-sample models into groups of equal structure (batch order kept inside each)."""
    by: dict[str, list[int]] = {}
    for i, m in enumerate(models):
        by.setdefault(structure_key(m), []).append(i)
    return [Group(idx, [models[i] for i in idx]) for idx in by.values()]
