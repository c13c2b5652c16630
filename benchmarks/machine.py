"""What every benchmark prints about the machine it ran on (ratios depend on it: AVX2 vs AVX-512
changes them by up to 2x on this VM type)."""

from __future__ import annotations

import platform
from pathlib import Path


def cpu_model() -> str:
    """The CPU model from /proc/cpuinfo (else what :mod:`platform` knows, else "unknown")."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def compile_simcam() -> None:
    """Compile simcam's bytecode, as a (non-editable) pip install does, before timing fresh processes.

    With an editable install and ``PYTHONDONTWRITEBYTECODE`` set (as on the CI machines), every new
    process would otherwise compile every simcam module it imports (~0.1 s for a render, more for a dask
    worker's start), a cost that rawpy, tifffile and dask, installed compiled, never pay.
    """
    import compileall

    import simcam

    compileall.compile_dir(str(Path(simcam.__file__).parent), quiet=1)
