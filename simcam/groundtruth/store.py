"""Scratch storage of a burst's working frames: in memory when small, else a temporary file.

The file is read with ``os.pread`` (not memory-mapped), so its pages never count
towards the process's resident memory; row strips of all frames are read back
for the tiled robust mean.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from ..errors import DatasetError


class FrameStore:
    """N float32 frames of shape (H, W).

    Parameters
    ----------
    n, shape : int, (int, int)
        Number and size of the frames.
    budget_bytes : int
        Frames are kept in RAM when ``n * H * W * 4`` fits, else in a file.
    scratch_dir : path, optional
        Where the scratch file goes (default: the system temporary directory).
    """

    def __init__(self, n: int, shape: tuple[int, int], *, budget_bytes: int = 2 << 30,
                 scratch_dir: str | Path | None = None):
        self.n = int(n)
        self.shape = (int(shape[0]), int(shape[1]))
        self.frame_bytes = self.shape[0] * self.shape[1] * 4
        self.row_bytes = self.shape[1] * 4
        self.mem: np.ndarray | None = None
        self.fd: int | None = None
        self.path: str | None = None
        if self.n * self.frame_bytes <= budget_bytes:
            self.mem = np.empty((self.n,) + self.shape, dtype=np.float32)
        else:
            try:
                fd, path = tempfile.mkstemp(prefix="simcam-gt-", suffix=".f32", dir=scratch_dir)
                os.ftruncate(fd, self.n * self.frame_bytes)
            except OSError as exc:
                raise DatasetError(f"{scratch_dir or tempfile.gettempdir()}: cannot create the "
                                   f"{self.n * self.frame_bytes / 2**30:.1f} GiB scratch file ({exc})") from None
            self.fd, self.path = fd, path

    @property
    def on_disk(self) -> bool:
        return self.fd is not None

    def put(self, i: int, frame: np.ndarray) -> None:
        frame = np.ascontiguousarray(frame, dtype=np.float32)
        if self.mem is not None:
            self.mem[i] = frame
            return
        buf = memoryview(frame).cast("B")
        off, done = i * self.frame_bytes, 0
        while done < len(buf):
            done += os.pwrite(self.fd, buf[done:], off + done)

    def _pread_into(self, out: np.ndarray, offset: int) -> None:
        buf = memoryview(out).cast("B")
        done = 0
        while done < len(buf):
            k = os.preadv(self.fd, [buf[done:]], offset + done)
            if k <= 0:
                raise DatasetError(f"{self.path}: short read from the scratch file")
            done += k

    def get(self, i: int) -> np.ndarray:
        if self.mem is not None:
            return self.mem[i].copy()
        out = np.empty(self.shape, dtype=np.float32)
        self._pread_into(out, i * self.frame_bytes)
        return out

    def rows(self, indices, r0: int, r1: int) -> np.ndarray:
        """Rows ``r0:r1`` of the frames ``indices``: (len(indices), r1 - r0, W)."""
        idx = list(indices)
        if self.mem is not None:
            return self.mem[idx, r0:r1]
        out = np.empty((len(idx), r1 - r0, self.shape[1]), dtype=np.float32)
        for k, i in enumerate(idx):
            self._pread_into(out[k], i * self.frame_bytes + r0 * self.row_bytes)
        return out

    def close(self) -> None:
        self.mem = None
        if self.fd is not None:
            os.close(self.fd)
            try:
                os.unlink(self.path)
            except OSError:
                pass
            self.fd = None

    def __enter__(self) -> "FrameStore":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
