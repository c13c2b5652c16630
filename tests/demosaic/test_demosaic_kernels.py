"""Hand-written bilinear / Malvar2004 kernels against colour-demosaicing and closed forms.

Border convention under test: whole-sample mirror (np.pad mode="reflect"), which keeps
the Bayer phase. colour-demosaicing pads with scipy's mode="reflect" (x[-1] = x[0]),
which swaps colours in the padding, so the two agree (a) in the interior (2 px margin
for Malvar's 5x5 kernels, 1 px for bilinear's 3x3) and (b) everywhere when
colour-demosaicing is given the mosaic already mirror-padded by 2 px and cropped back.
"""

from __future__ import annotations

import numpy as np
import pytest

from simcam.cfa import BAYER_PATTERNS, channel_masks
from simcam.demosaic import (
    DEMOSAIC_METHODS,
    demosaic,
    demosaic_bilinear,
    demosaic_malvar2004,
    demosaic_menon2007,
)
from simcam.errors import StageError

cd = pytest.importorskip("colour_demosaicing")

REFERENCES = {
    "bilinear": (demosaic_bilinear, cd.demosaicing_CFA_Bayer_bilinear, 1),
    "malvar2004": (demosaic_malvar2004, cd.demosaicing_CFA_Bayer_Malvar2004, 2),
}
# float32 kernels vs float64 reference: a handful of float32 roundings of values
# of order 1 (|kernel taps| sum to <= 4.5 for Malvar) -> errors ~1e-6 absolute.
RTOL, ATOL = 1e-5, 2e-6


def mosaic_of(rgb: np.ndarray, cfa: str) -> np.ndarray:
    """Sample an H x W x 3 image through a Bayer CFA."""
    masks = channel_masks(cfa, rgb.shape[:2])
    return sum(rgb[..., i] * masks[c] for i, c in enumerate("RGB")).astype(np.float32)


def random_mosaic(shape, seed=0):
    # negatives and values above 1 included: nothing may be clipped
    return np.random.default_rng(seed).uniform(-0.1, 1.2, shape).astype(np.float32)


def smooth_mosaic(shape, cfa, seed=1):
    h, w = shape
    y, x = np.mgrid[0:h, 0:w] / max(h, w)
    ph = np.random.default_rng(seed).uniform(0, 2 * np.pi, 3)
    rgb = np.stack([0.5 + 0.4 * np.sin(3 * x + 2 * y + p) for p in ph], axis=-1)
    return mosaic_of(rgb, cfa)


@pytest.mark.parametrize("method", sorted(REFERENCES))
@pytest.mark.parametrize("cfa", BAYER_PATTERNS)
@pytest.mark.parametrize("kind", ["random", "smooth"])
def test_interior_matches_colour_demosaicing(method, cfa, kind):
    ours_fn, ref_fn, margin = REFERENCES[method]
    m = random_mosaic((40, 52)) if kind == "random" else smooth_mosaic((40, 52), cfa)
    ours = ours_fn(m, cfa)
    ref = ref_fn(m.astype(np.float64), cfa)
    assert ours.dtype == np.float32 and ours.shape == (40, 52, 3)
    inner = (slice(margin, -margin), slice(margin, -margin))
    np.testing.assert_allclose(ours[inner], ref[inner], rtol=RTOL, atol=ATOL)


@pytest.mark.parametrize("method", sorted(REFERENCES))
@pytest.mark.parametrize("cfa", BAYER_PATTERNS)
@pytest.mark.parametrize("shape", [(24, 30), (23, 30), (24, 31), (17, 9), (3, 5), (2, 2), (71, 40), (64, 33)])
def test_whole_image_matches_colour_on_mirror_padded_mosaic(method, cfa, shape):
    """Borders (and odd sizes): colour-demosaicing on np.pad(mode="reflect") by 2, cropped. The last two
    shapes span several strips (each gathers its own phase-plane rows, mirrored at the top and bottom)."""
    ours_fn, ref_fn, _ = REFERENCES[method]
    m = random_mosaic(shape, seed=shape[0] * 100 + shape[1])
    padded = np.pad(m.astype(np.float64), 2, mode="reflect")  # even pad: same pattern string
    ref = ref_fn(padded, cfa)[2:-2, 2:-2]
    ours = ours_fn(m, cfa)
    assert ours.shape == shape + (3,) and ours.flags.c_contiguous
    np.testing.assert_allclose(ours, ref, rtol=RTOL, atol=ATOL)


@pytest.mark.parametrize("method", sorted(DEMOSAIC_METHODS))
@pytest.mark.parametrize("cfa", BAYER_PATTERNS)
def test_known_samples_are_kept(method, cfa):
    m = random_mosaic((16, 20), seed=3)
    rgb = demosaic(m, cfa, method)
    masks = channel_masks(cfa, m.shape)
    for i, c in enumerate("RGB"):
        np.testing.assert_array_equal(rgb[..., i][masks[c]], m[masks[c]])


@pytest.mark.parametrize("method", sorted(REFERENCES))
@pytest.mark.parametrize("cfa", BAYER_PATTERNS)
def test_constant_colour_is_exact_everywhere(method, cfa):
    """A flat colour field is reproduced at every pixel, border included (phase-preserving
    mirror). colour-demosaicing's Malvar does not at the border: it mixes colours there."""
    colour = np.array([0.8, 0.45, 0.2], dtype=np.float32)
    m = mosaic_of(np.broadcast_to(colour, (10, 14, 3)), cfa)
    ours = REFERENCES[method][0](m, cfa)
    np.testing.assert_allclose(ours, np.broadcast_to(colour, ours.shape), rtol=0, atol=1e-6)
    if method == "malvar2004":
        ref = cd.demosaicing_CFA_Bayer_Malvar2004(m.astype(np.float64), cfa)
        assert np.abs(ref[0] - colour).max() > 1e-2  # documents why we differ at the border


@pytest.mark.parametrize("method", sorted(REFERENCES))
@pytest.mark.parametrize("cfa", ["RGGB", "GBRG"])
def test_linear_ramps_reproduced_in_interior(method, cfa):
    """Closed form: both methods are exact on per-channel affine images (the Laplacian
    correction of Malvar vanishes on them; bilinear means of symmetric pairs are exact)."""
    y, x = np.mgrid[0:20, 0:26].astype(np.float64)
    truth = np.stack([0.1 + 0.01 * x + 0.02 * y, 0.3 - 0.005 * x + 0.01 * y, 0.2 + 0.015 * x - 0.007 * y], -1)
    ours = REFERENCES[method][0](mosaic_of(truth, cfa), cfa)
    np.testing.assert_allclose(ours[2:-2, 2:-2], truth[2:-2, 2:-2], rtol=0, atol=2e-6)


def test_quality_ordering_on_natural_image():
    """Malvar 2004 beats bilinear by several dB (the paper reports ~5.5 dB on Kodak),
    Menon 2007 beats Malvar: a check that each method is the one it claims to be."""
    data = pytest.importorskip("skimage.data")
    img = data.astronaut()[:128, 192:320].astype(np.float32) / 255.0
    psnr = {}
    for method in DEMOSAIC_METHODS:
        out = demosaic(mosaic_of(img, "GRBG"), "GRBG", method)
        mse = float(np.mean((out - img)[4:-4, 4:-4] ** 2))
        psnr[method] = 10 * np.log10(1.0 / mse)
    assert psnr["malvar2004"] > psnr["bilinear"] + 3.0, psnr
    assert psnr["menon2007"] > psnr["malvar2004"] + 1.0, psnr


@pytest.mark.parametrize("cfa", BAYER_PATTERNS)
def test_menon2007_wraps_colour_demosaicing(cfa):
    m = smooth_mosaic((20, 24), cfa)
    ours = demosaic_menon2007(m, cfa)
    ref = cd.demosaicing_CFA_Bayer_Menon2007(m.astype(np.float64), cfa)
    assert ours.dtype == np.float32 and ours.shape == (20, 24, 3)
    np.testing.assert_allclose(ours, ref, rtol=1e-6, atol=1e-7)


def test_float64_input_gives_float32_and_input_untouched():
    m = random_mosaic((8, 8)).astype(np.float64)
    before = m.copy()
    out = demosaic_malvar2004(m, "rggb")
    assert out.dtype == np.float32
    np.testing.assert_array_equal(m, before)


@pytest.mark.parametrize("method", sorted(DEMOSAIC_METHODS))
@pytest.mark.parametrize(
    "arr, cfa, match",
    [
        (np.zeros((4, 4, 3), np.float32), "RGGB", r"2-D H x W array, got shape \(4, 4, 3\)"),
        (np.zeros((1, 8), np.float32), "RGGB", r"at least 2 x 2 pixels, got shape \(1, 8\)"),
        (np.zeros((4, 4), np.float32), "RGBG", r"cfa: expected one of RGGB, BGGR, GRBG, GBRG, got 'RGBG'"),
        (np.array([["a", "b"], ["c", "d"]]), "RGGB", r"real numbers, got dtype <U1"),
    ],
)
def test_bad_input_is_one_clear_error(method, arr, cfa, match):
    with pytest.raises(StageError, match=match):
        demosaic(arr, cfa, method)


def test_unknown_method():
    with pytest.raises(StageError, match=r"method: expected one of .*got 'ahd'"):
        demosaic(np.zeros((4, 4)), "RGGB", "ahd")
