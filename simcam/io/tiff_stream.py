"""An uncompressed TIFF written band by band while a render computes it.

A 12 MP 16-bit render is 72 MB of samples. Written the usual way they are first an array in
memory (72 MB of fresh pages the kernel must fault in and zero) and then copied into the file.
:class:`TiffStream` creates the file first, with every tag of :func:`simcam.io.tiff_write.write_tiff`
and a region of the samples' size left unwritten, and each band of output rows is encoded into a
small buffer and written at its place (``os.pwrite``, from any thread, in any order). The file has the
same bytes as :func:`simcam.io.images.write_image` writes for the same samples, and appears only
when complete (a temporary file beside it, renamed by :meth:`TiffStream.commit`).

Used by :func:`simcam.jobs.render_file` for uncompressed TIFF outputs of the fused demosaic tail
(:func:`simcam.render_samples.render_demosaic_tail`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import ImageIOError


class TiffStream:
    """Where a render writes its output rows: an uncompressed TIFF at ``path``.

    Parameters
    ----------
    path : path
        The TIFF to write (replaced only by :meth:`commit`).
    protect : paths
        Files that must never be overwritten (the inputs).

    :meth:`open` makes the temporary file once the output's size, sample type, signal kind and
    metadata are known; :meth:`write` puts rows in it; :meth:`commit` renames it onto ``path``;
    :meth:`discard` (always call it, e.g. in a ``finally``) removes it if it was not committed.
    """

    def __init__(self, path: str | Path, *, protect: tuple = ()):
        self.path, self.protect = Path(path), tuple(protect)
        self.tmp: str | None = None
        self.fd: int | None = None
        self.shape: tuple[int, int, int] | None = None

    def open(self, shape: tuple[int, int, int], dtype, kind: str | None, meta) -> TiffStream:
        """Create the file for ``shape`` (H x W x 3) samples of ``dtype`` (tags from ``kind`` and ``meta``)."""
        from .atomic import temp_beside
        from .images import check_output_path, tiff_tags
        from .tiff_write import write_tiff

        check_output_path(self.path, self.protect)
        self.tmp = temp_beside(self.path, self.path.suffix)
        try:
            self.offset = write_tiff(self.tmp, None, shape=shape, dtype=dtype, **tiff_tags(kind, meta))
            self.fd = os.open(self.tmp, os.O_WRONLY)
        except (OSError, ValueError) as exc:
            raise ImageIOError(f"{self.path}: write failed ({type(exc).__name__}: {exc})") from None
        self.shape, self.dtype = tuple(shape), np.dtype(dtype)
        self.row_bytes = shape[1] * shape[2] * self.dtype.itemsize
        return self

    def write(self, row0: int, rows: np.ndarray) -> None:
        """Write output rows ``row0 .. row0 + len(rows)`` (n x W x 3 of the file's sample type)."""
        if rows.dtype != self.dtype or rows.shape[1:] != self.shape[1:] or row0 + len(rows) > self.shape[0]:
            raise ValueError(f"TiffStream.write: rows {rows.dtype} {rows.shape} at row {row0}; expected "
                             f"{self.dtype} rows of {self.shape}")
        data = memoryview(np.ascontiguousarray(rows)).cast("B")
        at = self.offset + row0 * self.row_bytes
        try:
            while len(data):
                n = os.pwrite(self.fd, data, at)
                data, at = data[n:], at + n
        except OSError as exc:
            raise ImageIOError(f"{self.path}: write failed ({type(exc).__name__}: {exc})") from None

    def commit(self) -> None:
        """Close the file and move it onto ``path``."""
        from .atomic import publish

        self._close()
        publish(self.tmp, self.path)
        self.tmp = None

    def discard(self) -> None:
        """Close and remove the temporary file, if it was not committed."""
        self._close()
        if self.tmp is not None and os.path.exists(self.tmp):
            os.unlink(self.tmp)
        self.tmp = None

    def _close(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None
