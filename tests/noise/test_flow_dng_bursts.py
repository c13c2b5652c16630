"""Noise Flow training data from DNG bursts with a ground truth (clean.dng or gt.npz).

Reference: the pixels read independently with rawpy and normalised with the known
black/white levels of the synthetic capture.
"""

from __future__ import annotations

import numpy as np
import pytest
import rawpy

from shared_data import REPO
from simcam.cli import main
from simcam.errors import DatasetError
from simcam.io.sample_dng import make_test_dng
from simcam.noise.flow.data import load_data, load_dng_bursts

BLACK, WHITE = 64.0, 1023.0


def rawpy_normalised(path):
    with rawpy.imread(str(path)) as raw:
        return (raw.raw_image.astype(np.float64) - BLACK) / (WHITE - BLACK)


@pytest.fixture
def burst(tmp_path):
    clean = make_test_dng(tmp_path / "src.dng", 96, 128, "RGGB", black=BLACK, white=WHITE, iso=400.0)
    out = tmp_path / "burst"
    assert main(["synth", str(clean), "-o", str(out), "--profile", str(REPO / "profiles" / "sidd-gp.yaml"),
                 "--iso", "400", "--frames", "2", "--seed", "3"]) == 0
    return out


def test_dng_burst_patches_match_independent_reading(burst):
    ps = load_dng_bursts(burst, patches_per_image=8, size=16, seed=0)
    assert ps["clean"].shape == (16, 4, 16, 16) and ps["noise"].shape == ps["clean"].shape
    assert np.all(ps["iso"] == 400.0)
    clean = np.clip(rawpy_normalised(burst / "clean.dng"), 0, 1)
    noise0 = np.clip(rawpy_normalised(burst / "frame_000.dng"), 0, 1) - clean
    # locate each patch of frame 0 in the independent reading (even offsets, packed by position)
    for c, n in zip(ps["clean"][:8], ps["noise"][:8]):
        hits = [(y, x) for y in range(0, 96 - 31, 2) for x in range(0, 128 - 31, 2)
                if np.allclose(clean[y:y + 32:2, x:x + 32:2], c[0], atol=1e-6)
                and np.allclose(clean[y + 1:y + 32:2, x + 1:x + 32:2], c[3], atol=1e-6)]
        assert hits, "patch not found in the ground truth"
        y, x = hits[0]
        np.testing.assert_allclose(n[1], noise0[y:y + 32:2, x + 1:x + 32:2], atol=1e-6)
        np.testing.assert_allclose(n[2], noise0[y + 1:y + 32:2, x:x + 32:2], atol=1e-6)
    assert np.std(ps["noise"]) > 0


def test_gt_npz_ground_truth_and_dispatch(burst):
    clean_dng = burst / "clean.dng"
    gt = rawpy_normalised(clean_dng).astype(np.float32)
    clean_dng.unlink()
    np.savez(burst / "gt.npz", gt=gt)
    ps = load_data(burst, patches_per_image=4, size=16)
    assert ps["clean"].shape[0] == 8


def test_burst_without_ground_truth_is_refused(burst):
    (burst / "clean.dng").unlink()
    with pytest.raises(DatasetError, match="no ground truth; expected clean.dng or gt.npz"):
        load_dng_bursts(burst)
