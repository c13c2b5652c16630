"""SIDD (Smartphone Image Denoising Dataset) side files.

* ``*_METADATA_RAW_*.MAT``: MATLAB ``imfinfo`` struct of the source DNG (tag
  name -> value, rationals already divided; tags MATLAB does not know are in
  ``UnknownTags``, an array of {ID, Offset, Value}). :func:`read_sidd_meta`
  turns it into the same :class:`CameraMeta` :func:`simcam.io.dng.read_dng_meta`
  gives for a DNG.
* ``DefectivePixelsMask_*.mat``: :func:`load_defect_mask`, bool H x W.

Both MATLAB formats are read by :func:`simcam.io.matlab.load_mat`.
Reference: Abdelhamed, Lin, Brown, CVPR 2018, doi:10.1109/CVPR.2018.00182.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..cfa import BAYER_PATTERNS, shift_pattern
from ..errors import DatasetError, MetadataError
from ..frame import CameraMeta
from .dng import PLANE_COLOR_LETTERS, T, black_level_pattern
from .matlab import load_mat
from .opcodes import parse_opcode_list

_TAG_NAMES = {code: name for name, code in T.items()}


# ---------------------------------------------------------------------------
# metadata
# ---------------------------------------------------------------------------
def _tag_dict(md: dict[str, Any]) -> dict[str, Any]:
    """Struct fields plus UnknownTags resolved to DNG tag names."""
    tags = {k: v for k, v in md.items() if k != "UnknownTags"}
    unknown = md.get("UnknownTags")
    if unknown is None:
        return tags
    if isinstance(unknown, dict):  # one entry, or v7.3 struct-of-arrays
        ids, vals = unknown.get("ID"), unknown.get("Value")
        if isinstance(ids, list):
            unknown = [{"ID": i, "Value": v} for i, v in zip(ids, vals)]
        else:
            unknown = [unknown]
    for entry in unknown:
        code = int(np.asarray(entry["ID"]).ravel()[0])
        name = _TAG_NAMES.get(code, f"Tag{code}")
        tags.setdefault(name, entry["Value"])
    return tags


def _arr(v: Any) -> np.ndarray | None:
    if v is None:
        return None
    if isinstance(v, str):
        return None
    a = np.asarray(v, dtype=np.float64).ravel()
    return None if a.size == 0 else a


def read_sidd_meta(path: str | os.PathLike) -> CameraMeta:
    """Read a SIDD ``*_METADATA_RAW_*.MAT`` file into :class:`CameraMeta`.

    Parameters
    ----------
    path : path-like
        The MATLAB file (v5/v7 or v7.3) holding the struct ``metadata``.

    Returns
    -------
    CameraMeta
        Same field conventions as :func:`simcam.io.dng.read_dng_meta`
        (``origin`` (0, 0), ``cfa`` of stored pixel (0, 0)); ``extra`` holds
        the image size and the source DNG file name.
    """
    path = Path(path)
    variables = load_mat(path, MetadataError)
    md = variables.get("metadata")
    if md is None:
        md = next((v for v in variables.values() if isinstance(v, dict)), None)
    if not isinstance(md, dict):
        raise MetadataError(f"{path}: metadata: no MATLAB struct found; expected the SIDD metadata struct")
    tags = _tag_dict(md)
    where = lambda name: f"{path}: {name}"  # noqa: E731

    def matrix(name):
        a = _arr(tags.get(name))
        if a is None:
            return None
        if a.size != 9:
            raise MetadataError(f"{where(name)}: {a.size} values; expected 9 (3x3)")
        return a.reshape(3, 3)

    def vec(name, n):
        a = _arr(tags.get(name))
        if a is not None and a.size != n:
            raise MetadataError(f"{where(name)}: {a.size} values; expected {n}")
        return a

    def scalar(name):
        a = _arr(tags.get(name))
        return None if a is None else float(a[0])

    def text(name):
        v = tags.get(name)
        if isinstance(v, np.ndarray):
            v = "".join(map(str, v.ravel())) if v.dtype.kind in "US" else ""
        return str(v).strip() if v is not None else ""

    h, w = int(scalar("Height") or 0), int(scalar("Width") or 0)
    aa = vec("ActiveArea", 4)
    active_area = tuple(int(x) for x in aa) if aa is not None else None

    # CFA (TIFF/EP CFAPattern indexes CFAPlaneColor; anchored at the active area)
    dim = _arr(tags.get("CFARepeatPatternDim"))
    if dim is not None and tuple(int(x) for x in dim) != (2, 2):
        raise MetadataError(f"{where('CFARepeatPatternDim')}: {dim.tolist()}; expected [2, 2]")
    pat = _arr(tags.get("CFAPattern"))
    if pat is None or pat.size != 4:
        raise MetadataError(f"{where('CFAPattern')}: {None if pat is None else pat.tolist()}; expected 4 values")
    plane = _arr(tags.get("CFAPlaneColor"))
    plane = [0, 1, 2] if plane is None else [int(x) for x in plane]
    try:
        letters = "".join(PLANE_COLOR_LETTERS[plane[int(p)]] for p in pat)
    except IndexError:
        raise MetadataError(f"{where('CFAPattern')}: {pat.tolist()} does not index CFAPlaneColor {plane}") from None
    if letters not in BAYER_PATTERNS:
        raise MetadataError(f"{where('CFAPattern')}: {letters!r}; expected one of {', '.join(BAYER_PATTERNS)}")
    top, left = (active_area[0], active_area[1]) if active_area else (0, 0)
    cfa = shift_pattern(letters, -top, -left)

    rep = _arr(tags.get("BlackLevelRepeatDim"))
    rep = (1, 1) if rep is None else tuple(int(x) for x in rep)
    black = black_level_pattern(_arr(tags.get("BlackLevel")), rep, where=where("BlackLevel"), error=MetadataError)
    white = scalar("WhiteLevel")
    if white is None:
        raise MetadataError(f"{where('WhiteLevel')}: missing; expected the sensor white level")

    noise = _arr(tags.get("NoiseProfile"))
    if noise is not None:
        if noise.size % 2:
            raise MetadataError(f"{where('NoiseProfile')}: {noise.size} values; expected (S, O) pairs")
        noise = noise.reshape(-1, 2)

    lists = {}
    for k in (1, 2, 3):
        v = tags.get(f"OpcodeList{k}")
        if v is None:
            lists[k] = []
        else:
            raw = np.asarray(v).ravel().astype(np.uint8).tobytes()
            lists[k] = parse_opcode_list(raw, where=where(f"OpcodeList{k}"))

    def pair(name):
        a = vec(name, 2)
        return None if a is None else (float(a[0]), float(a[1]))

    def illum(name):
        s = scalar(name)
        return None if s is None else int(s)

    iso = scalar("ISOSpeedRatings")
    exposure = scalar("ExposureTime")
    orientation = scalar("Orientation")
    extra = {"image_size": [h, w], "source_dng": text("Filename"), "format": "SIDD MATLAB metadata"}
    for name in ("FNumber", "FocalLength"):
        s = scalar(name)
        if s is not None:
            extra[name] = s
    return CameraMeta(
        make=text("Make"), model=text("Model"), unique_camera_model=text("UniqueCameraModel"),
        cfa=cfa, black_level=black,
        black_level_delta_h=_arr(tags.get("BlackLevelDeltaH")),
        black_level_delta_v=_arr(tags.get("BlackLevelDeltaV")),
        white_level=float(white),
        linearization_table=_arr(tags.get("LinearizationTable")),
        as_shot_neutral=vec("AsShotNeutral", 3), as_shot_white_xy=vec("AsShotWhiteXY", 2),
        color_matrix1=matrix("ColorMatrix1"), color_matrix2=matrix("ColorMatrix2"),
        camera_calibration1=matrix("CameraCalibration1"), camera_calibration2=matrix("CameraCalibration2"),
        forward_matrix1=matrix("ForwardMatrix1"), forward_matrix2=matrix("ForwardMatrix2"),
        analog_balance=vec("AnalogBalance", 3),
        calibration_illuminant1=illum("CalibrationIlluminant1"),
        calibration_illuminant2=illum("CalibrationIlluminant2"),
        baseline_exposure=scalar("BaselineExposure") or 0.0,
        noise_profile=noise,
        iso=iso if iso and iso > 0 else None,
        exposure_time_s=exposure if exposure and exposure > 0 else None,
        orientation=int(orientation) if orientation is not None else 1,
        active_area=active_area,
        default_crop_origin=pair("DefaultCropOrigin"), default_crop_size=pair("DefaultCropSize"),
        opcode_list1=lists[1], opcode_list2=lists[2], opcode_list3=lists[3],
        origin=(0, 0), source=str(path), extra=extra,
    )


def load_defect_mask(path: str | os.PathLike, *, variable: str | None = None) -> np.ndarray:
    """Load a SIDD defective-pixel mask (``DefectivePixelsMask_*.mat``).

    Parameters
    ----------
    path : path-like
        MATLAB file (v5/v7 or v7.3) with one 2-D logical/uint8 array.
    variable : str, optional
        Variable name; default: the only 2-D array in the file.

    Returns
    -------
    ndarray of bool, H x W
        True at defective pixels, in MATLAB's (row, column) = (y, x) order
        (e.g. 3044 x 4048 for the Pixel's 4048 x 3044 sensor).
    """
    path = Path(path)
    variables = load_mat(path, DatasetError)
    arrays = {k: v for k, v in variables.items() if isinstance(v, np.ndarray) and v.ndim == 2}
    if variable is not None:
        if variable not in arrays:
            raise DatasetError(f"{path}: {variable}: no such 2-D array; found {sorted(arrays)}")
        a = arrays[variable]
    elif len(arrays) == 1:
        a = next(iter(arrays.values()))
    else:
        raise DatasetError(f"{path}: expected one 2-D mask array, found {sorted(arrays) or 'none'}")
    if a.dtype != bool and not np.all(np.isin(a, (0, 1))):
        raise DatasetError(f"{path}: mask values {np.unique(a)[:5].tolist()}...; expected 0/1")
    return a.astype(bool)


def read_sidd_image(path: str | os.PathLike, *, dtype=np.float64, what: str = "RAW") -> np.ndarray:
    """The image of a SIDD ``.MAT`` file (Abdelhamed, Lin & Brown, CVPR 2018): its variable ``x``, else its
    only 2-D array (normalised raw in [0, 1] for the RAW files), as ``dtype``; DatasetError naming the
    file as a SIDD ``what`` .MAT when it holds none."""
    v = load_mat(Path(path), DatasetError)
    x = v.get("x", next((a for a in v.values() if isinstance(a, np.ndarray) and a.ndim == 2), None))
    if x is None or np.ndim(x) != 2:
        raise DatasetError(f"{path}: no 2-D image variable 'x'; expected a SIDD {what} .MAT")
    return np.asarray(x, dtype=dtype)
