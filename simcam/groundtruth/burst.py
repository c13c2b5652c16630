"""A burst: an ordered set of frames of one static scene, loaded one at a time.

Frames are served as normalised raw (float32 H x W, black subtracted, divided by
white - black, negatives kept; see :mod:`simcam.frame`). Every frame is checked
against the first: size, CFA pattern, ISO and exposure time must agree, and a
frame must not contain NaN or infinite values. A burst never holds more than one
frame in memory by itself.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from ..errors import DatasetError
from ..frame import CameraMeta, RawFrame

RAW_EXTS = (".dng",)
IMAGE_EXTS = (".png", ".tif", ".tiff", ".pgm")
#: File stems of clean references written beside burst frames (simcam synth: clean.dng; simcam gt: gt.*).
REFERENCE_STEMS = ("clean", "gt")


def is_sidd_frame(p: Path) -> bool:
    """A SIDD noisy raw frame: ``*_NOISY_RAW_NNN.MAT``."""
    return p.is_file() and p.suffix.upper() == ".MAT" and "NOISY_RAW" in p.name.upper()


@dataclass
class FrameSettings:
    """What every frame of a burst must share."""

    shape: tuple[int, int]
    cfa: str | None
    iso: float | None = None
    exposure_time_s: float | None = None

    def check(self, other: "FrameSettings", name: str, first: str) -> None:
        if other.shape != self.shape:
            raise DatasetError(f"{name}: shape: {other.shape[0]}x{other.shape[1]}, expected "
                               f"{self.shape[0]}x{self.shape[1]} like {first}")
        if other.cfa != self.cfa:
            raise DatasetError(f"{name}: cfa: {other.cfa!r}, expected {self.cfa!r} like {first}")
        for f in ("iso", "exposure_time_s"):
            a, b = getattr(self, f), getattr(other, f)
            if (a is None) != (b is None) or (a is not None and not np.isclose(a, b, rtol=1e-6, atol=0)):
                raise DatasetError(f"{name}: {f}: {b}, expected {a} like {first} (a burst needs one ISO and exposure)")


@dataclass
class Burst:
    """Frames of one scene, loaded lazily.

    Parameters
    ----------
    loaders : list of callables
        ``loaders[i]()`` returns frame i as a :class:`~simcam.frame.RawFrame`
        (kind ``raw`` or ``raw_dn``) or an H x W normalised array.
    names : list of str
        A name per frame for reports and error messages (file names).
    cfa : str or None
        Bayer pattern, or None for a monochrome sensor. Taken from the frames'
        metadata when they carry it.
    clip_low, clip_high : float
        Normalised values at which the sensor clips (samples at or beyond them
        are censored). From metadata when known: ``-black/(white-black)`` and 1.
    nan_policy : {"raise", "omit"}
        NaN in a frame raises :class:`DatasetError` (default) or marks missing samples.

    Attributes
    ----------
    settings : FrameSettings or None
        ISO, exposure and size shared by the frames (from their metadata), once checked.

    Examples
    --------
    >>> import numpy as np
    >>> burst = Burst.from_arrays([np.full((4, 4), 0.2 + 0.01 * i) for i in range(3)], cfa="RGGB")
    >>> len(burst), round(float(burst.load(2).mean()), 2)
    (3, 0.22)
    """

    loaders: Sequence[Callable[[], object]]
    names: Sequence[str]
    cfa: str | None = "RGGB"
    clip_low: float = 0.0
    clip_high: float = 1.0
    nan_policy: str = "raise"
    meta: CameraMeta | None = None
    settings: FrameSettings | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        if len(self.loaders) != len(self.names):
            raise DatasetError("burst: expected one name per frame")
        if self.nan_policy not in ("raise", "omit"):
            raise DatasetError(f"burst: nan_policy: expected 'raise' or 'omit', got {self.nan_policy!r}")

    def __len__(self) -> int:
        return len(self.loaders)

    # -- constructors ----------------------------------------------------------------
    @classmethod
    def from_arrays(cls, arrays: Sequence[np.ndarray], *, cfa: str | None = "RGGB", clip_low: float = 0.0,
                    clip_high: float = 1.0, names: Sequence[str] | None = None, **kw) -> "Burst":
        """Frames already in memory (normalised raw, H x W each)."""
        names = list(names) if names is not None else [f"frame[{i}]" for i in range(len(arrays))]
        return cls([(lambda a=a: a) for a in arrays], names, cfa=cfa, clip_low=clip_low, clip_high=clip_high, **kw)

    @classmethod
    def from_function(cls, n: int, fn: Callable[[int], np.ndarray], *, cfa: str | None = "RGGB",
                      clip_low: float = 0.0, clip_high: float = 1.0, name: str = "frame", **kw) -> "Burst":
        """Frames produced on demand by ``fn(i)`` (e.g. a synthetic generator)."""
        return cls([(lambda i=i: fn(i)) for i in range(n)], [f"{name}[{i}]" for i in range(n)], cfa=cfa,
                   clip_low=clip_low, clip_high=clip_high, **kw)

    @classmethod
    def from_directory(cls, path: str | Path, *, black_level: float | None = None,
                       white_level: float | None = None, pattern: str | None = None, **kw) -> "Burst":
        """Every DNG (or every PNG/TIFF/PGM, monochrome) file of a directory, in name order.

        DNGs are read with :func:`simcam.io.dng.read_dng` and normalised with
        their own black/white levels (``black_level``/``white_level`` override).
        Plain images are monochrome DN: ``(DN - black) / (white - black)``;
        ``white_level`` defaults to the sample type's maximum (65535 for 16-bit),
        ``black_level`` to 0. Without ``pattern``, the clean references that ``simcam synth`` and
        ``simcam gt`` write beside frames (``clean.*``, ``gt.*``) are not frames and are skipped.
        """
        path = Path(path)
        if not path.is_dir():
            raise DatasetError(f"{path}: burst directory not found")
        if pattern is None and any(is_sidd_frame(p) for p in path.iterdir()):
            return cls._from_sidd(path, **kw)
        files = sorted(p for p in (path.glob(pattern) if pattern else path.iterdir())
                       if p.is_file() and p.suffix.lower() in RAW_EXTS + IMAGE_EXTS
                       and (pattern or p.stem.lower() not in REFERENCE_STEMS))
        if not files:
            raise DatasetError(f"{path}: no frames found; expected .dng or .png/.tif/.pgm files")
        exts = {p.suffix.lower() in RAW_EXTS for p in files}
        if len(exts) > 1:
            raise DatasetError(f"{path}: mixes DNG and plain image files; expected one kind of frame")
        if files[0].suffix.lower() in RAW_EXTS:
            return cls._from_dngs(files, black_level, white_level, **kw)
        return cls._from_images(files, black_level, white_level, **kw)

    @classmethod
    def _from_dngs(cls, files, black_level, white_level, **kw) -> "Burst":
        try:
            from ..io.dng import read_dng
        except ImportError:  # pragma: no cover - until the DNG reader lands
            raise DatasetError(f"{files[0]}: reading DNG bursts needs simcam.io.dng (not available)") from None
        from ..raw import black_level_map, normalize

        levels = {"black_level": None if black_level is None else float(black_level),
                  "white_level": None if white_level is None else float(white_level)}

        def load(p):
            return normalize(read_dng(p), **levels)

        first = read_dng(files[0])
        meta = first.meta
        black = float(black_level) if black_level is not None else float(black_level_map(meta, first.data.shape).min())
        white = float(white_level) if white_level is not None else float(meta.white_level)
        lo = (0.0 - black) / (white - black)
        return cls([(lambda p=p: load(p)) for p in files], [str(p) for p in files], cfa=meta.cfa,
                   clip_low=lo, clip_high=1.0, meta=meta, **kw)

    @classmethod
    def _from_sidd(cls, path: Path, **kw) -> "Burst":
        """A SIDD scene instance (Abdelhamed, Lin & Brown, CVPR 2018): ``*_NOISY_RAW_NNN.MAT`` frames
        (variable ``x``: normalised raw in [0, 1], black subtracted) and the ``*_METADATA_RAW_*.MAT`` tag
        file (CFA); the ``*_GT_RAW_*`` reference is not a frame."""
        from ..io.sidd import read_sidd_image, read_sidd_meta

        files = sorted(p for p in path.iterdir() if is_sidd_frame(p))
        metas = sorted(p for p in path.iterdir() if "METADATA_RAW" in p.name.upper() and p.suffix.upper() == ".MAT")
        if not metas:
            raise DatasetError(f"{path}: SIDD scene without *_METADATA_RAW_*.MAT; expected the tag file beside "
                               "the NOISY_RAW frames")
        meta = read_sidd_meta(metas[0])

        def load(p):
            return read_sidd_image(p, dtype=np.float32, what="NOISY_RAW")

        return cls([(lambda p=p: load(p)) for p in files], [str(p) for p in files], cfa=meta.cfa,
                   clip_low=0.0, clip_high=1.0, meta=meta, **kw)

    @classmethod
    def _from_images(cls, files, black_level, white_level, **kw) -> "Burst":
        def raw(p):
            a = _read_native(p)
            if a.ndim == 3 and a.shape[2] == 1:
                a = a[..., 0]
            if a.ndim != 2:
                raise DatasetError(f"{p}: expected a single-channel (raw) image, got shape {a.shape}")
            return a

        a0 = raw(files[0])
        if white_level is None:
            white_level = float(np.iinfo(a0.dtype).max) if np.issubdtype(a0.dtype, np.integer) else 1.0
        black = float(black_level or 0.0)
        white = float(white_level)
        if white <= black:
            raise DatasetError(f"{files[0]}: white_level {white} must be above black_level {black}")

        def load(p):
            return ((raw(p).astype(np.float32) - black) / (white - black)).astype(np.float32)

        return cls([(lambda p=p: load(p)) for p in files], [str(p) for p in files], cfa=None,
                   clip_low=(0.0 - black) / (white - black), clip_high=1.0, **kw)

    # -- access ---------------------------------------------------------------------
    def load(self, i: int) -> np.ndarray:
        """Frame ``i`` as float32 normalised raw, checked against frame 0."""
        if self.settings is None and i != 0:
            self.load(0)
        obj = self.loaders[i]()
        name = self.names[i]
        if isinstance(obj, RawFrame):
            if obj.kind == "raw_dn":
                from ..raw import normalize

                obj = normalize(obj)
            if obj.kind != "raw":
                raise DatasetError(f"{name}: kind: {obj.kind!r}, expected a raw mosaic")
            st = FrameSettings(tuple(obj.data.shape), obj.meta.cfa, obj.meta.iso, obj.meta.exposure_time_s)
            data = obj.data
        else:
            data = np.asarray(obj)
            if data.ndim != 2:
                raise DatasetError(f"{name}: shape: {data.shape}, expected an H x W mosaic")
            st = FrameSettings(tuple(data.shape), self.cfa)
        if self.settings is None:
            self.settings = st
            self.cfa = st.cfa
        self.settings.check(st, name, self.names[0])
        data = np.asarray(data, dtype=np.float32)
        if self.settings.cfa is not None and (data.shape[0] < 4 or data.shape[1] < 4):
            raise DatasetError(f"{name}: shape: {data.shape}, expected at least 4x4 pixels")
        bad = ~np.isfinite(data)
        if bad.any():
            n_inf = int(np.isinf(data).sum())
            if self.nan_policy == "raise" or n_inf:
                y, x = np.argwhere(bad)[0]
                raise DatasetError(f"{name}: data: {int(bad.sum())} non-finite samples (first at row {y}, col {x}); "
                                   "expected finite normalised raw (use nan_policy='omit' to treat NaN as missing)")
        return data


def _read_native(path: Path) -> np.ndarray:
    """An image's samples in their stored type (DN), via OpenImageIO."""
    from ..io.images import decode_image

    return np.asarray(decode_image(path, error=DatasetError)[0])
