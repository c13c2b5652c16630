"""The loop's analysed region (whole frame / tile mosaic / centre crop) and the streamed whole-frame
statistics of the reader, against direct numpy computations on the same frames."""

import numpy as np
import pytest

from simcam.calibration.capture import FrameAccumulator
from simcam.calibration.region import Region


@pytest.mark.parametrize("h,w", [(3000, 4000), (512, 2048), (1537, 2051), (300, 400)])
def test_mosaic_tiles_inside_even_disjoint_and_within_budget(h, w):
    reg = Region(max_pixels=512 * 512, tile=128)
    ys, xs, th, tw = reg.plan(h, w)
    assert len(ys) * len(xs) * th * tw <= max(reg.max_pixels, th * tw)
    for o, t, size in ((ys, th, h), (xs, tw, w)):
        assert all(v % 2 == 0 for v in o) and o[0] >= 0 and o[-1] + t <= size
        assert all(b - a >= t for a, b in zip(o, o[1:]))
    if h * w > reg.max_pixels:  # the grid spans the frame
        assert ys[-1] + th > h - 2 * th and xs[-1] + tw > w - 2 * tw


def test_mosaic_is_the_frames_tiles():
    rng = np.random.default_rng(0)
    f = rng.integers(0, 1000, (3, 700, 900)).astype(np.float32)
    reg = Region(max_pixels=256 * 256, tile=64)
    ys, xs, th, tw = reg.plan(700, 900)
    m = reg.extract(f)
    assert m.shape == (3, len(ys) * th, len(xs) * tw)
    for i, y in enumerate(ys):
        for j, x in enumerate(xs):
            np.testing.assert_array_equal(m[:, i * th:(i + 1) * th, j * tw:(j + 1) * tw], f[:, y:y + th, x:x + tw])


def test_small_frames_are_whole_and_max_size_is_a_centre_crop():
    f = np.zeros((2, 64, 96), np.float32)
    assert Region().extract(f).shape == (2, 64, 96)
    assert Region().describe(64, 96)["layout"] == "whole frame"
    assert Region(max_size=32).extract(f).shape == (2, 32, 32)
    assert Region(max_size=32).plan(64, 96)[:2] == ([16], [32])


def test_streamed_statistics_equal_direct_ones():
    rng = np.random.default_rng(1)
    frames = (100 + 5 * rng.standard_normal((7, 40, 50))).astype(np.float32)
    acc = FrameAccumulator(keep_mean_map=True)
    for f in frames:
        acc.add(f, 4095.0)
    st = acc.result()
    x = frames.astype(np.float64)
    for k, (dy, dx) in enumerate(((0, 0), (0, 1), (1, 0), (1, 1))):
        p = x[:, dy::2, dx::2]
        d = p[0] - p[1]
        assert st.pair_mean[k] == pytest.approx(p[:2].mean(), rel=1e-12)
        assert st.pair_var[k] == pytest.approx(np.mean((d - d.mean()) ** 2) / 2, rel=1e-10)
        assert st.avg_var[k] == pytest.approx(np.var(p.mean(0), ddof=1), rel=1e-9)
        assert st.temporal_var[k] == pytest.approx(np.mean(np.var(p, axis=0, ddof=1)), rel=1e-9)
    d = x[0] - x[1]
    assert st.pair_var[4] == pytest.approx(np.mean((d - d.mean()) ** 2) / 2, rel=1e-10)
    np.testing.assert_allclose(st.mean_map, x.mean(0), rtol=1e-6)
    np.testing.assert_allclose(st.frame_means, x.mean(axis=(1, 2)), rtol=1e-12)
