"""SIDD-format block files: v5 / v7.3 round trips, MATLAB's transposed HDF5 layout, folders of pairs."""

import h5py
import numpy as np
import pytest
import scipy.io

from simcam.errors import DatasetError
from simcam.io.sidd_blocks import list_variables, read_blocks, read_pair_folder, write_blocks


@pytest.mark.parametrize("fmt", ["v5", "v7.3"])
@pytest.mark.parametrize("shape,dtype", [((3, 2, 8, 6), np.float32), ((2, 3, 6, 4, 3), np.uint8)])
def test_round_trip(tmp_path, fmt, shape, dtype):
    rng = np.random.default_rng(0)
    a = (rng.random(shape) * 255).astype(dtype)
    p = write_blocks(tmp_path / "b.mat", a, "BenchmarkNoisyBlocksRaw", format=fmt)
    b = read_blocks(p)
    assert b.dtype == a.dtype and b.shape == a.shape
    np.testing.assert_array_equal(a, b)
    assert list_variables(p) == {"BenchmarkNoisyBlocksRaw": shape}


def test_v73_layout_is_matlab_column_major(tmp_path):
    # MATLAB stores A(n, m, h, w) at HDF5 index [w, h, m, n]; check against h5py directly.
    a = np.arange(2 * 3 * 4 * 5, dtype=np.float32).reshape(2, 3, 4, 5)
    p = write_blocks(tmp_path / "b.mat", a, "X", format="v7.3")
    with h5py.File(p, "r") as f:
        raw = f["X"][()]
        assert f["X"].attrs["MATLAB_class"] == b"single"
    assert raw.shape == (5, 4, 3, 2)
    assert raw[4, 3, 2, 1] == a[1, 2, 3, 4]
    assert open(p, "rb").read(19) == b"MATLAB 7.3 MAT-file"
    # scipy refuses v7.3 files, as it does MATLAB's own
    with pytest.raises(NotImplementedError):
        scipy.io.loadmat(p)


def test_reads_v5_written_by_scipy_with_other_keys(tmp_path):
    a = np.ones((1, 2, 4, 4), np.float32)
    scipy.io.savemat(tmp_path / "m.mat", {"ValidationGtBlocksRaw": a, "note": np.array([1.0])})
    np.testing.assert_array_equal(read_blocks(tmp_path / "m.mat"), a)
    with pytest.raises(DatasetError, match="variable 'nope' not found"):
        read_blocks(tmp_path / "m.mat", key="nope")


def test_bad_inputs(tmp_path):
    with pytest.raises(DatasetError, match="no such file"):
        read_blocks(tmp_path / "missing.mat")
    (tmp_path / "junk.mat").write_bytes(b"not a mat file at all" * 10)
    with pytest.raises(DatasetError, match="junk.mat"):
        read_blocks(tmp_path / "junk.mat")
    with pytest.raises(DatasetError, match="block array"):
        write_blocks(tmp_path / "x.mat", np.zeros((4, 4)), "X")


def test_pair_folder(tmp_path):
    rng = np.random.default_rng(1)
    gt = rng.random((8, 6)).astype(np.float32)
    np.save(tmp_path / "0001_NOISY_RAW.npy", gt + 0.1)
    np.save(tmp_path / "0001_GT_RAW.npy", gt)
    pairs = read_pair_folder(tmp_path)
    assert [p.name for p in pairs] == ["0001"]
    np.testing.assert_array_equal(pairs[0].gt[0], gt)
    assert pairs[0].noisy.shape == (1, 8, 6)
    np.save(tmp_path / "0002_NOISY_RAW.npy", gt)
    with pytest.raises(DatasetError, match="0002_GT_RAW.npy"):
        read_pair_folder(tmp_path)
