"""Output paths checked before any work starts.

Every command checks its outputs first, so a wrong ``-o`` is one line before minutes of work
and never leaves a partial file: a file path that is an existing folder, a file whose folder does
not exist, a folder path that is an existing file, and an output that is one of the inputs are
refused with :class:`~simcam.errors.OutputError`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable

from ..errors import OutputError


def _same(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def check_output_file(path: str | Path, *, option: str = "-o", inputs: Iterable[str | Path] = (),
                      suffixes: Iterable[str] | None = None) -> Path:
    """Check that ``path`` can be written as a file.

    Parameters
    ----------
    path : path
        The output file.
    option : str
        The command-line option that named it (in the error).
    inputs : paths
        Files the command reads; the output may not be one of them.
    suffixes : iterable of str, optional
        Accepted extensions (lower case, with the dot).

    Returns
    -------
    Path

    Raises
    ------
    OutputError
        ``path`` is a folder, its folder does not exist or is not a folder, it has another
        extension, or it is one of ``inputs``.

    Examples
    --------
    >>> import tempfile
    >>> d = tempfile.mkdtemp()
    >>> check_output_file(d, option="-o")
    Traceback (most recent call last):
    ...
    simcam.errors.OutputError: ... -o: is a folder; expected a file path
    """
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"{path}: {option}: is a folder; expected a file path")
    parent = path.parent
    if not parent.exists():
        raise OutputError(f"{path}: {option}: output folder {parent} does not exist")
    if not parent.is_dir():
        raise OutputError(f"{path}: {option}: {parent} is a file; expected the output's folder")
    if suffixes is not None:
        allowed = sorted(set(suffixes))
        if path.suffix.lower() not in allowed:
            raise OutputError(f"{path}: {option}: extension {path.suffix or '(none)'!r}; expected one of {allowed}")
    for p in inputs:
        if p is not None and _same(Path(p), path):
            raise OutputError(f"{path}: {option}: refusing to overwrite the input {p}")
    return path


def check_output_dir(path: str | Path, *, option: str = "--out", inputs: Iterable[str | Path] = ()) -> Path:
    """Check that ``path`` is, or can be made, a folder (it is created later, by the writer).

    Parameters
    ----------
    path, option
        The output folder and the command-line option that named it (in the error).
    inputs : paths
        Files or folders the command reads; the output may not be one of them.

    Returns
    -------
    Path
        ``path`` as a :class:`~pathlib.Path` (the folder is not created here).

    Raises
    ------
    OutputError
        ``path`` or one of its ancestors is an existing file, or ``path`` is an input.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputError(f"{path}: {option}: is a file; expected a folder")
    ancestor = path
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if ancestor.exists() and not ancestor.is_dir():
        raise OutputError(f"{path}: {option}: {ancestor} is a file; expected a folder")
    for p in inputs:
        if p is not None and _same(Path(p), path):
            raise OutputError(f"{path}: {option}: refusing to write into the input {p}")
    return path
