"""``simcam loop --maps``: the profile keeps *this* sensor's fixed patterns, and the noise stage draws them.

The capture set comes from the test-owned generator (``loop_generator``, plain numpy), whose hidden DSNU
and PRNU maps are the reference. Synthesis goes through :func:`simcam.synth.synth` with the noise stage,
and the DNGs are read back with rawpy. Expected correlations with the hidden maps (64 x 64 pixels): the
dark offset map holds the DSNU (2.5 DN) plus the temporal noise of a 12-frame mean (3 DN / sqrt(12)), so
r ~ 2.5 / sqrt(2.5^2 + 0.87^2) = 0.94; the flat gain map holds the PRNU (2 %) plus the shot noise of a
12-frame mean at ~290 e- (1.7 %), r ~ 0.76; 16 synthesised darks add their own mean's noise (r ~ 0.9). A
profile without maps draws a new pattern: |r| below 0.1 (SE of r on 4096 pixels ~ 0.016).
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from loop_generator import HiddenEffectSensor, SensorSpec, capture_set, write_capture_set

rawpy = pytest.importorskip("rawpy")


def _corr(a, b) -> float:
    a, b = np.ravel(a) - np.mean(a), np.ravel(b) - np.mean(b)
    return float(a @ b / np.sqrt((a @ a) * (b @ b)))


def _synth_dark_mean(profile, spec: SensorSpec, n: int, out, exposure_s: float = 0.01) -> np.ndarray:
    from simcam.frame import CameraMeta, RawFrame
    from simcam.stages.noise import Noise
    from simcam.synth import synth

    meta = CameraMeta(cfa=spec.cfa, black_level=np.full((1, 1), spec.black_dn), white_level=spec.white_dn,
                      iso=float(spec.iso), exposure_time_s=exposure_s)
    clean = RawFrame(np.zeros((spec.height, spec.width), np.float32), meta, kind="raw")
    synth(clean, out, stage=Noise(profile=str(profile), iso=spec.iso), frames=n, seed=5)
    frames = []
    for i in range(n):
        with rawpy.imread(str(out / f"frame_{i:03d}.dng")) as r:
            frames.append(r.raw_image_visible.astype(np.float64))
    return np.mean(frames, axis=0)


def test_maps_reproduce_this_sensors_patterns(tmp_path):
    from simcam.calibration.loop import LoopConfig
    from simcam.calibration.report import run_and_write

    spec = SensorSpec(effects={"dsnu": {"sigma_dn": 2.5}, "prnu": {"sigma": 0.02}})
    root = write_capture_set(tmp_path / "set", capture_set(spec, flat_levels=(0.6, 0.3, 0.45), seed=7))
    hidden = HiddenEffectSensor(spec)
    outs = {}
    for maps in (True, False):
        out = tmp_path / ("maps" if maps else "plain")
        doc = run_and_write(root, out, cfg=LoopConfig(maps=maps, progress=False))
        assert set(doc["isos"][0]["effects"]) == {"dsnu", "prnu"}
        outs[maps] = out
    prof = yaml.safe_load((outs[True] / "profile.yaml").read_text())
    types = [e["type"] for e in prof["cameras"][0]["entries"][0]["model"]["effects"]]
    assert {"empirical_offset", "empirical_gain"} <= set(types) and not {"dsnu", "prnu"} & set(types)
    assert not (outs[False] / "maps.npz").exists()
    with np.load(outs[True] / "maps.npz") as z:
        fs = spec.white_dn - spec.black_dn
        assert _corr(z["iso800_dark_offset"] * fs, hidden.offset) > 0.85
        assert _corr(z["iso800_flat_gain"], hidden.prnu) > 0.6
    with_maps = _synth_dark_mean(outs[True] / "profile.yaml", spec, 16, tmp_path / "synth_maps")
    without = _synth_dark_mean(outs[False] / "profile.yaml", spec, 16, tmp_path / "synth_plain")
    assert _corr(with_maps, hidden.offset) > 0.8
    assert abs(_corr(without, hidden.offset)) < 0.1
    # the parametric DSNU's spread is the measured one either way (within 10 %: 4096 pixels)
    assert np.std(without) == pytest.approx(np.std(with_maps), rel=0.1)


def test_dark_rate_map_reproduces_this_sensors_dark_current(tmp_path):
    """Dark current with a log-normal non-uniformity (40 e-/s, log-sigma 0.3: a pixel spread of ~12 e-/s),
    darks at 0.01 s and 1 s (12 frames each): the per-pixel slope holds the rate plus the noise of two
    12-frame means (~3 e-/s), r ~ 0.97 with the hidden rates. 16 synthesised 1-s darks from the profile with
    maps follow this sensor's rates (their own mean's noise: r ~ 0.9); without maps a new pattern (|r| < 0.1)."""
    from simcam.calibration.loop import LoopConfig
    from simcam.calibration.report import run_and_write

    spec = SensorSpec(effects={"dark_current": {"rate_e_per_s": 40.0, "log_sigma": 0.3}})
    root = write_capture_set(tmp_path / "set", capture_set(spec, flat_levels=(0.3, 0.6), seed=11))
    hidden = HiddenEffectSensor(spec)
    outs = {}
    for maps in (True, False):
        out = tmp_path / ("maps" if maps else "plain")
        doc = run_and_write(root, out, cfg=LoopConfig(maps=maps, progress=False))
        assert "dark_current" in doc["isos"][0]["effects"]
        outs[maps] = out
    prof = yaml.safe_load((outs[True] / "profile.yaml").read_text())
    effects = prof["cameras"][0]["entries"][0]["model"]["effects"]
    types = [e["type"] for e in effects]
    assert "empirical_field" in types and "dark_current" not in types
    field = next(e for e in effects if e["type"] == "empirical_field")
    fs = spec.white_dn - spec.black_dn
    assert field["electron"] * fs == pytest.approx(spec.K, rel=0.1)
    with np.load(outs[True] / "maps.npz") as z:
        rate_e = z["iso800_dark_rate"] * fs / spec.K
    assert _corr(rate_e, hidden.dark_rate) > 0.9
    assert float(np.mean(rate_e)) == pytest.approx(float(np.mean(hidden.dark_rate)), rel=0.05)
    with_maps = _synth_dark_mean(outs[True] / "profile.yaml", spec, 16, tmp_path / "synth_maps", exposure_s=1.0)
    without = _synth_dark_mean(outs[False] / "profile.yaml", spec, 16, tmp_path / "synth_plain", exposure_s=1.0)
    assert _corr(with_maps, hidden.dark_rate) > 0.8
    assert abs(_corr(without, hidden.dark_rate)) < 0.1
