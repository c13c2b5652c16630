"""Row bands on threads (simcam.parallel): the demosaicers give the same bytes for any thread
count, and the banded Menon 2007 equals colour-demosaicing's on a multi-band mosaic."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from simcam.demosaic import demosaic_bilinear, demosaic_malvar2004, demosaic_menon2007
from simcam.demosaic.menon2007 import BAND, HALO


@pytest.mark.parametrize("fn", [demosaic_bilinear, demosaic_malvar2004, demosaic_menon2007])
def test_demosaic_same_bytes_for_any_thread_count(fn, monkeypatch):
    m = np.random.default_rng(0).random((2 * BAND + 2 * HALO + 7, 91)).astype(np.float32)
    outs = []
    for t in ("1", "2", "3"):
        monkeypatch.setenv("SIMCAM_THREADS", t)
        outs.append(fn(m, "GRBG").tobytes())
    assert outs[1] == outs[0] and outs[2] == outs[0]


@pytest.mark.parametrize("cfa", ["RGGB", "BGGR"])
def test_banded_menon2007_equals_colour_demosaicing(cfa):
    cd = pytest.importorskip("colour_demosaicing")
    m = np.random.default_rng(1).random((3 * BAND + 11, 64)).astype(np.float32)
    ours = demosaic_menon2007(m, cfa)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = cd.demosaicing_CFA_Bayer_Menon2007(m.astype(np.float64), cfa)
    np.testing.assert_allclose(ours, ref, rtol=1e-6, atol=1e-6)


def test_banded_menon2007_propagates_nan_and_inf_as_colour_demosaicing():
    """The compiled kernel takes the same branch as colour-demosaicing where a neighbour is NaN or
    infinite (a comparison with NaN is false: the vertical estimate), so the same pixels come out
    non-finite and the others agree."""
    cd = pytest.importorskip("colour_demosaicing")
    rng = np.random.default_rng(3)
    m = rng.random((2 * BAND + 2 * HALO + 5, 70)).astype(np.float32)
    m[rng.random(m.shape) < 0.004] = np.nan
    m[rng.random(m.shape) < 0.002] = np.inf
    ours = demosaic_menon2007(m, "GBRG")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = cd.demosaicing_CFA_Bayer_Menon2007(m.astype(np.float64), "GBRG")
    np.testing.assert_array_equal(np.isnan(ours), np.isnan(ref))
    np.testing.assert_array_equal(np.isinf(ours), np.isinf(ref))
    fin = np.isfinite(ref)
    assert fin.mean() > 0.5
    np.testing.assert_allclose(ours[fin], ref[fin], rtol=1e-6, atol=1e-6)
