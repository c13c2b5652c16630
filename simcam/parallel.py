"""Row bands on a thread pool: the one place simcam's image kernels get their parallelism.

numpy and scipy release the GIL inside their loops, so independent row bands of
an image run in parallel on threads. Bands are fixed by the caller (not by the
thread count) and each writes only its own rows, so results are the same bytes
whatever the number of threads.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor


def threads() -> int:
    """Worker threads: ``SIMCAM_THREADS`` if set to a positive integer, else the number of cores this process may use."""
    env = os.environ.get("SIMCAM_THREADS", "").strip()
    if env.isdigit() and int(env) > 0:
        return int(env)
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def run_bands(h: int, fn, rows: int = 16) -> bool:
    """Run ``fn(r0, r1)`` on every band of ``rows`` rows of ``range(h)`` on :func:`threads` threads;
    True if any call returned True."""
    bands = [(r, min(h, r + rows)) for r in range(0, h, rows)]
    n = min(threads(), len(bands))
    if n <= 1:
        return any([fn(a, b) for a, b in bands])  # noqa: C419 (a list: every band must run)
    with ThreadPoolExecutor(n) as ex:
        return any(list(ex.map(lambda ab: fn(*ab), bands)))


def map_threads(fn, items: list) -> list:
    """``[fn(x) for x in items]`` on :func:`threads` threads, results in the order of ``items``.

    For independent items that write only their own outputs (as row bands do), so the results are
    the same bytes whatever the number of threads.
    """
    n = min(threads(), len(items))
    if n <= 1:
        return [fn(x) for x in items]
    with ThreadPoolExecutor(n) as ex:
        return list(ex.map(fn, items))
