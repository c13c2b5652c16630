"""Command-line inputs: files, folders and glob patterns expanded to a sorted list of files."""

from __future__ import annotations

import glob
from pathlib import Path
from typing import Iterable

from ..errors import SimcamError

_GLOB_CHARS = set("*?[")


def is_pattern(item: str | Path) -> bool:
    """True when ``item`` is a glob pattern (``*``, ``?`` or ``[``) rather than a path."""
    return bool(_GLOB_CHARS & set(str(item)))


def expand_inputs(items: Iterable[str | Path], *, suffixes: Iterable[str], what: str = "input") -> list[Path]:
    """Expand files, folders (their files with one of ``suffixes``) and glob patterns.

    Parameters
    ----------
    items : iterable of path or str
        As given on the command line.
    suffixes : iterable of str
        Lower-case extensions with the dot (``(".dng",)``) that a folder's files must have.
    what : str
        Noun for errors.

    Returns
    -------
    list of Path
        Sorted within each item, in the order the items were given, without repeats.

    Raises
    ------
    SimcamError
        A path that does not exist, a folder or pattern with no matching file.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> for n in ("b.dng", "a.DNG", "c.txt"):
    ...     _ = (d / n).write_bytes(b"")
    >>> [p.name for p in expand_inputs([d], suffixes=(".dng",))]
    ['a.DNG', 'b.dng']
    """
    suffixes = tuple(s.lower() for s in suffixes)
    out: list[Path] = []
    for item in items:
        if is_pattern(item):
            found = sorted(Path(p) for p in glob.glob(str(item)) if Path(p).is_file())
            if not found:
                raise SimcamError(f"{item}: no file matches this {what} pattern")
        else:
            path = Path(item)
            if path.is_dir():
                found = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in suffixes)
                if not found:
                    raise SimcamError(f"{path}: folder has no {'/'.join(suffixes)} file; expected {what} files")
            elif path.exists():
                found = [path]
            else:
                raise SimcamError(f"{path}: no such file or folder")
        out.extend(p for p in found if p not in out)
    return out
