"""On-the-fly noisy/clean training patches for PyTorch (Abdelhamed 2020, section s 6.5 and 7.2).

:class:`NoisyPatchDataset` (map-style) and :class:`NoisyPatchStream`
(iterable, over a file list) yield dicts ``{"noisy": 4 x p x p, "clean": 4 x p x p,
"meta": {...}}`` of packed normalised raw (channel order (0,0), (0,1), (1,0),
(1,1); with ``cfa_out="RGGB"`` the crop phase is chosen so that this is
R, G, G, B whatever the source's pattern). Clean sources are raw mosaics
(``.npy`` arrays, DNG files, arrays in memory) or sRGB images unprocessed to
raw (:class:`~simcam.training.unprocess.Unprocess`, Brooks et al. 2019).

Randomness: sample ``i`` of epoch ``e`` draws everything (source, crop,
unprocessing, noise) from ``np.random.SeedSequence([seed, e, i])``, so the
tensors do not depend on the number of workers; epochs differ.
Use :func:`make_loader`: it picks the ``spawn`` start method where rawpy or
onnxruntime are used and gives each worker one intra-op thread.

Needs ``simcam[torch]``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..cfa import PACK_OFFSETS, check_pattern, pack, shift_pattern
from ..errors import DatasetError, require_extra
from ..frame import RawFrame
from .crops import crop_origin
from .loader import PatchBatch, ThreadLoader, collate_patches
from .unprocess import Unprocess

torch = require_extra("torch", "torch")

NoiseSampler = Callable[[np.ndarray, np.random.Generator, dict], tuple[np.ndarray, dict]]


# ------------------------------------------------------------------------------- sources
@dataclass
class Source:
    """One clean image: a normalised-raw mosaic (``kind="raw"``) or display sRGB (``kind="srgb"``)."""

    data: np.ndarray | None = None
    path: Path | None = None
    kind: str = "raw"
    cfa: str | None = "RGGB"

    @property
    def needs_spawn(self) -> bool:
        return self.path is not None and self.path.suffix.lower() == ".dng"

    def load(self) -> "Source":
        if self.data is not None:
            return self
        p = self.path
        suffix = p.suffix.lower()
        if suffix == ".npy":
            arr = np.load(p, allow_pickle=False)
        elif suffix == ".dng":
            from ..io.normalized import read_normalized

            frame = read_normalized(p)
            return Source(frame.data.astype(np.float32), p, "raw", frame.meta.cfa)
        elif suffix in (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr"):
            from ..io.images import read_image

            arr = read_image(p)[..., :3]
        else:
            raise DatasetError(f"{p}: unsupported clean source {suffix!r}; expected .npy, .dng or an sRGB image")
        arr = np.asarray(arr, dtype=np.float32)
        if arr.ndim == 2:
            return Source(arr, p, "raw", self.cfa)
        if arr.ndim == 3 and arr.shape[2] == 3:
            return Source(arr, p, "srgb", None)
        raise DatasetError(f"{p}: expected an H x W mosaic or H x W x 3 image, got shape {arr.shape}")


def as_sources(items: Sequence[Any], cfa: str = "RGGB") -> list[Source]:
    """Paths, arrays (H x W mosaic with ``cfa``; H x W x 3 sRGB) or RawFrames -> sources."""
    out = []
    for k, it in enumerate(items):
        if isinstance(it, Source):
            out.append(it)
        elif isinstance(it, RawFrame):
            if it.kind != "raw":
                raise DatasetError(f"sources[{k}]: expected a normalised raw frame, got kind {it.kind!r}")
            out.append(Source(it.data, None, "raw", it.meta.cfa))
        elif isinstance(it, (str, Path)):
            p = Path(it)
            if not p.exists():
                raise DatasetError(f"{p}: no such clean source file")
            out.append(Source(None, p, "raw", cfa))
        else:
            a = np.asarray(it, dtype=np.float32)
            kind = "srgb" if a.ndim == 3 and a.shape[2] == 3 else "raw"
            if kind == "raw" and a.ndim != 2:
                raise DatasetError(f"sources[{k}]: expected an H x W mosaic or H x W x 3 image, got shape {a.shape}")
            out.append(Source(a, None, kind, cfa if kind == "raw" else None))
    if not out:
        raise DatasetError("sources: expected at least one clean source")
    return out


# ------------------------------------------------------------------------------- sample maker
class PatchMaker:
    """Deterministic sample factory shared by the map-style and iterable datasets."""

    def __init__(self, sources, noise: NoiseSampler, *, patch_size: int = 128, seed: int = 0,
                 cfa_out: str | None = "RGGB", unprocess: Unprocess | None = None, cfa: str = "RGGB"):
        self.sources = as_sources(sources, cfa)
        self.noise = noise
        self.patch_size = int(patch_size)
        self.seed = int(seed)
        self.cfa_out = check_pattern(cfa_out) if cfa_out else None
        self.unprocess = unprocess
        self._cache: dict[int, Source] = {}
        if any(s.kind == "srgb" and s.data is not None for s in self.sources) and unprocess is None:
            self.unprocess = Unprocess(cfa=self.cfa_out or "RGGB")

    @property
    def needs_spawn(self) -> bool:
        return bool(getattr(self.noise, "needs_spawn", False) or any(s.needs_spawn for s in self.sources))

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_cache"] = {}  # never ship loaded images to workers
        return state

    def source(self, k: int) -> Source:
        src = self._cache.get(k)
        if src is None:  # (thread workers may race here: each gets a valid source)
            if len(self._cache) > 64:
                self._cache.clear()
            src = self._cache[k] = self.sources[k].load()
        return src

    def make(self, index: int, epoch: int, source_index: int | None = None) -> dict[str, Any]:
        p = self.patch_size
        noisy, clean = np.empty((4, p, p), np.float32), np.empty((4, p, p), np.float32)
        meta = self.make_into(index, epoch, noisy, clean, source_index)
        return {"noisy": torch.from_numpy(noisy), "clean": torch.from_numpy(clean), "meta": meta}

    def make_into(self, index: int, epoch: int, noisy_out: np.ndarray, clean_out: np.ndarray,
                  source_index: int | None = None) -> dict[str, Any]:
        """Write sample ``index`` of ``epoch`` into ``noisy_out`` / ``clean_out`` (4 x p x p float32,
        C-contiguous) and return its meta."""
        ss = np.random.SeedSequence([self.seed, int(epoch), int(index)])
        crop_ss, noise_ss = ss.spawn(2)
        rng = np.random.default_rng(crop_ss)
        k = int(rng.integers(len(self.sources))) if source_index is None else int(source_index)
        src = self.source(k)
        p2 = 2 * self.patch_size
        h, w = src.data.shape[:2]
        where = src.path or f"sources[{k}]"
        if src.kind == "raw":
            cfa = src.cfa or "RGGB"
            top, left = crop_origin(rng, (h, w), p2, cfa, self.cfa_out, where)
            mosaic = src.data[top:top + p2, left:left + p2]
            out_cfa = shift_pattern(cfa, top, left)
            unproc: dict[str, float] = {}
        else:
            if h < p2 or w < p2:
                raise DatasetError(f"{where}: {h}x{w} image is smaller than a {p2}x{p2} patch")
            top, left = int(rng.integers(h - p2 + 1)), int(rng.integers(w - p2 + 1))
            mosaic, drawn = self.unprocess(src.data[top:top + p2, left:left + p2], rng)
            out_cfa = self.unprocess.cfa
            unproc = {"red_gain": drawn["red_gain"], "blue_gain": drawn["blue_gain"], "rgb_gain": drawn["rgb_gain"]}
        noise_rng = np.random.default_rng(noise_ss)
        info = {"cfa": out_cfa}
        if getattr(self.noise, "packs", False):  # pack and noise in one pass, same bytes
            params = self.noise.pack_noise(mosaic, noise_rng, info, clean_out, noisy_out)
            return self._meta(index, epoch, k, top, left, out_cfa, params, unproc)
        for c, (dy, dx) in enumerate(PACK_OFFSETS):
            clean_out[c] = mosaic[dy::2, dx::2]
        if getattr(self.noise, "writes_out", False):
            _, params = self.noise(clean_out, noise_rng, info, out=noisy_out)
        else:
            noisy, params = self.noise(clean_out, noise_rng, info)
            noisy_out[...] = noisy
        return self._meta(index, epoch, k, top, left, out_cfa, params, unproc)

    @staticmethod
    def _meta(index, epoch, k, top, left, cfa, params, unproc) -> dict[str, Any]:
        return {"index": int(index), "epoch": int(epoch), "source": k, "top": top, "left": left,
                "cfa": cfa, **{k2: float(v) for k2, v in params.items()}, **unproc}

    def make_batch(self, indices: Sequence[int], epoch: int,
                   source_indices: Sequence[int] | None = None) -> "PatchBatch":
        """The samples ``indices`` of ``epoch`` made straight into one stacked pair of tensors
        (in shared memory inside a DataLoader worker, so the batch is not copied again)."""
        noisy, clean = _batch_tensor(len(indices), self.patch_size), _batch_tensor(len(indices), self.patch_size)
        nn, cn = noisy.numpy(), clean.numpy()
        metas = [self.make_into(i, epoch, nn[j], cn[j], None if source_indices is None else source_indices[j])
                 for j, i in enumerate(indices)]
        return PatchBatch({"noisy": noisy[j], "clean": clean[j], "meta": m} for j, m in enumerate(metas)).stacked(
            noisy, clean, metas)


def _batch_tensor(n: int, p: int):
    """An uninitialised n x 4 x p x p float32 tensor, allocated in shared memory inside a
    DataLoader worker (as ``default_collate`` does, so the batch crosses to the main process
    without a copy)."""
    if torch.utils.data.get_worker_info() is None:
        # numpy's allocation (memory reused by malloc, huge pages where the kernel grants them)
        # measured cheaper than torch.empty's for batches of megabytes
        return torch.from_numpy(np.empty((n, 4, p, p), np.float32))
    proto = torch.empty(0, dtype=torch.float32)
    storage = proto._typed_storage()._new_shared(n * 4 * p * p)
    return proto.new(storage).resize_(n, 4, p, p)


# ------------------------------------------------------------------------------- datasets
class _Epoched:
    """The current epoch (:meth:`set_epoch` between epochs)."""

    epoch: int

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)


class _Sized:
    """``length`` samples per epoch, indices 0 .. length - 1."""

    length: int

    def __len__(self) -> int:
        return self.length

    def _check_index(self, index: int) -> None:
        if not 0 <= index < self.length:
            raise IndexError(index)


class _EpochedPatches(_Epoched):
    """What the synthetic-noise datasets share: a :class:`PatchMaker` and the current epoch."""

    maker: "PatchMaker"

    @property
    def needs_spawn(self) -> bool:
        return self.maker.needs_spawn

class NoisyPatchDataset(_EpochedPatches, _Sized, torch.utils.data.Dataset):
    """Map-style dataset of ``length`` noisy/clean packed patches per epoch.

    Parameters
    ----------
    sources : sequence
        Clean sources (paths, arrays, RawFrames; see :func:`as_sources`).
    noise : callable
        ``noise(clean_packed, rng, info) -> (noisy_packed, params)``
        (see :mod:`simcam.training.samplers`).
    length : int
        Samples per epoch.
    patch_size : int
        Packed patch side (the mosaic crop is twice as large).
    seed, epoch : int
        Sample i of epoch e uses ``SeedSequence([seed, e, i])``; call
        :meth:`set_epoch` between epochs.
    cfa_out : str or None
        Crop phase so that packed channels follow this pattern (None: keep).
    unprocess : Unprocess, optional
        For sRGB sources (default: Brooks' parameters, identity colour matrix).
    """

    def __init__(self, sources, noise: NoiseSampler, *, length: int, patch_size: int = 128, seed: int = 0,
                 epoch: int = 0, cfa_out: str | None = "RGGB", unprocess: Unprocess | None = None,
                 cfa: str = "RGGB"):
        self.maker = PatchMaker(sources, noise, patch_size=patch_size, seed=seed, cfa_out=cfa_out,
                                unprocess=unprocess, cfa=cfa)
        self.length = int(length)
        self.epoch = int(epoch)

    def __getitem__(self, index: int) -> dict[str, Any]:
        self._check_index(index)
        return self.maker.make(index, self.epoch)

    def __getitems__(self, indices: list[int]) -> "PatchBatch":
        """A batch for the DataLoader's fetcher: made straight into stacked tensors (same values
        as ``[self[i] for i in indices]``)."""
        for i in indices:
            self._check_index(i)
        return self.maker.make_batch(indices, self.epoch)


class PairPatchDataset(_Epoched, _Sized, torch.utils.data.Dataset):
    """Map-style dataset of aligned crops of real noisy/clean pairs (no synthetic noise).

    ``pairs`` is a list of ``(noisy, clean)`` normalised-raw mosaics; ``noisy``
    may hold several frames of the same scene (F x H x W), one is picked per
    sample. Seeding as in :class:`NoisyPatchDataset`.
    """

    def __init__(self, pairs: Sequence[tuple[np.ndarray, np.ndarray]], *, length: int, patch_size: int = 128,
                 seed: int = 0, epoch: int = 0, cfa: str = "RGGB", cfa_out: str | None = "RGGB"):
        self.pairs = []
        for k, (n, c) in enumerate(pairs):
            n, c = np.asarray(n, np.float32), np.asarray(c, np.float32)
            n = n[None] if n.ndim == 2 else n
            if n.ndim != 3 or n.shape[1:] != c.shape:
                raise DatasetError(f"pairs[{k}]: noisy {n.shape} does not match clean {c.shape}; expected "
                                   f"[F,] H x W frames of the clean H x W mosaic")
            self.pairs.append((n, c))
        self.length, self.patch_size, self.seed, self.epoch = int(length), int(patch_size), int(seed), int(epoch)
        self.cfa, self.cfa_out = check_pattern(cfa), (check_pattern(cfa_out) if cfa_out else None)
        self.needs_spawn = False

    def __getitem__(self, index: int) -> dict[str, Any]:
        self._check_index(index)
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, self.epoch, int(index)]))
        k = int(rng.integers(len(self.pairs)))
        noisy, clean = self.pairs[k]
        f = int(rng.integers(noisy.shape[0]))
        p2 = 2 * self.patch_size
        top, left = crop_origin(rng, clean.shape, p2, self.cfa, self.cfa_out, f"pairs[{k}]")
        sl = (slice(top, top + p2), slice(left, left + p2))
        meta = {"index": int(index), "epoch": self.epoch, "source": k, "frame": f, "top": top, "left": left,
                "cfa": shift_pattern(self.cfa, top, left)}
        return {"noisy": torch.from_numpy(np.ascontiguousarray(pack(noisy[f][sl]))),
                "clean": torch.from_numpy(np.ascontiguousarray(pack(clean[sl]))), "meta": meta}


class NoisyPatchStream(_EpochedPatches, torch.utils.data.IterableDataset):
    """Iterable dataset over a file list: ``patches_per_file`` patches from each file, files
    in a per-epoch random order (``SeedSequence([seed, e])``).

    Sharding across workers is by whole batches of ``batch_size`` samples
    (batch b goes to worker b mod num_workers), so a ``DataLoader`` with the
    same ``batch_size`` yields exactly the batches of ``num_workers=0``, in
    the same order, with no duplicates.
    """

    def __init__(self, files: Sequence[Any], noise: NoiseSampler, *, patches_per_file: int = 8,
                 batch_size: int = 1, patch_size: int = 128, seed: int = 0, epoch: int = 0,
                 cfa_out: str | None = "RGGB", unprocess: Unprocess | None = None, cfa: str = "RGGB"):
        self.maker = PatchMaker(files, noise, patch_size=patch_size, seed=seed, cfa_out=cfa_out,
                                unprocess=unprocess, cfa=cfa)
        self.patches_per_file = int(patches_per_file)
        self.batch_size = int(batch_size)
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return len(self.maker.sources) * self.patches_per_file

    def file_order(self) -> np.ndarray:
        rng = np.random.default_rng(np.random.SeedSequence([self.maker.seed, self.epoch]))
        return rng.permutation(len(self.maker.sources))

    def __iter__(self):
        info = torch.utils.data.get_worker_info()
        wid, nw = (info.id, info.num_workers) if info is not None else (0, 1)
        order = self.file_order()
        n = len(self)
        n_batches = -(-n // self.batch_size)
        for b in range(wid, n_batches, nw):
            for i in range(b * self.batch_size, min(n, (b + 1) * self.batch_size)):
                yield self.maker.make(i, self.epoch, source_index=int(order[i // self.patches_per_file]))


# ------------------------------------------------------------------------------- loader
def worker_init(worker_id: int) -> None:
    """One intra-op thread per worker (torch, OpenMP users such as rawpy/onnxruntime)."""
    os.environ["OMP_NUM_THREADS"] = "1"
    torch.set_num_threads(1)


def make_loader(dataset, *, batch_size: int, num_workers: int = 0, shuffle: bool = False,
                generator_seed: int = 0, workers: str = "process", **kwargs):
    """A ``DataLoader`` with the right start method (``spawn`` where rawpy/onnxruntime are used),
    one thread per worker, whole batches made in place (:func:`collate_patches`), and (for
    ``shuffle``) a seeded sampler.

    ``workers="thread"`` makes the batches with ``num_workers`` threads of this process instead
    (:class:`~simcam.training.loader.ThreadLoader`: same batches, no shared-memory
    hand-over; map-style datasets; only ``collate_fn`` and ``drop_last`` among the
    ``DataLoader`` options).
    """
    if workers not in ("process", "thread"):
        raise DatasetError(f"make_loader: workers={workers!r}; expected 'process' or 'thread'")
    if isinstance(dataset, NoisyPatchStream) and batch_size != dataset.batch_size:
        raise DatasetError(f"make_loader: batch_size {batch_size} differs from the stream's batch_size "
                           f"{dataset.batch_size}; expected equal (worker sharding is by batch)")
    kwargs.setdefault("collate_fn", collate_patches)
    gen = None
    if shuffle:
        gen = torch.Generator()
        gen.manual_seed(int(generator_seed) + int(getattr(dataset, "epoch", 0)))
    if workers == "thread" and num_workers > 0:
        extra = sorted(set(kwargs) - {"collate_fn", "drop_last"})
        if extra:
            raise DatasetError(f"make_loader: workers='thread' does not take {', '.join(extra)}")
        sampler = torch.utils.data.RandomSampler(dataset, generator=gen) if shuffle else None
        return ThreadLoader(dataset, batch_size=batch_size, num_workers=num_workers, sampler=sampler,
                            generator=gen, **kwargs)
    if num_workers > 0:
        kwargs.setdefault("worker_init_fn", worker_init)
        if getattr(dataset, "needs_spawn", False):
            kwargs.setdefault("multiprocessing_context", "spawn")
    return torch.utils.data.DataLoader(dataset, batch_size=batch_size, num_workers=num_workers,
                                       shuffle=shuffle, generator=gen, **kwargs)
