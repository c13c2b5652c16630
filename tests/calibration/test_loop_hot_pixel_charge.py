"""Hot pixels as dark charge: the noise stage's ``hot_electron`` option (Poisson electrons each frame,
off by default) and the loop card's data-decided ``shot_noise``."""

import numpy as np

from simcam.calibration import diagnostics as dg
from simcam.calibration.effects import CARDS, FitContext
from simcam.calibration.model import LoopModel
from simcam.noise.base import NoiseCondition, model_from_entry

K, READ, BLACK, WHITE = 2.0, 3.0, 64.0, 4095.0
FS = WHITE - BLACK


def _darks(shot: bool, seed=0, n=12, size=64):
    rng = np.random.default_rng(seed)
    hot = rng.random((size, size)) < 0.01
    off_e = np.where(hot, rng.uniform(100, 300, (size, size)), 0.0)
    frames = []
    for _ in range(n):
        charge = rng.poisson(off_e) if shot else off_e
        frames.append(np.round(BLACK + K * charge + rng.normal(0, READ, (size, size))))
    return np.asarray(frames, np.float32)


def _fit(frames):
    d = dg.CaptureData([frames], [], [], np.full((2, 2), BLACK), WHITE, "RGGB")
    m = LoopModel("RGGB", np.full((2, 2), BLACK), WHITE, K, READ, READ ** 2 + 1 / 12)
    return CARDS["hot_pixels"].fit(d, m, FitContext()), m


def test_card_turns_shot_noise_on_for_charge_only():
    p, m = _fit(_darks(shot=True))
    assert p.shot_noise is True and p.gain_dn_per_e == K
    entry = CARDS["hot_pixels"].to_profile(p, m).effect
    assert entry["hot_electron"] == K / FS
    back = CARDS["hot_pixels"].from_profile(entry, FS)
    assert back.shot_noise is True and back.gain_dn_per_e == K
    p0, m0 = _fit(_darks(shot=False))
    assert p0.shot_noise is None and "hot_electron" not in CARDS["hot_pixels"].to_profile(p0, m0).effect


def _sample(entry, n=64, size=64):
    comp = model_from_entry({"type": "composite", "base": {"type": "poisson_gaussian", "beta1": 1e-9, "beta2": 1e-12},
                             "effects": [entry], "sensor_seed": 3}, where="test")
    cond = NoiseCondition(cfa="RGGB", source="test")
    return comp.sample_frames(np.zeros((size, size), np.float32), cond, np.random.default_rng(1), n)


def test_noise_stage_hot_electron_is_poisson_and_default_off():
    off = 0.05
    base = {"type": "hot_pixels", "hot_fraction": 0.02, "hot_offset": off}
    plain = model_from_entry({"type": "composite", "base": {"type": "poisson_gaussian", "beta1": 1e-9,
                                                            "beta2": 1e-12}, "effects": [base]}, where="test")
    assert "hot_electron" not in plain.effects[0].to_entry()  # off: the entry keeps its former keys
    x0 = _sample(base)
    hot = x0[0] > off / 2
    assert hot.any() and np.allclose(x0[:, hot], off, atol=1e-4)  # a fixed offset: no temporal noise
    e = 1e-3  # 50 electrons per hot pixel
    x = _sample(dict(base, hot_electron=e))
    assert abs(float(x[:, hot].mean()) - off) < 0.02 * off
    # Poisson: variance = e * mean (normalised raw), within ~10 %
    assert abs(float(x[:, hot].var(axis=0, ddof=1).mean()) / (e * off) - 1) < 0.15


def test_without_a_photon_transfer_the_gain_comes_from_the_hot_pixels_own_charge():
    """Darks only (no flats, K unknown: 0): the card reads K from the hot pixels' variance excess over their
    offsets. Its standard error from the closed form (a sample variance of m dof has variance 2 v^2 / m,
    v_i = K^2 lambda_i + read^2 + 1/12): the estimate must lie within 4 of them."""
    frames = _darks(shot=True, seed=5, n=16)
    d = dg.CaptureData([frames], [], [], np.full((2, 2), BLACK), WHITE, "RGGB")
    m = LoopModel("RGGB", np.full((2, 2), BLACK), WHITE, 0.0, READ, READ ** 2 + 1 / 12)
    p = CARDS["hot_pixels"].fit(d, m, FitContext())
    assert p.shot_noise is True
    hot = dg.hot_pixel_mask(d)
    off_dn = (frames.mean(0) - BLACK)[hot]
    v = K * off_dn + READ ** 2 + 1 / 12
    se = np.sqrt(np.sum(2 * v ** 2 / (frames.shape[0] - 1))) / off_dn.sum()
    assert abs(p.gain_dn_per_e - K) < 4 * se, (p.gain_dn_per_e, se)
    p0 = CARDS["hot_pixels"].fit(dg.CaptureData([_darks(shot=False, seed=5, n=16)], [], [], np.full((2, 2), BLACK),
                                                WHITE, "RGGB"), m, FitContext())
    assert p0.count and p0.shot_noise is None and p0.gain_dn_per_e is None  # a fixed offset: no gain read
