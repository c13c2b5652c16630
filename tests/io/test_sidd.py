"""SIDD side files: metadata .MAT -> CameraMeta, defective-pixel mask."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
import scipy.io

from shared_data import shared_path
from simcam.cli import main
from simcam.errors import DatasetError, MetadataError
from simcam.io.opcodes import parse_opcode_list, serialise_opcode_list
from simcam.io.sidd import load_defect_mask, read_sidd_meta

META = "sidd/0001_METADATA_RAW_010.MAT"
MASK = "sidd/DefectivePixelsMask_GP_4048x3044.mat"


def _raw_struct(path):
    """The MATLAB struct read with scipy defaults (independent of simcam)."""
    md = scipy.io.loadmat(str(path))["metadata"][0, 0]
    unknown = {int(row[0]["ID"].ravel()[0]): row[0]["Value"].ravel() for row in md["UnknownTags"]}
    return md, unknown


@pytest.mark.shared_data
def test_sidd_metadata():
    path = shared_path(META)
    meta = read_sidd_meta(path)
    md, unknown = _raw_struct(path)
    assert meta.cfa == "GRBG"
    assert meta.black_level.tolist() == [[0.0, 0.0], [0.0, 0.0]] and meta.white_level == 1023.0
    np.testing.assert_array_equal(meta.color_matrix1, md["ColorMatrix1"].reshape(3, 3))
    np.testing.assert_array_equal(meta.color_matrix2, md["ColorMatrix2"].reshape(3, 3))
    np.testing.assert_array_equal(meta.forward_matrix1, unknown[50964].reshape(3, 3))
    np.testing.assert_array_equal(meta.forward_matrix2, unknown[50965].reshape(3, 3))
    np.testing.assert_array_equal(meta.as_shot_neutral, md["AsShotNeutral"].ravel())
    np.testing.assert_array_equal(meta.noise_profile, unknown[51041].reshape(3, 2))
    assert (meta.calibration_illuminant1, meta.calibration_illuminant2) == (21, 17)
    assert meta.iso == 100.0 and meta.orientation == 3
    assert meta.active_area == (0, 0, 3000, 5328) and meta.extra["image_size"] == [3000, 5328]
    assert meta.default_crop_origin == (8.0, 8.0) and meta.default_crop_size == (5312.0, 2984.0)
    assert meta.make == "samsung" and meta.model == "SM-G925I"
    maps = meta.gain_maps(2)
    assert len(maps) == 4 and all(gm.map_points == (1, 1) for gm in maps)
    assert {(gm.top, gm.left) for gm in maps} == {(0, 0), (0, 1), (1, 0), (1, 1)}
    assert meta.opcode_list3 == []
    raw_list = unknown[51009].astype(np.uint8).tobytes()
    assert serialise_opcode_list(parse_opcode_list(raw_list)) == raw_list


@pytest.mark.shared_data
def test_defect_mask():
    mask = load_defect_mask(shared_path(MASK))
    # MATLAB (row, col): 3044 rows x 4048 columns, the Pixel's 4048 x 3044 sensor in landscape
    assert mask.shape == (3044, 4048) and mask.dtype == bool
    assert int(mask.sum()) == 59358


def _write_v73_mask(path, mask):
    """A MATLAB v7.3 (HDF5) file as MATLAB writes it: column-major, so stored transposed."""
    with h5py.File(path, "w", userblock_size=512) as f:
        ds = f.create_dataset("DefectivePixelsMask", data=mask.T.astype(np.uint8))
        ds.attrs["MATLAB_class"] = np.bytes_("logical")
    with open(path, "r+b") as f:
        f.write(b"MATLAB 7.3 MAT-file".ljust(116) + b"\0" * 8 + b"\x00\x02IM")


def test_v73_mask_orientation(tmp_path):
    mask = np.zeros((6, 10), bool)
    mask[1, 7] = mask[5, 0] = True
    path = tmp_path / "m73.mat"
    _write_v73_mask(path, mask)
    got = load_defect_mask(path)
    np.testing.assert_array_equal(got, mask)


def test_v5_mask_and_errors(tmp_path):
    mask = np.zeros((4, 6), np.uint8)
    mask[2, 5] = 1
    scipy.io.savemat(tmp_path / "m.mat", {"M": mask})
    np.testing.assert_array_equal(load_defect_mask(tmp_path / "m.mat"), mask.astype(bool))
    with pytest.raises(DatasetError, match="no such file"):
        load_defect_mask(tmp_path / "missing.mat")
    (tmp_path / "bad.mat").write_text("not a mat file")
    with pytest.raises(DatasetError, match="bad.mat"):
        load_defect_mask(tmp_path / "bad.mat")
    with pytest.raises(MetadataError, match="struct"):
        read_sidd_meta(tmp_path / "m.mat")
    with pytest.raises(MetadataError, match="is a directory"):
        read_sidd_meta(tmp_path)


@pytest.mark.shared_data
def test_info_reads_sidd_mat(capsys):
    assert main(["info", str(shared_path(META)), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["cfa"] == "GRBG" and d["white_level"] == 1023.0
    assert [op["name"] for op in d["opcode_list2"]] == ["GainMap"] * 4
    assert d["opcode_list2"][0]["gain_map"]["map_points"] == [1, 1, 1]


def test_v73_metadata_struct(tmp_path):
    """A v7.3 struct with char fields and an UnknownTags struct array (object references)."""
    path = tmp_path / "meta73.mat"
    with h5py.File(path, "w", userblock_size=512) as f:
        g = f.create_group("metadata")
        g.attrs["MATLAB_class"] = np.bytes_("struct")

        def put(group, name, value, cls="double"):
            arr = np.asarray(value)
            ds = group.create_dataset(name, data=arr.T if arr.ndim else arr)
            ds.attrs["MATLAB_class"] = np.bytes_(cls)
            return ds

        put(g, "Make", np.array([[ord(c) for c in "samsung"]], np.uint16), "char")
        put(g, "WhiteLevel", np.array([[1023.0]]))
        put(g, "Width", np.array([[64.0]]))
        put(g, "Height", np.array([[48.0]]))
        put(g, "BlackLevelRepeatDim", np.array([[2.0, 2.0]]))
        put(g, "BlackLevel", np.array([[1.0, 2.0, 3.0, 4.0]]))
        put(g, "ColorMatrix1", np.arange(9.0)[None, :] / 8)
        refs = f.create_group("#refs#")
        ids, vals = [], []
        for k, (code, value) in enumerate([(33421, [2, 2]), (33422, [1, 2, 0, 1]), (51041, [1e-4, 2e-6])]):
            ids.append(put(refs, f"i{k}", np.array([[float(code)]])).ref)
            vals.append(put(refs, f"v{k}", np.array([value], dtype=float)).ref)
        u = g.create_group("UnknownTags")
        u.attrs["MATLAB_class"] = np.bytes_("struct")
        u.create_dataset("ID", data=np.array([ids], dtype=h5py.ref_dtype).T)
        u.create_dataset("Value", data=np.array([vals], dtype=h5py.ref_dtype).T)
    with open(path, "r+b") as fh:
        fh.write(b"MATLAB 7.3 MAT-file".ljust(116) + b"\0" * 8 + b"\x00\x02IM")
    meta = read_sidd_meta(path)
    assert meta.make == "samsung" and meta.white_level == 1023.0
    assert meta.cfa == "GBRG"  # CFAPattern [1, 2, 0, 1] with planes R, G, B
    assert meta.black_level.tolist() == [[1.0, 2.0], [3.0, 4.0]]
    np.testing.assert_array_equal(meta.color_matrix1, np.arange(9.0).reshape(3, 3) / 8)
    np.testing.assert_array_equal(meta.noise_profile, [[1e-4, 2e-6]])
    assert meta.extra["image_size"] == [48, 64]
