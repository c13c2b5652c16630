"""simcam: camera-pipeline simulator and raw noise-synthesis toolkit."""

__version__ = "0.1.0"

from .api import read, render  # noqa: E402
from .errors import SimcamError  # noqa: E402
from .frame import CameraMeta, RawFrame  # noqa: E402

__all__ = ["__version__", "SimcamError", "CameraMeta", "RawFrame", "read", "render"]
