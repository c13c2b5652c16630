"""Dark current from darks at several exposure times (emva1288 package's camera simulator: thermal
electrons Poisson with mean dark_current x exposure, uniform over the pixels)."""

import numpy as np
import pytest

pytest.importorskip("emva1288")

from emva1288.camera.camera import Camera  # noqa: E402

from simcam.calibration.capture import CaptureSet, Sequence  # noqa: E402
from simcam.calibration.dark_current import dark_current  # noqa: E402
from simcam.calibration.loop import LoopConfig, run_loop  # noqa: E402

SIZE, FRAMES, K = 64, 8, 1.0
REF_E_S = 400.0  # at 30 C; the camera runs at 22 C: 400 * 2 ** (-8 / 8) = 200 e-/s
TRUE_E_S = REF_E_S / 2


def _darks(times=(0.05, 0.25, 0.5), seed=0, frames=None):
    cam = Camera(bit_depth=12, width=SIZE, height=SIZE, K=K, dark_signal_0=50.0, sigma2_dark_0=9.0,
                 dark_current_ref=REF_E_S, seed=seed)
    seqs = []
    for i, t in enumerate(times):
        cam.exposure = t * 1e9
        fr = np.stack([cam.grab(0.0) for _ in range(frames[i] if frames else FRAMES)]).astype(np.float32)
        seqs.append(Sequence(f"dark_{t}", "dark", fr, 100, t, None, None, float(cam.img_max)))
    return seqs, cam


def test_dark_current_from_mean_and_variance():
    seqs, cam = _darks()
    dc = dark_current(seqs, cam.K)  # the camera quantises its gain: K = 1.0315 DN/e-
    assert dc["applicable"] and dc["exposure_s"] == [0.05, 0.25, 0.5]
    # mean: 64x64x8 pixels per point, per-pixel sd ~ sqrt(9 + 100) e- -> SE of each mean ~0.06 e-,
    # slope SE over 0.45 s ~0.2 e-/s: 2 % tolerance is > 10 SE
    assert dc["e_per_s_from_mean"] == pytest.approx(TRUE_E_S, rel=0.02)
    # variance: each temporal variance (~109 e-^2) has SE ~109 * sqrt(2 / (4096 * 7)) ~ 0.9 e-^2,
    # slope SE ~ 2.5 e-/s -> 6 % tolerance (~5 SE)
    assert dc["e_per_s_from_variance"] == pytest.approx(TRUE_E_S, rel=0.06)
    # the simulator's dark current is uniform: what is left is the noise of the correction (~1 e-/s)
    assert dc["nonuniformity_e_per_s"] < 0.05 * TRUE_E_S


def test_single_exposure_is_not_applicable_with_reason():
    seqs, _ = _darks(times=(0.1,))
    dc = dark_current(seqs, K)
    assert dc == {"applicable": False, "reason": "needs darks at >= 2 exposure times: darks at a single "
                                                 "exposure time (0.1 s)"}


def test_loop_does_not_pool_darks_of_different_exposures():
    seqs, cam = _darks(times=(0.05, 0.5), frames=(8, 10))
    r = run_loop(CaptureSet("memory", "directory", seqs), LoopConfig(replicates=8, heldout_replicates=4))[0]
    assert any("darks at 0.05 s used for the dark diagnostics" in n for n in r.notes)
    # the read noise of the base fit is that of the 0.05 s darks alone (sqrt(9 + 10) e-; EMVA 1288 R4.0
    # measures the temporal dark noise at the shortest exposure time), not a mixture
    assert r.base.read_dn == pytest.approx(np.sqrt(9.0 + TRUE_E_S * 0.05) * cam.K, rel=0.05)
