"""Two effects that share one residual are fitted jointly (``Loop._joint``).

A black level 3 DN below the declared one, and a dark level that rises by 3 DN per second of exposure
without shot noise (a self-heating offset, not dark charge) with a ramp over each sequence: darks at
0.01 s and 1 s. The offset alone moves the long darks away from the data, the rise alone the short
ones; each is refuted on the held-out frames (the held-out error grows), and a dark-current fit to the
rise (a small Poisson rate: the dark variance does not follow the level) once took the iteration with
a 2-nat gain. Fitted jointly, the frame form of ``empirical_offset`` with its rate and the black offset
explain the darks. Frames from the repository's test generator, the rise and ramp added here."""

import numpy as np
import pytest

from loop_generator import HiddenEffectSensor, SensorSpec, capture_set
from loop_matrix import in_memory_capture
from simcam.calibration.loop import LoopConfig, run_loop

OFFSET, RATE = -3.0, 3.0


def _capture(drift_dn: float, rate: float = RATE, seed: int = 7):
    spec = SensorSpec(effects={"black_level_offset": {"offset_dn": OFFSET}})
    caps = capture_set(spec, seed=seed)
    kind, fr, meta = caps["dark"]
    caps["dark_long"] = ("dark", HiddenEffectSensor(spec).frames(0.0, fr.shape[0], np.random.default_rng(seed + 4), 1.0),
                         dict(meta, exposure_s=1.0))
    for name in ("dark", "dark_long"):
        kind, fr, meta = caps[name]
        n = fr.shape[0]
        rise = rate * meta["exposure_s"] + drift_dn * (np.arange(n) / (n - 1) - 0.5)
        caps[name] = (kind, np.round(fr + rise[:, None, None]).astype(fr.dtype), meta)
    return caps


def _rate_se(caps) -> float:
    """SE of the rise per second from the two dark sequences' frame means (their spread over the frames)."""
    (_, a, ma), (_, b, mb) = caps["dark"], caps["dark_long"]
    var = [np.var(f.mean(axis=(1, 2)), ddof=1) / f.shape[0] for f in (a, b)]
    return float(np.sqrt(sum(var)) / (mb["exposure_s"] - ma["exposure_s"]))


@pytest.mark.parametrize("drift_dn", [2.0, 3.0])
def test_a_black_offset_beside_a_rising_dark_level_is_fitted_jointly(drift_dn):
    caps = _capture(drift_dn)
    r = run_loop(in_memory_capture(caps), LoopConfig())[0]
    assert set(r.model.effects) == {"empirical_offset", "black_level_offset"} and not r.unexplained
    off = r.model.effects["black_level_offset"].offset_dn
    assert np.allclose(off, OFFSET, atol=0.5)  # dark means of 6 frames of 64 x 64 pixels: SE ~0.05 DN
    rate = r.model.effects["empirical_offset"].rate_dn_per_s
    assert abs(rate - RATE) < 3 * _rate_se(caps), (rate, _rate_se(caps))
    first, second = r.iterations[0], r.iterations[1]
    assert first["accepted"] and second["accepted"]
    assert {first["effect"], second["effect"]} == {"empirical_offset", "black_level_offset"}
    assert first["joint_with"] == second["effect"] and second["joint_with"] == first["effect"]
    # each alone was refuted, the pair chosen; the held-out structured KL falls by >= 80 %
    singles = {c["effect"]: c for c in first["candidates"] if not c.get("joint_with")}
    assert not singles["black_level_offset"]["beats_current"] and not singles["empirical_offset"]["beats_current"]
    (pair,) = [c for c in first["candidates"] if c.get("joint_with")]
    assert pair["chosen"] and pair["beats_current"]
    h = second["heldout"]
    assert h["kl_structured_after"] <= 0.2 * h["kl_structured_before"]


def test_a_black_offset_alone_is_not_paired():
    caps = _capture(0.0, rate=0.0)
    del caps["dark_long"]
    r = run_loop(in_memory_capture(caps), LoopConfig())[0]
    assert list(r.model.effects) == ["black_level_offset"]
    assert not any(c.get("joint_with") for it in r.iterations for c in it["candidates"])
