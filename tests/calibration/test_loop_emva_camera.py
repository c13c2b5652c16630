"""The loop and the EMVA 1288 numbers on captures made by the ``emva1288`` package's own camera
simulator (an independent generator: Poisson photo-electrons, Gaussian dark noise in electrons,
per-pixel DSNU / PRNU maps, dithered 12-bit ADC), monochrome like the EMVA descriptor sets."""

import numpy as np
import pytest

pytest.importorskip("emva1288")

from emva1288.camera.camera import Camera  # noqa: E402

from simcam.calibration.capture import CaptureSet, Sequence  # noqa: E402
from simcam.calibration.loop import LoopConfig, run_loop  # noqa: E402
from simcam.calibration.photon_transfer import emva1288_numbers  # noqa: E402

SIZE, FRAMES = 64, 12
LEVELS_DN = (300, 600, 900, 1200, 1500, 1800, 2100, 2400)
SIGMA_DARK_E = 4.0  # sigma2_dark_0 = 16 e-^2
DARK_E = 60.0  # dark signal: keeps the dark frames away from the camera's clip at 0 e-


def _capture(seed: int = 0, **maps) -> tuple[CaptureSet, Camera]:
    cam = Camera(bit_depth=12, width=SIZE, height=SIZE, K=1.0, dark_signal_0=DARK_E,
                 sigma2_dark_0=SIGMA_DARK_E ** 2, seed=seed, **maps)
    white = float(cam.img_max)

    def seq(name, kind, radiance):
        frames = np.stack([cam.grab(radiance) for _ in range(FRAMES)]).astype(np.float32)
        return Sequence(name, kind, frames, 0, cam.exposure * 1e-9, None, None, white)

    seqs = [seq("dark", "dark", 0.0)]
    seqs += [seq(f"flat_{k}", "flat", cam.get_radiance_for(mean=m)) for k, m in enumerate(LEVELS_DN)]
    return CaptureSet("emva1288-camera", "directory", seqs), cam


def test_emva_numbers_match_the_camera():
    cs, cam = _capture()
    e = emva1288_numbers(cs.sequences)
    # K from the photon-transfer slope over 8 levels of 64x64 px x 11 frame pairs: its spread over
    # capture seeds is 1.4 % (5 seeds) -> 6 % tolerance; sigma_d shares K's error (sigma_y / K)
    assert e["K_dn_per_e"] == pytest.approx(cam.K, rel=0.06)
    assert e["sigma_dark_e"] == pytest.approx(SIGMA_DARK_E, rel=0.06)


@pytest.mark.parametrize("case", ["base", "dsnu", "prnu"])
def test_loop_names_the_camera_maps(case):
    rng = np.random.default_rng(11)
    maps = {"base": {}, "dsnu": {"dsnu": rng.normal(0.0, 3.0, (SIZE, SIZE))},  # e-
            "prnu": {"prnu": 1.0 + rng.normal(0.0, 0.02, (SIZE, SIZE))}}[case]
    cs, cam = _capture(**maps)
    r = run_loop(cs, LoopConfig())[0]
    # base: K from the pooled photon transfer (K SE ~1 %), read noise sigma_d K in DN
    assert r.base.K == pytest.approx(cam.K, rel=0.05)
    assert r.base.read_dn == pytest.approx(SIGMA_DARK_E * cam.K, rel=0.05)
    expected = [] if case == "base" else [case]
    assert list(r.model.effects) == expected and r.unexplained == []
    if case == "dsnu":  # 3 e- map: SE of a 4096-pixel robust spread ~2 %, plus the temporal part removed
        assert r.model.effects["dsnu"].sigma_dn == pytest.approx(3.0 * cam.K, rel=0.12)
    if case == "prnu":
        assert r.model.effects["prnu"].sigma == pytest.approx(0.02, rel=0.15)
