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
