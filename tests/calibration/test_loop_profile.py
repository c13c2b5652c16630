"""The loop's model as a noise-stage profile: round trip and (when simcam.noise is present) validation."""

import numpy as np
import pytest

from simcam.calibration.effects.hot_pixels import HotPixels
from simcam.calibration.model import LoopModel
from simcam.calibration.profile import models_from_noise_profile, noise_entry, noise_profile


def _model():
    eff = {
        "prnu": {"sigma": 0.01}, "channel_gain": {"gains": [1.1, 1.0, 1.0, 0.9]}, "frame_flicker": {"sigma": 0.005},
        "nonlinearity": {"c": -0.1}, "spatial_correlation": {"a": 0.2}, "row_noise": {"sigma_dn": 1.5},
        "periodic_pattern": {"amplitude_dn": 2.0, "period_px": 8.0, "axis": "row"}, "column_fpn": {"sigma_dn": 1.0},
        "dsnu": {"sigma_dn": 2.0}, "hot_pixels": {"fraction": 0.001, "log_mean": 4.0, "log_sigma": 0.05},
        "black_level_offset": {"offset_dn": [6.0, 6.0, 6.0, 6.0]}, "quantization": {"step_dn": 4.0},
    }
    return LoopModel("RGGB", np.full((2, 2), 64.0), 1023.0, 2.0, 3.0, 9.0 + 16 / 12 + 2.25 + 2.0, effects=eff)


class _Res:
    def __init__(self, m):
        self.model, self.iso = m, 800


class _Cap:
    root = "/tmp/sensor"


def test_round_trip_through_noise_profile():
    m = _model()
    doc = noise_profile([_Res(m)], _Cap())
    back = models_from_noise_profile(doc, "profile.yaml")[800]
    assert back.K == pytest.approx(m.K) and back.read_dn == pytest.approx(m.read_dn)
    assert set(back.effects) == set(m.effects)
    assert back.effects["dsnu"].sigma_dn == pytest.approx(2.0)
    assert back.effects["spatial_correlation"].a == pytest.approx(0.2, rel=1e-6)
    assert back.effects["nonlinearity"].c == pytest.approx(-0.1)
    assert back.effects["channel_gain"].gains == pytest.approx([1.1, 1.0, 1.0, 0.9])
    # beta1 on normalised raw = K g_c / (white - black), per site
    entry, _ = noise_entry(m)
    assert entry["base"]["beta1"] == pytest.approx([2.2 / 959.0, 2.0 / 959.0, 2.0 / 959.0, 1.8 / 959.0])


def test_profile_is_accepted_by_the_noise_stage():
    from simcam.profiles.schema import profile_from_dict

    doc = noise_profile([_Res(_model())], _Cap())
    prof = profile_from_dict(doc, source="profile.yaml")
    model = prof.model_for(800)
    assert type(model).__name__.lower().startswith("composite")


def test_noise_stage_from_the_profile_draws_the_fitted_noise():
    """The written profile, read by simcam.profiles and sampled by the noise stage, has the loop model's
    photon-transfer curvature and read-noise crosstalk (closed forms in DN, see test_loop_simulate)."""
    from simcam.noise import NoiseCondition
    from simcam.profiles.schema import profile_from_dict

    c, a = -0.12, 0.35
    m = LoopModel("RGGB", np.full((2, 2), 64.0), 1023.0, 2.0, 3.0, 9.0,
                  effects={"nonlinearity": {"c": c}, "spatial_correlation": {"a": a}})
    m.refit_read()
    model = profile_from_dict(noise_profile([_Res(m)], _Cap()), source="profile.yaml").model_for(800)
    s = 959.0
    cond = NoiseCondition(cfa="RGGB")
    x0 = 600.0  # linear level above black (DN)
    fl = model.sample_frames(np.full((64, 64), x0 / s, np.float32), cond, np.random.default_rng(0), 16) * s
    v = np.var(fl - fl.mean(0), axis=0, ddof=1).mean()
    # delta method: (1 + 2 c x0 / s)^2 (K x0 + read^2); SE of 16 x 4096 variances ~ 1 % -> 5 %
    assert v == pytest.approx((1 + 2 * c * x0 / s) ** 2 * (2.0 * x0 + 9.0), rel=0.05)
    dk = model.sample_frames(np.zeros((64, 64), np.float32), cond, np.random.default_rng(1), 16) * s
    r = dk - dk.mean(0)
    p = r[:, 0::2, 0::2]
    # in-plane lag-1 correlation of the read noise 2a / (1 + 2a^2), the response slope ~1 at black;
    # SE ~ 1.5 / sqrt(16 * 1024) = 0.012 -> 0.05
    assert np.mean(p[:, :, 1:] * p[:, :, :-1]) / np.mean(p * p) == pytest.approx(2 * a / (1 + 2 * a * a), abs=0.05)


def test_hot_pixel_log_normal_round_trip():
    # the loop's log-normal (log_mean, log_sigma in DN) -> hot_offset = its mean / (white - black) and
    # hot_log_sigma, and back (exact inverse)
    m = _model()
    m.effects["hot_pixels"] = HotPixels(fraction=0.004, log_mean=3.9, log_sigma=0.75)
    entry, notes = noise_entry(m)
    hp = next(e for e in entry["effects"] if e["type"] == "hot_pixels")
    assert hp["hot_offset"] == pytest.approx(np.exp(3.9 + 0.75 ** 2 / 2) / 959.0)
    assert hp["hot_log_sigma"] == 0.75 and not any("hot" in n for n in notes)
    back = models_from_noise_profile(noise_profile([_Res(m)], _Cap()), "profile.yaml")[800]
    assert back.effects["hot_pixels"].log_mean == pytest.approx(3.9)
    assert back.effects["hot_pixels"].log_sigma == pytest.approx(0.75)
