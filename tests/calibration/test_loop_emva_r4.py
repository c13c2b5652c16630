"""EMVA 1288 R4.0 results the loop's report carries, computed from the whole frames the capture reader
streams, against what the reference implementation (PyPI ``emva1288`` 1.0.2) computed from the same
files of the real CCD set (its results file ships beside the data)."""

import json

import pytest
from shared_data import shared_path

from simcam.calibration.capture import read_emva1288
from simcam.calibration.report import emva1288_r4_figure, emva1288_r4_html, emva1288_r4_results


def _reference(path) -> dict:
    """Values of the reference implementation's results file, by symbol."""
    out = {}
    for line in path.read_text().splitlines():
        parts = line.split()
        if len(parts) >= 2 and parts[-2].startswith("$"):
            try:
                out[parts[-2]] = float(parts[-1])
            except ValueError:
                pass
    return out


@pytest.fixture(scope="module")
def ccd():
    desc = shared_path("emva1288_ccd/EMVA1288_Data.txt")
    ref = _reference(shared_path("emva1288_ccd/emva1288_v1.0.2_results.txt"))
    cs = read_emva1288(desc, progress=False)
    return emva1288_r4_results(cs)[cs.isos()[0]], ref


def test_ccd_r4_results_match_the_reference_implementation(ccd):
    e, ref = ccd
    y = e["channels"]["Y"]
    # Gain and dark noise: R4.0 fits the photon transfer over 0-70 % of saturation as 1.0.2 does
    assert y["system_gain"]["value"] == pytest.approx(0.2800626, rel=0.01)
    assert y["dark_noise_e"]["value"] == pytest.approx(ref["$\\sigma_d$"], rel=0.01)
    assert y["quantum_efficiency"]["value"] == pytest.approx(ref["$\\eta$"], rel=0.01)
    assert y["dark_current_mean_e_s"]["value"] == pytest.approx(ref["$\\mu_{I.mean}$"], rel=0.01)
    assert y["dark_current_var_e_s"]["value"] == pytest.approx(ref["$\\mu_{I.var}$"], rel=0.02)
    assert y["dsnu_e"]["total"]["value"] == pytest.approx(0.5532, rel=0.01)
    assert y["prnu_percent"]["total"]["value"] == pytest.approx(0.4327, rel=0.01)
    assert y["snr_max"]["value"] == pytest.approx(ref["$SNR_{max}$"], rel=0.01)


def test_ccd_r4_results_are_json_and_render_as_html_with_a_plot(ccd):
    e, _ = ccd
    json.dumps(e)
    page = emva1288_r4_html(e)
    assert "System gain K" in page and "DSNU row" in page and "PRNU column" in page
    pytest.importorskip("matplotlib")
    png = emva1288_r4_figure(e)
    assert png and len(png) > 10_000


def test_not_applicable_is_a_sentence():
    assert "not applicable (no flats)" in emva1288_r4_html({"not_applicable": "no flats"})
    assert emva1288_r4_figure({"not_applicable": "no flats"}) is None
