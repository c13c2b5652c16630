"""Setup run inside each local dask worker process (``distributed``'s worker ``preload``).

A batch reports every item's failure itself (:func:`simcam.batch.execute` turns an exception into
one line; a worker that dies surfaces as a failed future on the client), so what ``distributed``
logs inside a worker adds nothing for the user, and at shutdown it can add a traceback: a worker
whose heartbeat is in flight when the scheduler closes logs "Failed to communicate with scheduler
during heartbeat" with the whole ``CommClosedError`` chain. The worker's ``distributed`` loggers
are raised to CRITICAL here; the client process keeps its own settings.
"""

from __future__ import annotations

import logging

QUIET_LOGGERS = ("distributed", "distributed.worker", "distributed.core", "distributed.comm",
                 "distributed.nanny", "distributed.utils_perf", "distributed.worker_memory",
                 "distributed.scheduler", "distributed.client")


def quiet_logging(level: int = logging.CRITICAL) -> dict[str, int]:
    """Raise the ``distributed`` loggers of this process to ``level``; return their former levels
    (for :func:`restore_logging`)."""
    former = {}
    for name in QUIET_LOGGERS:
        logger = logging.getLogger(name)
        former[name] = logger.level
        logger.setLevel(level)
    return former


def restore_logging(former: dict[str, int]) -> None:
    """Give the loggers back the levels :func:`quiet_logging` returned."""
    for name, level in former.items():
        logging.getLogger(name).setLevel(level)


def dask_setup(worker) -> None:  # noqa: ARG001 - the preload hook's signature
    """``distributed`` calls this in each worker process as it starts (the preload protocol)."""
    quiet_logging()
