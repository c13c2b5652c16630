"""EMVA 1288 numbers on the real CCD set against the reference implementation's results."""

import re

import numpy as np
import pytest

from shared_data import shared_path
from simcam.calibration.capture import read_emva1288
from simcam.calibration.photon_transfer import emva1288_numbers


def _reference(path):
    txt = path.read_text()

    def val(symbol):
        m = re.search(re.escape(symbol) + r"\s+(\S+)\s*$", txt, re.M)
        return float(m.group(1))

    return {"K_dn_per_e": val("K"), "sigma_dark_e": val(r"$\sigma_d$"),
            "dsnu_e": val(r"$DSNU_{1288}$"), "prnu_percent": val(r"$PRNU_{1288}$")}


@pytest.fixture(scope="module")
def emva():
    desc = shared_path("emva1288_ccd/EMVA1288_Data.txt")
    ref = _reference(shared_path("emva1288_ccd/emva1288_v1.0.2_results.txt"))
    return emva1288_numbers(read_emva1288(desc).sequences), ref


def test_emva_gain_and_dark_noise_within_1_percent(emva):
    got, ref = emva
    assert ref["K_dn_per_e"] == pytest.approx(0.2801, abs=1e-4)  # the file read is the one the issue quotes
    for key in ("K_dn_per_e", "sigma_dark_e"):
        assert got[key] == pytest.approx(ref[key], rel=0.01), key


def test_emva_dsnu_prnu(emva):
    got, ref = emva
    for key in ("dsnu_e", "prnu_percent"):
        assert got[key] == pytest.approx(ref[key], rel=0.01), key


@pytest.mark.slow
def test_loop_on_emva_set_reports_before_after(tmp_path):
    from simcam.calibration.report import run_and_write
    from simcam.calibration.loop import LoopConfig

    desc = shared_path("emva1288_ccd/EMVA1288_Data.txt")
    doc = run_and_write(desc.parent, tmp_path / "out", cfg=LoopConfig(max_size=64))
    assert doc["emva"]["K_dn_per_e"] == pytest.approx(0.2801, rel=0.03)
    g = doc["isos"][0]
    for it in g["iterations"]:
        h = it["heldout"]
        assert h["kl_before"] is not None and h["kl_after"] is not None
    assert g["heldout"]["kl_final"] <= g["heldout"]["kl_base"]
    # every significant residual left is reported with its reason
    assert all(u["reason"] for u in g["unexplained"])
    # the CCD's darks carry a per-frame offset alternating between interleaved sites: over all 51 dark
    # pairs the checkerboard contrast's variance is ~1,500x its white-noise value, but not in the pair at
    # the shortest exposure time, which the loop's dark diagnostics use (EMVA 1288 Release 4.0), so the
    # loop does not see it there
    from simcam.calibration import diagnostics as dg
    from simcam.calibration.capture import read_capture_set

    cap = read_capture_set(desc.parent)
    darks = [s for s in cap.group(cap.isos()[0]) if s.kind == "dark"]
    shortest = min(s.exposure_s for s in darks)

    def jitter(seqs):
        d = dg.CaptureData([s.frames for s in seqs], [], [], np.zeros((2, 2)), darks[0].white_dn, darks[0].cfa)
        return float(np.exp(dg.dark_checker_jitter(d)))

    assert jitter(darks) > 100
    assert jitter([s for s in darks if s.exposure_s == shortest]) < 10
    assert "dark_checker_jitter" not in {u["diagnostic"] for u in g["unexplained"]}


def test_emva_numbers_on_generated_cfa_set_match_the_generator():
    # K = 2 DN/e-, read 3 DN -> sigma_d = 1.5 e-. Per plane 32x32 px, 12-frame pairs: K SE ~ 2 %,
    # dark variance SE ~ 1.4 % -> 6 % tolerance; PRNU 2 % from a 32x32 map of a 12-frame flat (SE ~ 3 %).
    import numpy as np

    from loop_generator import DEFAULT_EFFECTS, SensorSpec, capture_set
    from loop_matrix import in_memory_capture

    cs = in_memory_capture(capture_set(SensorSpec(effects={"prnu": DEFAULT_EFFECTS["prnu"]})))
    e = emva1288_numbers(cs.sequences)
    assert e["K_dn_per_e"] == pytest.approx(2.0, rel=0.06)
    assert e["sigma_dark_e"] == pytest.approx(1.5, rel=0.06)
    assert e["prnu_percent"] == pytest.approx(2.0, rel=0.15)
    assert len(e["planes"]) == 4 and np.isfinite(e["dsnu_e"] or 0.0)


def test_emva_dark_current_matches_reference(emva):
    """Dark current from the mean and from the variance of the CCD's temporal darks (50 exposure
    times), against the reference implementation's results file."""
    from simcam.calibration.dark_current import dark_current

    got, _ = emva
    txt = shared_path("emva1288_ccd/emva1288_v1.0.2_results.txt").read_text()
    ref_mean = float(re.search(r"\$\\mu_\{I\.mean\}\$\s+(\S+)", txt).group(1))
    ref_var = float(re.search(r"\$\\mu_\{I\.var\}\$\s+(\S+)", txt).group(1))
    seqs = read_emva1288(shared_path("emva1288_ccd/EMVA1288_Data.txt"), progress=False).sequences
    dc = dark_current([s for s in seqs if s.kind == "dark"], got["K_dn_per_e"])
    assert dc["e_per_s_from_mean"] == pytest.approx(ref_mean, rel=0.01)
    assert dc["e_per_s_from_variance"] == pytest.approx(ref_var, rel=0.01)
