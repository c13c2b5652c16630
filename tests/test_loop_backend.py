"""The loop's model drawn by simcam's noise stage (backend "simcam") against the loop's reference
simulator and closed-form moments."""

import numpy as np
import pytest

from simcam.dataset.loop_model import LoopModel, SimSpec, simulate_capture


def _model(**effects):
    m = LoopModel("RGGB", np.full((2, 2), 64.0), 1023.0, 2.0, 3.0, 0.0, effects=effects)
    m.var_dark_dn2 = 9.0 + m.q ** 2 / 12 + effects.get("row_noise", {}).get("sigma_dn", 0.0) ** 2
    m.refit_read()
    return m


@pytest.mark.parametrize("backend", ["internal", "simcam"])
def test_moments_of_both_simulators(backend):
    m = _model(row_noise={"sigma_dn": 1.5}, dsnu={"sigma_dn": 2.0}, black_level_offset={"offset_dn": [4.0] * 4})
    h = w = 64
    flat = np.full((h, w), 400.0)
    specs = [SimSpec("dark", 16, np.zeros((h, w))), SimSpec("flat", 16, flat)]
    dark, fl = simulate_capture(m, specs, np.random.default_rng(0), backend)
    # integer ADC codes
    assert np.all(dark == np.round(dark))
    # dark mean = black + offset (SE ~ sqrt(2^2/4096 + ...) < 0.05 DN)
    assert dark.mean() == pytest.approx(68.0, abs=0.15)
    # temporal variance of a dark pixel = read^2 + row^2 + 1/12 = 9 + 2.25 + 1/12 (SE ~ 1 % -> 5 %)
    assert np.var(dark - dark.mean(0), axis=0, ddof=1).mean() == pytest.approx(11.33, rel=0.05)
    # row means: sigma_row^2 + (read^2 + 1/12)/W (1024 rows x frames, SE ~ 5 % -> 20 %)
    r = dark - dark.mean(0)
    assert np.var(r.mean(axis=2), axis=1, ddof=1).mean() * 16 / 15 == pytest.approx(2.25 + 9.08 / 64, rel=0.2)
    # DSNU: variance of the 16-frame mean map = dsnu^2 + temporal / 16 (SE ~ 3 % -> 12 %)
    assert np.var(dark.mean(0)) == pytest.approx(4.0 + 11.33 / 16, rel=0.12)
    # flat: shot-noise variance K * signal + dark temporal variance (SE ~ 1 % -> 5 %)
    v = np.var(fl - fl.mean(0), axis=0, ddof=1).mean()
    assert v == pytest.approx(2.0 * 400 + 11.33, rel=0.05)


@pytest.mark.slow
def test_simcam_backend_loop_names_an_effect():
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parent))
    from loop_matrix import run_case

    r = run_case(("dsnu",), backend="simcam")
    assert list(r.model.effects) == ["dsnu"] and r.unexplained == []
