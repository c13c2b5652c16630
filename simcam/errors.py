"""Error families of simcam.

Every error a user can trigger derives from :class:`SimcamError` and carries a
one-line message naming the file, the field, the value and what was expected.
The CLI prints ``str(err)`` and exits with code 2; it never shows a traceback
for these.
"""

from __future__ import annotations


class SimcamError(Exception):
    """Base class of every user-facing simcam error (one clear line).

    Parameters
    ----------
    message : str
        What went wrong; runs of white space (line breaks included) are folded to one space.

    Attributes
    ----------
    args : tuple
        ``(message,)``, the folded one-line message.

    Examples
    --------
    >>> from simcam import SimcamError
    >>> str(SimcamError("photo.dng:   ColorMatrix1:  missing"))
    'photo.dng: ColorMatrix1: missing'
    """

    def __init__(self, message: str):
        super().__init__(" ".join(str(message).split()))


class DngError(SimcamError):
    """A DNG (or TIFF) file cannot be read or written as asked."""


class MetadataError(SimcamError):
    """Camera metadata is missing or inconsistent for the requested operation."""


class PipelineError(SimcamError):
    """A pipeline description or stage parameter is invalid."""


class CfaError(SimcamError):
    """A colour-filter-array pattern is not one of the four 2x2 Bayer patterns."""


class StageError(SimcamError):
    """A stage cannot process the frame it was given."""


class ImageIOError(SimcamError):
    """An image file (PNG, TIFF, EXR) cannot be read or written."""


class ProfileError(SimcamError):
    """A calibration profile is invalid or does not cover the request."""


class NoiseModelError(SimcamError):
    """A noise model got invalid inputs or parameters."""


class DatasetError(SimcamError):
    """A capture set, burst or benchmark input is invalid."""


class OptionalDependencyError(SimcamError):
    """An optional extra is needed: the message names the ``pip install`` line."""


def require_extra(module: str, extra: str):
    """Import an optional module or raise :class:`OptionalDependencyError`.

    Parameters
    ----------
    module : str
        Module name, e.g. ``"torch"``.
    extra : str
        The simcam extra that provides it, e.g. ``"torch"``.
    """
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:  # pragma: no cover - depends on environment
        raise OptionalDependencyError(
            f"{module} is needed for this feature: pip install 'simcam[{extra}]' ({exc})"
        ) from None


class SimcamWarning(UserWarning):
    """Something simcam did not do and says so (an optional DNG opcode it cannot apply, ...)."""


class OutputError(SimcamError):
    """An output path cannot be written as asked (a folder where a file is expected, a missing folder, an input)."""
