"""Empirical components and measured maps: a profile with an .npz beside it reproduces the map."""

import numpy as np
import pytest
import yaml
from scipy import stats

from simcam.errors import NoiseModelError, ProfileError
from simcam.noise import NoiseCondition, model_from_entry
from simcam.profiles.schema import load_profile

COND = NoiseCondition(cfa="RGGB", exposure_s=1.0)


def comp(effects, seed=0):
    return model_from_entry({"type": "composite", "base": {"type": "gaussian", "sigma": 1e-9},
                             "effects": effects, "sensor_seed": seed})


def write_profile(root, effects):
    doc = {"schema_version": 1,
           "provenance": {"source": "test", "method": "measured", "tool": "test", "created": "", "licence": "none"},
           "cameras": [{"id": "cam", "cfa": "RGGB", "entries": [{"iso": 100, "model": {
               "type": "composite", "base": {"type": "gaussian", "sigma": 1e-9}, "effects": effects,
               "sensor_seed": 1}}]}]}
    p = root / "profile.yaml"
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(yaml.safe_dump(doc))
    return p


def test_measured_pixel_map_is_reproduced_through_a_profile(tmp_path):
    rng = np.random.default_rng(0)
    dsnu = (2e-3 * rng.standard_normal((40, 60))).astype(np.float32)
    prof = write_profile(tmp_path / "prof", [{"type": "empirical_offset", "axis": "pixel", "map": "maps.npz#dsnu"}])
    np.savez(prof.parent / "maps.npz", dsnu=dsnu)
    m = load_profile(prof).model_for(100)
    x = m.sample(np.zeros((32, 48), np.float32), COND, np.random.default_rng(1))
    assert np.allclose(x, dsnu[:32, :48], atol=1e-7)  # top-left part of the calibrated sensor


def test_map_errors_are_one_line(tmp_path):
    def sample(prof):
        return load_profile(prof).model_for(100).sample(np.zeros((8, 8), np.float32), COND, np.random.default_rng(0))

    with pytest.raises(NoiseModelError, match="missing.npz"):
        sample(write_profile(tmp_path / "a", [{"type": "empirical_offset", "map": "missing.npz#dsnu"}]))
    np.savez(tmp_path / "small.npz", dsnu=np.zeros((4, 4)))
    with pytest.raises(NoiseModelError, match="shape"):
        sample(write_profile(tmp_path / "b", [{"type": "empirical_offset", "map": "../small.npz#dsnu"}]))
    with pytest.raises(ProfileError, match="quantiles"):
        sample(write_profile(tmp_path / "c", [{"type": "empirical_offset"}]))


def test_temporal_row_offsets_follow_the_measured_distribution():
    q = np.quantile(np.random.default_rng(5).laplace(0, 1e-3, 20001), np.linspace(0, 1, 201))
    m = comp([{"type": "empirical_offset", "axis": "row", "temporal": True, "quantiles": q.tolist()}])
    x = m.sample_frames(np.zeros((500, 8), np.float32), COND, np.random.default_rng(2), 8)
    rows = x[:, :, 0].ravel()
    assert stats.ks_2samp(rows, np.random.default_rng(6).laplace(0, 1e-3, 20000)).pvalue > 1e-3
    assert np.allclose(x, x[:, :, :1])  # one offset per row and frame


def test_frame_offset_rate_adds_rate_times_exposure_and_is_left_out_of_the_entry_at_zero():
    q = [-1e-3, 0.0, 1e-3]
    entry = {"type": "empirical_offset", "axis": "frame", "temporal": True, "quantiles": q}
    assert "rate" not in comp([entry]).effects[0].to_entry()  # off: the entry keeps its former keys
    m = comp([dict(entry, rate=2e-3)])
    clean = np.zeros((4, 4), np.float32)
    for t in (0.5, 2.0):
        x = m.sample_frames(clean, NoiseCondition(cfa="RGGB", source="test", exposure_s=t), np.random.default_rng(1),
                            4000)
        means = x.mean(axis=(1, 2))
        assert np.allclose(x, means[:, None, None])  # one offset per frame, shared by every pixel
        # the frame law is uniform on [-1e-3, 1e-3] (sd 5.8e-4) about 2e-3 t: the mean within 4 SE
        assert abs(means.mean() - 2e-3 * t) < 4 * 1e-3 / np.sqrt(3) / np.sqrt(4000)
    with pytest.raises(NoiseModelError, match="exposure"):
        m.sample_frames(clean, NoiseCondition(cfa="RGGB", source="test"), np.random.default_rng(1), 2)


def test_empirical_gain_multiplies_the_signal():
    m = comp([{"type": "empirical_gain", "axis": "column", "quantiles": [0.9, 1.1]}])
    x = m.sample(np.full((16, 400), 0.5, np.float32), COND, np.random.default_rng(0))
    g = x[0] / 0.5
    assert np.allclose(x, x[:1]) and g.min() >= 0.9 - 1e-6 and g.max() <= 1.1 + 1e-6
    assert abs(g.mean() - 1.0) < 5 * (0.2 / np.sqrt(12)) / np.sqrt(400)


def test_empirical_code_uses_the_measured_transitions():
    edges = [0.5, 1.5, 4.5, 5.5, 9.5]  # code 2 spans 1.5..4.5 (3 LSB wide), code 4 5.5..9.5
    m = comp([{"type": "empirical_code", "range_dn": 10.0, "edges": edges}])
    x = m.sample((np.array([[1.0, 2.0, 4.0, 6.0, 9.0, 9.9]]) / 10).astype(np.float32), COND, np.random.default_rng(0))
    assert (x * 10).round().tolist() == [[1, 2, 2, 4, 4, 5]]


def test_empirical_field_scales_with_exposure():
    m = comp([{"type": "empirical_field", "field": [[0.01, 0.01], [0.01, 0.01]], "electron": 1e-4}])
    for t in (0.5, 2.0):
        x = m.sample(np.zeros((64, 64), np.float32), NoiseCondition(cfa="RGGB", exposure_s=t),
                     np.random.default_rng(1))
        lam = 0.01 * t / 1e-4
        assert abs(x.mean() / 1e-4 - lam) < 5 * np.sqrt(lam / x.size)


def test_empirical_lines_keep_their_frequencies_and_power_with_a_phase_per_sensor():
    lines = [[0.25, 2e-3], [0.1, 1e-3]]
    x = comp([{"type": "empirical_lines", "axis": "column", "lines": lines}]).sample(
        np.zeros((8, 400), np.float32), COND, np.random.default_rng(0))
    assert np.allclose(x, x[:1])  # one offset per column, the same in every row
    col = x[0].astype(np.float64)
    # the power of each line in the periodogram of the columns (400 columns: both on an exact bin)
    p = np.abs(np.fft.rfft(col)) ** 2 * 2 / col.size ** 2
    for f, a in lines:
        assert abs(p[round(f * col.size)] - a * a / 2) < 1e-3 * a * a
    assert p.sum() == pytest.approx(sum(a * a / 2 for _, a in lines), rel=1e-3)
    # another sensor seed: the same lines with other phases
    y = comp([{"type": "empirical_lines", "axis": "column", "lines": lines}], seed=1).sample(
        np.zeros((8, 400), np.float32), COND, np.random.default_rng(0))
    assert not np.allclose(x, y)
    rows = comp([{"type": "empirical_lines", "axis": "row", "lines": [[0.125, 1e-3]]}]).sample(
        np.zeros((64, 8), np.float32), COND, np.random.default_rng(0))
    assert np.allclose(rows, rows[:, :1]) and np.ptp(rows[:, 0]) > 1e-3
    with pytest.raises(Exception, match="lines"):
        comp([{"type": "empirical_lines", "lines": [[0.7, 1e-3]]}])


def test_empirical_lines_gain_part_grows_with_the_signal_at_its_phase():
    """A line ``[f, a, g, delta]``: columns get ``a cos(phi_i) + S g cos(phi_i + delta)`` on a flat of
    expected signal S, phi_i = 2 pi f i + phi; the phase drawn per sensor is the same for both parts."""
    f, a, g, delta = 0.25, 2e-3, 0.02, 1.0
    m = comp([{"type": "empirical_lines", "axis": "column", "lines": [[f, a, g, delta], [0.1, 0.0, 0.01, 0.0]]}])
    dark = m.sample(np.zeros((4, 400), np.float32), COND, np.random.default_rng(0))[0].astype(np.float64)
    s = 0.4
    flat = m.sample(np.full((4, 400), s, np.float32), COND, np.random.default_rng(0))[0].astype(np.float64) - s
    A, B = np.fft.rfft(dark), np.fft.rfft((flat - dark) / s)
    k, k2 = round(f * 400), round(0.1 * 400)
    assert abs(A[k]) * 2 / 400 == pytest.approx(a, rel=1e-3)  # offset amplitude
    assert abs(B[k]) * 2 / 400 == pytest.approx(g, rel=1e-3)  # gain amplitude
    assert np.angle(B[k] / A[k]) == pytest.approx(delta, abs=1e-3)  # the gain part's phase against the offset's
    assert abs(A[k2]) < 1e-6 and abs(B[k2]) * 2 / 400 == pytest.approx(0.01, rel=1e-3)  # gain-only line
    # an offset-only profile entry draws the same phases as before the gain part existed
    x = comp([{"type": "empirical_lines", "axis": "column", "lines": [[f, a]]}]).sample(
        np.zeros((4, 400), np.float32), COND, np.random.default_rng(0))[0].astype(np.float64)
    assert np.angle(np.fft.rfft(x)[k]) == pytest.approx(np.angle(A[k]), abs=1e-6)
    with pytest.raises(Exception, match="relative gain"):
        comp([{"type": "empirical_lines", "lines": [[0.25, 1e-3, 0.7, 0.0]]}])
