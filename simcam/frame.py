"""The frame model: pixel data plus camera metadata, the one object stages pass along.

``RawFrame.data`` is float32. Its meaning is given by ``RawFrame.kind``:

========== =========================================================================
kind       meaning
========== =========================================================================
raw_dn     H x W CFA mosaic in sensor digital numbers, as stored in the file
raw        H x W mosaic, *normalised raw*: (DN - black) / (white - black), per CFA
           site; negatives kept (dark-noise statistics need them)
camera_rgb H x W x 3 demosaicked camera RGB (white-balanced or not, see meta)
xyz        H x W x 3 CIE XYZ, D50 connection space (DNG convention), Y=1 is white
linear_srgb H x W x 3 scene-linear sRGB primaries, D65 white
display    H x W x 3 display-referred sRGB (tone-mapped and/or gamma-encoded)
========== =========================================================================
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .cfa import check_pattern

SIGNAL_KINDS = ("raw_dn", "raw", "camera_rgb", "xyz", "linear_srgb", "display")
MOSAIC_KINDS = frozenset({"raw_dn", "raw"})
RGB_KINDS = frozenset({"camera_rgb", "xyz", "linear_srgb", "display"})

#: CameraMeta's colour matrices and the DNG tags that hold them (DNG specification 1.7, chapter 6)
COLOUR_MATRIX_TAGS = {
    "color_matrix1": "ColorMatrix1", "color_matrix2": "ColorMatrix2",
    "camera_calibration1": "CameraCalibration1", "camera_calibration2": "CameraCalibration2",
    "forward_matrix1": "ForwardMatrix1", "forward_matrix2": "ForwardMatrix2",
}

#: DNG opcode ids -> names (DNG 1.6 specification, chapter 7).
OPCODE_NAMES = {
    1: "WarpRectilinear",
    2: "WarpFisheye",
    3: "FixVignetteRadial",
    4: "FixBadPixelsConstant",
    5: "FixBadPixelsList",
    6: "TrimBounds",
    7: "MapTable",
    8: "MapPolynomial",
    9: "GainMap",
    10: "DeltaPerRow",
    11: "DeltaPerColumn",
    12: "ScalePerRow",
    13: "ScalePerColumn",
    14: "WarpRectilinear2",
}


@dataclass(frozen=True)
class AreaSpec:
    """Which pixels an opcode touches (DNG specification 1.7, sec. 7, "area spec"): the first
    parameters of GainMap and of the opcodes in :mod:`simcam.io.opcode_params`."""

    top: int
    left: int
    bottom: int
    right: int
    plane: int
    planes: int
    row_pitch: int
    col_pitch: int

    def slices(self, shape: tuple[int, int]) -> tuple[slice, slice]:
        """Row and column slices of an (H, W) image (an empty rectangle: the whole image)."""
        h, w = shape
        if self.bottom <= self.top or self.right <= self.left:
            t, l, b, r = 0, 0, h, w
        else:
            t, l, b, r = max(self.top, 0), max(self.left, 0), min(self.bottom, h), min(self.right, w)
        # keep the pitch phase of the rectangle's own origin
        t += (-(t - self.top)) % self.row_pitch if self.bottom > self.top else 0
        l += (-(l - self.left)) % self.col_pitch if self.right > self.left else 0
        return slice(t, max(t, b), self.row_pitch), slice(l, max(l, r), self.col_pitch)

    def plane_range(self, n_planes: int) -> range:
        return range(self.plane, min(self.plane + self.planes, n_planes))


@dataclass(frozen=True)
class GainMap(AreaSpec):
    """A decoded DNG GainMap opcode (DNG 1.6 spec, opcode 9).

    Coordinates are in pixels of the image the opcode list applies to (for
    OpcodeList2: the active area, origin at its top-left corner). ``gains`` has
    shape (map_points_v, map_points_h, map_planes), float32, dimensionless gain.
    The map sample (i, j) sits at image position
    (origin_v + i*spacing_v, origin_h + j*spacing_h) in *relative* units of the
    whole image the list applies to (0 its top/left edge, 1 its bottom/right
    edge; pixel (y, x) has its centre at ((y + 0.5) / H, (x + 0.5) / W)), as
    the DNG SDK's ``dng_gain_map_interpolator`` computes it; (top, left,
    bottom, right) with the pitches only selects the pixels the map touches.
    """

    map_spacing_v: float
    map_spacing_h: float
    map_origin_v: float
    map_origin_h: float
    gains: np.ndarray

    @property
    def map_points(self) -> tuple[int, int]:
        return int(self.gains.shape[0]), int(self.gains.shape[1])

    def summary(self) -> dict[str, Any]:
        return {
            "rect": [self.top, self.left, self.bottom, self.right],
            "plane": self.plane,
            "planes": self.planes,
            "pitch": [self.row_pitch, self.col_pitch],
            "map_points": list(self.map_points) + [int(self.gains.shape[2])],
            "spacing": [self.map_spacing_v, self.map_spacing_h],
            "origin": [self.map_origin_v, self.map_origin_h],
            "gain_min": float(self.gains.min()),
            "gain_max": float(self.gains.max()),
        }


@dataclass
class Opcode:
    """One DNG opcode: id, version, flags and its raw parameter bytes.

    ``parsed`` holds the decoded form for opcodes simcam understands
    (currently :class:`GainMap`); others are kept as bytes so they round-trip.
    """

    id: int
    version: tuple[int, int, int, int]
    flags: int
    payload: bytes
    parsed: Any = None

    @property
    def name(self) -> str:
        return OPCODE_NAMES.get(self.id, f"Unknown{self.id}")

    @property
    def optional(self) -> bool:
        return bool(self.flags & 1)


@dataclass
class CameraMeta:
    """Camera metadata of a raw capture (DNG tag semantics; units in names).

    Matrices are float64 numpy arrays. ``color_matrix*`` map XYZ -> camera
    (3x3), ``forward_matrix*`` white-balanced camera -> XYZ D50,
    ``camera_calibration*`` are the per-unit 3x3 calibrations.
    ``black_level`` has shape ``black_level_repeat_dim`` (rows, cols) and is in DN;
    ``black_level_delta_v`` (per row, length H) / ``black_level_delta_h`` (per
    column, length W) are added to it. ``noise_profile`` has shape (n, 2): (S, O)
    pairs of ``var = S * x + O`` on normalised raw (one pair, or one per CFA
    plane). ``origin`` is the (row, col) position of ``data[0, 0]`` in the full
    stored raw image; crops update it.

    Parameters
    ----------
    make, model, unique_camera_model : str
        Make, Model and UniqueCameraModel tags.
    cfa : str or None
        2x2 Bayer pattern of pixel (0, 0) (``"RGGB"``...); None for a mosaic of unknown layout.
    black_level, white_level : ndarray, float
        BlackLevel (DN, ``black_level_repeat_dim``) and WhiteLevel (DN).
    **fields
        Every other tag, by its field name (see the class body); all have defaults.

    Attributes
    ----------
    fields
        As the parameters; :meth:`to_dict` gives them JSON-friendly, :meth:`replace` a changed copy.

    Examples
    --------
    >>> import numpy as np
    >>> from simcam import CameraMeta
    >>> meta = CameraMeta(cfa="BGGR", black_level=np.full((1, 1), 64.0), white_level=1023.0)
    >>> meta.cfa, meta.white_level, meta.replace(iso=800.0).iso
    ('BGGR', 1023.0, 800.0)
    """

    make: str = ""
    model: str = ""
    unique_camera_model: str = ""
    cfa: str | None = "RGGB"
    black_level: np.ndarray = field(default_factory=lambda: np.zeros((1, 1)))
    black_level_delta_h: np.ndarray | None = None
    black_level_delta_v: np.ndarray | None = None
    white_level: float = 1.0
    linearization_table: np.ndarray | None = None
    as_shot_neutral: np.ndarray | None = None
    as_shot_white_xy: np.ndarray | None = None
    color_matrix1: np.ndarray | None = None
    color_matrix2: np.ndarray | None = None
    camera_calibration1: np.ndarray | None = None
    camera_calibration2: np.ndarray | None = None
    forward_matrix1: np.ndarray | None = None
    forward_matrix2: np.ndarray | None = None
    analog_balance: np.ndarray | None = None
    calibration_illuminant1: int | None = None
    calibration_illuminant2: int | None = None
    baseline_exposure: float = 0.0
    noise_profile: np.ndarray | None = None
    iso: float | None = None
    exposure_time_s: float | None = None
    orientation: int = 1
    active_area: tuple[int, int, int, int] | None = None  # top, left, bottom, right
    default_crop_origin: tuple[float, float] | None = None  # (x, y) = (col, row) in active area
    default_crop_size: tuple[float, float] | None = None  # (width, height)
    opcode_list1: list[Opcode] = field(default_factory=list)
    opcode_list2: list[Opcode] = field(default_factory=list)
    opcode_list3: list[Opcode] = field(default_factory=list)
    origin: tuple[int, int] = (0, 0)
    white_balance_gains: np.ndarray | None = None  # gains (R, G, B) already applied to the data
    camera_id: str | None = None
    source: str = ""  # file the metadata came from (for error messages)
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.cfa is not None:
            self.cfa = check_pattern(self.cfa, where=f"{self.source or 'meta'}: cfa")

    # -- convenience -----------------------------------------------------
    def gain_maps(self, list_index: int = 2) -> list[GainMap]:
        """The decoded GainMaps of OpcodeList1, 2 or 3 (in order)."""
        ops = getattr(self, f"opcode_list{list_index}")
        return [op.parsed for op in ops if isinstance(op.parsed, GainMap)]

    def copy(self) -> "CameraMeta":
        """An independent copy, except that the opcodes are shared.

        Opcodes (and their decoded GainMaps, whose gains are read-only) are never modified in
        place, so every stage's copy shares them: a file with tens of thousands of GainMaps costs
        no more per stage than one without. The lists themselves are new.
        """
        lists = {f"opcode_list{k}": getattr(self, f"opcode_list{k}") for k in (1, 2, 3)}
        memo = {id(ops): list(ops) for ops in lists.values()}
        return copy.deepcopy(self, memo)

    def replace(self, **changes: Any) -> "CameraMeta":
        new = self.copy()
        for k, v in changes.items():
            if not hasattr(new, k):
                raise AttributeError(f"CameraMeta has no field {k!r}")
            setattr(new, k, v)
        return new

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly dict (arrays as lists, opcodes by name, GainMaps summarised)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.name.startswith("opcode_list"):
                out[f.name] = [
                    {"name": op.name, "id": op.id, "flags": op.flags, "bytes": len(op.payload),
                     **({"gain_map": op.parsed.summary()} if isinstance(op.parsed, GainMap) else {})}
                    for op in v
                ]
            else:
                out[f.name] = _jsonable(v)
        return out

    def equals(self, other: "CameraMeta", *, ignore: tuple[str, ...] = ("source", "extra")) -> bool:
        """Field-by-field equality (arrays compared exactly)."""
        return not self.differences(other, ignore=ignore)

    def differences(self, other: "CameraMeta", *, ignore: tuple[str, ...] = ("source", "extra")) -> list[str]:
        """Names of fields that differ (arrays compared exactly, opcodes by bytes)."""
        diff = []
        for f in dataclasses.fields(self):
            if f.name in ignore:
                continue
            a, b = getattr(self, f.name), getattr(other, f.name)
            if f.name.startswith("opcode_list"):
                same = len(a) == len(b) and all(
                    (x.id, tuple(x.version), x.flags, bytes(x.payload)) == (y.id, tuple(y.version), y.flags, bytes(y.payload))
                    for x, y in zip(a, b)
                )
            elif a is None or b is None:
                same = a is None and b is None
            elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
                same = np.shape(a) == np.shape(b) and np.array_equal(np.asarray(a), np.asarray(b))
            else:
                same = _jsonable(a) == _jsonable(b)
            if not same:
                diff.append(f.name)
        return diff


def _jsonable(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    if isinstance(v, tuple):
        return [_jsonable(x) for x in v]
    if isinstance(v, list):
        return [_jsonable(x) for x in v]
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, bytes):
        return f"<{len(v)} bytes>"
    return v


@dataclass
class RawFrame:
    """Pixel data + camera metadata + signal kind.

    Parameters
    ----------
    data : ndarray
        float32, H x W for mosaic kinds, H x W x 3 for RGB kinds.
    meta : CameraMeta
        Metadata; stages that change geometry or colour state update a copy.
    kind : str
        One of :data:`SIGNAL_KINDS`.

    Attributes
    ----------
    data, meta, kind
        As the parameters (``data`` converted to float32 and checked against ``kind``).
    history : list of str
        The stages the frame went through.

    Examples
    --------
    >>> import numpy as np
    >>> from simcam import CameraMeta, RawFrame
    >>> frame = RawFrame(np.zeros((4, 6)), CameraMeta(cfa="RGGB"), kind="raw")
    >>> frame.data.dtype.name, frame.height, frame.width
    ('float32', 4, 6)
    """

    data: np.ndarray
    meta: CameraMeta
    kind: str = "raw"
    history: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        from .errors import StageError

        if self.kind not in SIGNAL_KINDS:
            raise StageError(f"RawFrame.kind: expected one of {SIGNAL_KINDS}, got {self.kind!r}")
        self.data = np.asarray(self.data)
        if self.data.dtype != np.float32:
            self.data = self.data.astype(np.float32)
        want_ndim = 2 if self.kind in MOSAIC_KINDS else 3
        if self.data.ndim != want_ndim or (want_ndim == 3 and self.data.shape[2] != 3):
            shape = "H x W" if want_ndim == 2 else "H x W x 3"
            raise StageError(
                f"RawFrame.data: kind {self.kind!r} needs an {shape} array, got shape {self.data.shape}"
            )

    @property
    def height(self) -> int:
        return int(self.data.shape[0])

    @property
    def width(self) -> int:
        return int(self.data.shape[1])

    @property
    def cfa(self) -> str | None:
        return self.meta.cfa

    def evolve(self, data: np.ndarray | None = None, *, kind: str | None = None,
               meta: CameraMeta | None = None, step: str | None = None) -> "RawFrame":
        """A new frame sharing what is not replaced (metadata is never mutated in place)."""
        return RawFrame(
            data=self.data if data is None else data,
            meta=self.meta if meta is None else meta,
            kind=self.kind if kind is None else kind,
            history=self.history + ([step] if step else []),
        )
