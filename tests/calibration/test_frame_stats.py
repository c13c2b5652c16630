"""The independent frame-statistics check: equal laws pass, each changed effect is caught by its statistic."""

import numpy as np
import pytest
from frame_stats import compare, dark_slope, sequence_stats


def sensor(seed, *, n=16, h=96, w=128, read=2.0, row=0.0, dsnu=0.0, tail=0.0, dnl=0.0, level=100.0):
    rng = np.random.default_rng(seed)
    fpn = dsnu * rng.standard_normal((h, w))
    x = level + fpn + read * rng.standard_normal((n, h, w)) + row * rng.standard_normal((n, h, 1))
    if tail:
        hit = rng.random((n, h, w)) < tail
        x += hit * rng.choice([-30.0, 30.0], size=(n, h, w))
    if dnl:  # unequal code widths: transition levels moved by up to dnl LSB
        edges = np.arange(0, 400) + 0.5 + dnl * np.random.default_rng(99).standard_normal(400)
        return np.searchsorted(np.sort(edges), x).astype(np.float64)
    return np.rint(x)


def failing(rows):
    return {r["stat"] for r in rows if not r["ok"]}


def test_two_draws_of_one_law_agree():
    for s in range(3):
        a, b = sequence_stats(sensor(10 + s, row=1.0, dsnu=1.5)), sequence_stats(sensor(20 + s, row=1.0, dsnu=1.5))
        assert failing(compare(a, b)) == set()


@pytest.mark.parametrize("change, stat", [
    ({"row": 2.0}, "row_spread"),
    ({"dsnu": 3.0}, "pixel_spread"),
    ({"read": 2.6}, "temporal_var"),
    ({"tail": 0.002}, "tail_fraction"),
    ({"dnl": 0.3}, "code_nonuniformity"),
])
def test_a_changed_effect_is_caught_by_its_statistic(change, stat):
    base = dict(row=1.0, dsnu=1.5)
    a = sequence_stats(sensor(1, **base))
    b = sequence_stats(sensor(2, **{**base, **change}))
    assert stat in failing(compare(a, b))


def test_dark_slope():
    a, se = dark_slope([(0.1, 10.2), (1.0, 19.1), (2.0, 29.0)])
    assert a == pytest.approx(9.9, abs=0.2) and se > 0
