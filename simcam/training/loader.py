"""Batches made by a pool of threads in the training process (``make_loader(..., workers="thread")``).

Process workers (PyTorch's ``DataLoader``) hand every batch over through freshly
allocated shared memory: the kernel has to zero and map new pages for each
tensor, about 0.4 ms per MB on the 2-core reference machine, which is more than
the NLF noise itself costs (``benchmarks/dataloader.py``, "transfer only"). The
heavy parts of simcam's samplers release the GIL (the numba NLF and
Poisson-Gaussian kernels, numpy's array loops, onnxruntime), so threads can make
batches in parallel in the consumer's own memory with no hand-over at all -- the
``method="thread"`` mapping that ``torchdata.nodes`` offers, for map-style datasets.

Batches are the ones a ``DataLoader`` with the same ``batch_size``, ``shuffle``
and seeded generator gives (same indices, same bytes: each sample depends only on
(seed, epoch, index)), yielded in order; at most ``num_workers * prefetch``
batches are in flight.
"""

from __future__ import annotations

from collections import deque
from concurrent.futures import ThreadPoolExecutor

from ..errors import DatasetError, require_extra

torch = require_extra("torch", "torch")


class PatchBatch(list):
    """The samples of one batch (a plain list of sample dicts, so ``default_collate`` works on it)
    with the batch already stacked: :func:`collate_patches` returns that without copying."""

    collated: dict | None = None

    def stacked(self, noisy, clean, metas) -> "PatchBatch":
        from torch.utils.data import default_collate

        self.collated = {"noisy": noisy, "clean": clean, "meta": default_collate(metas)}
        return self


def collate_patches(batch):
    """``default_collate``, except for a :class:`PatchBatch` whose stacked tensors are returned as they are."""
    if isinstance(batch, PatchBatch) and batch.collated is not None:
        return batch.collated
    from torch.utils.data import default_collate

    return default_collate(batch)



class ThreadLoader:
    """Iterable of collated batches of a map-style ``dataset`` made by ``num_workers`` threads.

    Parameters
    ----------
    dataset : map-style dataset
        ``__getitems__`` (one call per batch) is used when present, else ``__getitem__``.
    batch_size : int
        Samples per batch.
    num_workers : int
        Threads (>= 1).
    sampler : iterable of int, optional
        Index order (default: 0 .. len - 1).
    generator : torch.Generator, optional
        The shuffling sampler's generator: as ``DataLoader`` does, each epoch first draws one
        int64 from it (the DataLoader's base seed), so both shuffle alike.
    collate_fn : callable
        Batch collation (:func:`collate_patches` by default).
    drop_last : bool
        Drop a last incomplete batch.
    prefetch : int
        Batches in flight per thread.
    """

    def __init__(self, dataset, *, batch_size: int, num_workers: int, sampler=None, generator=None,
                 collate_fn=None, drop_last: bool = False, prefetch: int = 2):
        if isinstance(dataset, torch.utils.data.IterableDataset):
            raise DatasetError(f"thread workers: {type(dataset).__name__} is an iterable dataset; expected a "
                               "map-style one (use process workers for streams)")
        if num_workers < 1 or batch_size < 1 or prefetch < 1:
            raise DatasetError(f"thread workers: num_workers={num_workers}, batch_size={batch_size}, "
                               f"prefetch={prefetch}; expected each >= 1")
        if collate_fn is None:
            collate_fn = collate_patches
        self.dataset, self.collate_fn = dataset, collate_fn
        self.sampler = sampler if sampler is not None else range(len(dataset))
        self.batch_sampler = torch.utils.data.BatchSampler(self.sampler, batch_size, drop_last)
        self.num_workers, self.prefetch = int(num_workers), int(prefetch)
        self.generator = generator

    def __len__(self) -> int:
        return len(self.batch_sampler)

    def _fetch(self, indices):
        ds = self.dataset
        items = ds.__getitems__(indices) if hasattr(ds, "__getitems__") else [ds[i] for i in indices]
        return self.collate_fn(items)

    def __iter__(self):
        if self.generator is not None:
            torch.empty((), dtype=torch.int64).random_(generator=self.generator)
        batches = iter(self.batch_sampler)
        with ThreadPoolExecutor(self.num_workers, thread_name_prefix="simcam-loader") as pool:
            pending: deque = deque()
            try:
                for indices in batches:
                    pending.append(pool.submit(self._fetch, indices))
                    if len(pending) >= self.num_workers * self.prefetch:
                        yield pending.popleft().result()
                while pending:
                    yield pending.popleft().result()
            finally:  # consumer stopped early (or a batch failed): do not make the rest
                for f in pending:
                    f.cancel()
