"""Numbers in the loop's report as a person reads them: units, precision, the ISO as the data give it."""

from simcam.calibration.report import format_parameters, iso_label


def test_parameters_carry_units_and_three_significant_digits():
    assert format_parameters("row_noise", {"sigma_dn": 2.661862129850693}) == "sigma_dn = 2.66 DN"
    assert format_parameters("prnu", {"sigma": 0.010014455}) == "sigma = 1 %"
    assert format_parameters("periodic_pattern", {"amplitude_dn": 1.25, "period_px": 16.0, "axis": "row"}) == \
        "amplitude_dn = 1.25 DN; period_px = 16 px; axis = row"
    assert format_parameters("black_level_offset", {"offset_dn": [2.75, 2.5, 2.75, 3.0]}) == "offset_dn = [2.75, 2.5, 2.75, 3] DN"
    assert format_parameters("hot_pixels", {"fraction": 2.5e-6, "log_mean": 4.0, "log_sigma": 0.5}) == \
        "fraction = 0.00025 %; log_mean = 4 ln DN; log_sigma = 0.5 ln DN"
    assert format_parameters("spatial_correlation", {"a": 1.5e-7}) == "a = 1.5e-07"


def test_iso_label():
    assert iso_label(800) == "ISO 800"
    assert iso_label(0) == "ISO not given"
