"""Batch jobs over many inputs, on ``dask.distributed`` or in this process.

A batch command (``simcam render IN... -o DIR``, ``simcam synth ... -o set.zarr``,
``simcam gt BURSTS... -o DIR``, ``simcam loop SETS... --out DIR``) turns its inputs into
:class:`Task` objects and hands them to :func:`run_batch` with a *job*: a module-level function
``job(payload) -> dict`` that does one item and writes that item's outputs (atomically: the
writers write then rename). ``run_batch``

* runs the tasks on a ``LocalCluster`` of worker processes (one thread each, numba / BLAS /
  OpenMP / onnxruntime limited to ``threads_per_worker`` threads so workers do not
  oversubscribe the cores), on an existing scheduler (``scheduler="tcp://host:8786"`` or the
  ``DASK_SCHEDULER_ADDRESS`` variable), or serially in this process (``workers=0``);
* shows a progress bar on the client (on a terminal) and prints the dashboard address;
* collects per-item failures (one line each) while the other items complete; a failed item
  leaves none of its outputs behind;
* with ``resume=True`` skips the items whose outputs all exist;
* hands dask the items one by one while there are at most ``TASKS_PER_SLOT`` (32) per worker thread,
  else in consecutive chunks, one task each (:func:`chunks`): a dask task costs the client process
  (scheduler, result fetch) a few milliseconds of CPU, which two busy workers on two cores pay for.

Determinism is the job's: item *i* draws from ``SeedSequence([seed, i])`` (the commands put the
seed in the payload), so the bytes written do not depend on the worker count, the scheduler or
the order in which items finish.

Worker start. The local workers are forked from a *fork server* (``multiprocessing``'s
``forkserver`` start method, ``distributed.worker.multiprocessing-method``), a fresh
single-threaded process that imports dask and the modules the job lists in its ``preload``
attribute once; each worker is a fork of it, so it starts with them imported, and it exits
without running the interpreter's teardown. Against dask's default (``spawn``: every worker a new
interpreter that imports everything itself and tears it down at the end) this cuts the fixed
cost of a batch (``benchmarks/batch.py`` prints it). Forking a
single-threaded server is safe, unlike forking the client (threads of the event loop). Where the
platform has no fork server (Windows), or the dask configuration names a start method
(``DASK_DISTRIBUTED__WORKER__MULTIPROCESSING_METHOD``), workers start as dask starts them.
"""

from __future__ import annotations

import logging
import os
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

from .errors import OptionalDependencyError, SimcamError

#: Environment variables that cap the threads of simcam's row bands (:mod:`simcam.parallel`), numba,
#: OpenMP, BLAS and onnxruntime in a worker.
THREAD_VARIABLES = ("SIMCAM_THREADS", "OMP_NUM_THREADS", "NUMBA_NUM_THREADS", "MKL_NUM_THREADS",
                    "OPENBLAS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")


@dataclass(frozen=True)
class Task:
    """One item of a batch.

    Attributes
    ----------
    key : str
        What the item is called in progress and error lines (usually its input path).
    payload : object
        The job's argument (picklable).
    outputs : tuple of str
        Files or folders the item writes: all present means done (``resume``); on failure the
        ones that did not exist before are removed.
    """

    key: str
    payload: Any
    outputs: tuple[str, ...] = ()


@dataclass
class Outcome:
    """What became of one task."""

    key: str
    ok: bool
    skipped: bool = False
    error: str | None = None
    seconds: float = 0.0
    info: dict = field(default_factory=dict)


@dataclass
class BatchConfig:
    """Where and how a batch runs.

    Attributes
    ----------
    workers : int or None
        Worker processes of the local cluster; ``None``: one per core; ``0``: no cluster, the
        items run one after the other in this process.
    scheduler : str or None
        Address of an existing ``dask.distributed`` scheduler (``tcp://host:8786``); default
        ``$DASK_SCHEDULER_ADDRESS``. Its workers must see the inputs and outputs under the same
        paths (a shared filesystem) or use fsspec URLs.
    threads_per_worker : int
        Threads of each worker, and the cap on numba / BLAS / OpenMP threads inside it.
    memory_limit : str
        Per-worker memory limit of the local cluster (dask syntax, ``"auto"`` = RAM / workers).
    resume : bool
        Skip items whose outputs all exist.
    progress : bool
        A progress bar on stderr (only on a terminal).
    """

    workers: int | None = None
    scheduler: str | None = None
    threads_per_worker: int = 1
    memory_limit: str = "auto"
    resume: bool = False
    progress: bool = True

    def scheduler_address(self) -> str | None:
        return self.scheduler or os.environ.get("DASK_SCHEDULER_ADDRESS") or None


def one_line(exc: BaseException) -> str:
    """``str(exc)`` on one line; unexpected exception types are named."""
    msg = " ".join(str(exc).split()) or "(no message)"
    return msg if isinstance(exc, SimcamError) else f"{type(exc).__name__}: {msg}"


def _remove(paths: Sequence[str]) -> None:
    for p in paths:
        path = Path(p)
        if path.is_dir():
            shutil.rmtree(path, ignore_errors=True)
        elif path.exists():
            path.unlink(missing_ok=True)


def execute(job: Callable[[Any], dict], task: Task) -> Outcome:
    """Run one task where it is scheduled; never raises (a failure is an :class:`Outcome`)."""
    before = {p for p in task.outputs if Path(p).exists()}
    t0 = time.perf_counter()
    try:
        info = dict(job(task.payload) or {})
    except Exception as exc:  # noqa: BLE001 - every failure becomes one line of the report
        _remove([p for p in task.outputs if p not in before])
        return Outcome(task.key, ok=False, error=one_line(exc), seconds=time.perf_counter() - t0)
    info["peak_rss_mib"] = _peak_rss_mib()
    return Outcome(task.key, ok=True, seconds=time.perf_counter() - t0, info=info)


def execute_chunk(job: Callable[[Any], dict], tasks: Sequence[Task]) -> list[Outcome]:
    """:func:`execute` on each task of one chunk, in order (one dask task runs a chunk)."""
    return [execute(job, t) for t in tasks]


#: Dask tasks per worker thread a batch is cut into, at most (:func:`chunks`).
TASKS_PER_SLOT = 32


def chunks(todo: Sequence[int], slots: int) -> list[list[int]]:
    """Cut the items ``todo`` into consecutive chunks, one dask task each: items one by one while
    there are at most ``TASKS_PER_SLOT`` per worker thread, else chunks of equal size (to one item)
    so that there are about that many.

    A dask task costs the client process (scheduler, result fetch, release) ~4 ms of CPU
    (``benchmarks/batch.py``, 1000 training-set sources of ~40 ms each: the client took 15 % of a
    core, taken from two busy workers on two cores). Chunks keep that share small while the last
    chunks still balance the workers' load to about 1/``TASKS_PER_SLOT`` of a worker's share (dask
    best practices: tasks well above the scheduler's per-task overhead). A chunk's items keep their own
    outcomes, seeds and outputs, so the bytes written do not depend on the chunking; a chunk whose
    worker died (memory) runs again item by item (:func:`run_batch`), so only the item that kills its
    worker fails.

    Examples
    --------
    >>> chunks([3, 5, 8], 2)
    [[3], [5], [8]]
    >>> parts = chunks(range(130), 2)  # 2 worker threads: 64 tasks, of 3 or 2 items
    >>> len(parts), parts[0], parts[-1], sorted({len(c) for c in parts})
    (64, [0, 1, 2], [128, 129], [2, 3])
    """
    todo = list(todo)
    n = min(len(todo), max(1, int(slots)) * TASKS_PER_SLOT)
    if n == 0:
        return []
    size, extra = divmod(len(todo), n)
    out, start = [], 0
    for c in range(n):
        stop = start + size + (1 if c < extra else 0)
        out.append(todo[start:stop])
        start = stop
    return out


def _peak_rss_mib() -> float:
    """Peak resident memory of this process so far (MiB; Linux reports ru_maxrss in KiB)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _done(task: Task) -> bool:
    return bool(task.outputs) and all(Path(p).exists() for p in task.outputs)


def _worker_env(threads: int) -> dict[str, str]:
    return {v: str(int(threads)) for v in THREAD_VARIABLES}


def _fork_server(preload: Sequence[str], threads: int) -> bool:
    """Start the fork server local workers are forked from (module docstring), importing
    ``distributed`` and ``preload``, with the thread caps in its environment (numba and BLAS read
    them when they are imported, which is in the server). Returns whether workers will start from it.

    It is started before this process imports ``distributed`` itself: the server's imports (the
    longest step before the first item can run) then overlap with the client's import and with the
    scheduler's and nannies' start on the other core."""
    import importlib.util
    import multiprocessing

    if importlib.util.find_spec("distributed") is None or "forkserver" not in multiprocessing.get_all_start_methods() or any(
            k.upper() == "DASK_DISTRIBUTED__WORKER__MULTIPROCESSING_METHOD" for k in os.environ):
        return False
    from multiprocessing import forkserver

    # a server already running keeps the modules it started with; the workers import the rest themselves.
    # distributed.utils.get_mp_context later sets dask's own list (distributed and what it imports) on
    # the running server: no effect then. multiprocessing's default list is ["__main__"]: the server
    # would run this process's main script again (for `simcam`, the whole CLI and typer) for nothing —
    # a job is a module-level function that workers import by name, or cloudpickle carries it.
    current = [m for m in getattr(forkserver._forkserver, "_preload_modules", []) or [] if m != "__main__"]
    wanted = ["distributed", *preload]
    multiprocessing.get_context("forkserver").set_forkserver_preload(
        current + [m for m in wanted if m not in current])
    saved = {v: os.environ.get(v) for v in THREAD_VARIABLES}
    os.environ.update(_worker_env(threads))
    try:
        forkserver.ensure_running()  # the server takes this environment (and keeps it)
    finally:
        for v, old in saved.items():
            if old is None:
                os.environ.pop(v, None)
            else:
                os.environ[v] = old
    return True


def start_workers_early(job: Callable[[Any], dict], config: BatchConfig) -> None:
    """Start the fork server local workers will come from (:func:`_fork_server`) now, so that its imports
    (~0.7 s: ``distributed`` and the job's ``preload``, on the other core) run while the command still
    lists its inputs and prepares its outputs; :func:`run_batch` then finds it running. Nothing for a
    serial batch (``workers=0``) or an existing scheduler. A command that fails before its batch leaves
    the server to end with this process."""
    if config.workers == 0 or config.scheduler_address():
        return
    _fork_server(getattr(job, "preload", ()), config.threads_per_worker)


def _client(config: BatchConfig, forkserver: bool = False):
    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError as exc:
        raise OptionalDependencyError(
            f"dask.distributed is needed for batch jobs: pip install 'simcam[batch]' ({exc})") from None
    # dask's nanny exports MALLOC_TRIM_THRESHOLD_=65536 to its workers by default. Setting any malloc
    # threshold turns off glibc's dynamic mmap threshold, so every temporary over 128 KiB (an image
    # band) is a fresh mmap that faults in page by page: 22,000 page faults per 12 MP render instead of
    # 3,000 and 15-25 % more time per item than the same code in a plain process (benchmarks/batch.py).
    # None unsets it (the workers then manage memory as any Python process does).
    dask.config.set({"distributed.worker.daemon": False, "logging.distributed": "error",
                     "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None})
    for name in ("distributed", "distributed.scheduler", "distributed.nanny", "distributed.worker"):
        logging.getLogger(name).setLevel(logging.ERROR)
    address = config.scheduler_address()
    if address:
        try:
            return Client(address, timeout="20s"), None
        except (OSError, TimeoutError) as exc:
            raise SimcamError(f"--scheduler {address}: cannot reach the dask scheduler ({one_line(exc)})") from None
    workers = config.workers or os.cpu_count() or 1
    # A local worker's statistical profiler wakes its event loop every 10 ms to walk the task thread's
    # stack (it takes the GIL from the item each time): ~0.75 % of a core per worker, measured with items
    # that only sleep. The batch dashboard's task stream and progress stay; its profile tab is empty.
    dask.config.set({"distributed.worker.profile.enabled": False})
    if forkserver:
        dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"})
    import importlib.util

    dashboard = "127.0.0.1:0" if importlib.util.find_spec("bokeh") else None  # the dashboard needs bokeh
    cluster = LocalCluster(n_workers=int(workers), threads_per_worker=int(config.threads_per_worker),
                           processes=True, memory_limit=config.memory_limit, dashboard_address=dashboard,
                           silence_logs=logging.ERROR, env=_worker_env(config.threads_per_worker),
                           host="127.0.0.1", preload=["simcam.batch_worker"])
    return Client(cluster), cluster


def run_batch(job: Callable[[Any], dict], tasks: Sequence[Task], config: BatchConfig | None = None, *,
              label: str = "items", echo: Callable[[str], None] | None = None) -> list[Outcome]:
    """Run ``job`` on every task; return the outcomes in task order.

    Parameters
    ----------
    job : callable
        A module-level function ``job(payload) -> dict`` (it is pickled to the workers). Its
        ``preload`` attribute, if any, names the modules local workers start with imported.
    tasks : sequence of Task
    config : BatchConfig, optional
    label : str
        Noun for the progress bar ("renders", "bursts").
    echo : callable, optional
        Where status lines go (the dashboard address); default stderr.

    Returns
    -------
    list of Outcome
        Failed items have ``ok=False`` and a one-line ``error``; skipped ones ``skipped=True``.

    Examples
    --------
    >>> from simcam.batch import BatchConfig, Task, run_batch
    >>> out = run_batch(dict, [Task("a", {"n": 1}), Task("b", 5)], BatchConfig(workers=0, progress=False))
    >>> [(o.key, o.ok, o.error) for o in out]
    [('a', True, None), ('b', False, "TypeError: 'int' object is not iterable")]
    """
    from tqdm import tqdm

    config = config or BatchConfig()
    echo = echo or (lambda s: print(s, file=sys.stderr))
    outcomes: dict[int, Outcome] = {}
    todo = []
    for i, t in enumerate(tasks):
        if config.resume and _done(t):
            outcomes[i] = Outcome(t.key, ok=True, skipped=True)
        else:
            todo.append(i)
    bar = tqdm(total=len(todo), desc=label, unit="item", disable=None if config.progress else True)
    try:
        if not todo:
            pass
        elif config.workers == 0 and not config.scheduler_address():
            for i in todo:
                outcomes[i] = execute(job, tasks[i])
                bar.update(1)
        else:
            forkserver = not config.scheduler_address() and _fork_server(getattr(job, "preload", ()),
                                                                         config.threads_per_worker)
            from distributed import as_completed

            client, cluster = _client(config, forkserver)
            from simcam.batch_worker import quiet_logging, restore_logging

            # every item's failure is reported by the batch, one line each (report()); what the scheduler
            # logs meanwhile (a task whose workers died, a result lost with its worker) says it again
            former = quiet_logging()
            try:
                if client.dashboard_link:
                    echo(f"dask dashboard: {client.dashboard_link}")
                slots = sum(client.nthreads().values()) or 1
                futures = {client.submit(execute_chunk, job, [tasks[i] for i in group],
                                         key=f"simcam-{label}-{group[0]}-{os.getpid()}", pure=False): group
                           for group in chunks(todo, slots)}
                running = as_completed(futures)
                for fut in running:
                    group = futures[fut]
                    try:
                        done = fut.result()
                    except Exception as exc:  # noqa: BLE001 - a worker died (memory) or could not unpickle
                        if len(group) > 1:  # which item of the chunk it was: each again, as its own task
                            for i in group:
                                one = client.submit(execute_chunk, job, [tasks[i]], pure=False,
                                                    key=f"simcam-{label}-{i}-alone-{os.getpid()}")
                                futures[one] = [i]
                                running.add(one)
                            continue
                        # writers write then rename: a killed worker leaves no partial file
                        done = [Outcome(tasks[group[0]].key, ok=False, error=f"worker failed: {one_line(exc)}")]
                    outcomes.update(zip(group, done))
                    bar.update(len(group))
            finally:
                # the results are in: what distributed logs while it shuts down (a heartbeat that
                # meets a closed scheduler) is not the user's business either
                try:
                    client.close()
                    if cluster is not None:
                        cluster.close()
                finally:
                    restore_logging(former)
    finally:
        bar.close()
    return [outcomes[i] for i in range(len(tasks))]


def report(outcomes: Sequence[Outcome], *, command: str, echo_err: Callable[[str], None] | None = None) -> int:
    """Print one line per failed item and return the exit status (0 all done, 1 any failed)."""
    echo_err = echo_err or (lambda s: print(s, file=sys.stderr))
    failed = [o for o in outcomes if not o.ok]
    for o in failed:
        err = o.error or ""
        echo_err(f"{command}: failed: {err}" if err.startswith(o.key) else f"{command}: failed: {o.key}: {err}")
    return 1 if failed else 0
