"""Model and effect entries exercised by the torch equivalence tests (one per registered type)."""

NLF4 = {"type": "nlf", "beta1": [1.0e-3, 1.6e-3, 1.2e-3, 2.2e-3], "beta2": [2.0e-5, 1.0e-5, 3.0e-5, 1.5e-5]}
PG4 = {"type": "poisson_gaussian", "beta1": [2.0e-3, 3.0e-3, 2.5e-3, 4.0e-3], "beta2": [2.0e-5, 1.0e-5, 3.0e-5, 1.5e-5]}

#: one entry per registered model type with a torch sampler.
MODEL_CASES = {
    "gaussian": {"type": "gaussian", "sigma": [0.01, 0.02, 0.015, 0.005]},
    "nlf": NLF4,
    "poisson_gaussian": PG4,
    "poisson_mixture": {"type": "poisson_mixture", "beta1": [2.0e-3, 3.0e-3, 2.5e-3, 4.0e-3], "beta2": 2.0e-5,
                        "z1": 0.5, "z2": 3.0, "p1": 0.3},
    "clipped": {"type": "clipped", "base": PG4, "low": 0.0, "high": 0.5},  # exact in float32
    "composite": {"type": "composite", "base": NLF4, "effects": [{"type": "dsnu", "sigma": 0.004}], "sensor_seed": 5},
}

PG1 = {"type": "poisson_gaussian", "beta1": 2.5e-3, "beta2": 2.0e-5}

#: one composite per registered effect type (the effect alone, on a base it needs).
EFFECT_CASES = {
    "row_noise": [{"type": "row_noise", "sigma": 0.004}],
    "column_fpn": [{"type": "column_fpn", "sigma": 0.004}],
    "dsnu": [{"type": "dsnu", "sigma": 0.003}],
    "prnu": [{"type": "prnu", "sigma": 0.05}],
    "hot_pixels": [{"type": "hot_pixels", "hot_fraction": 0.02, "hot_offset": 0.05, "hot_log_sigma": 0.4,
                    "stuck_fraction": 0.01, "stuck_value": 0.9, "dead_fraction": 0.01}],
    # hot pixels as dark charge (what simcam loop writes when their temporal variance shows shot noise)
    "hot_pixels_charge": [{"type": "hot_pixels", "hot_fraction": 0.3, "hot_offset": 0.05, "hot_electron": 0.01}],
    # hot pixels as a local dark current: offset + rate x exposure, Poisson charge (simcam loop with darks at
    # two exposure times)
    "hot_pixels_rate": [{"type": "hot_pixels", "hot_fraction": 0.3, "hot_offset": 0.02, "hot_log_sigma": 0.3,
                         "hot_electron": 0.01, "hot_rate": 0.05, "hot_rate_log_sigma": 0.5}],
    "heavy_tail_read": [{"type": "heavy_tail_read", "lam": -0.2, "scale": 0.002}],
    "quantization": [{"type": "quantization", "range_dn": 200.0, "step_dn": 2.0, "offset_dn": 16.3}],
    "spatial_correlation": [{"type": "heavy_tail_read", "lam": 0.0, "scale": 0.002},
                            {"type": "spatial_correlation", "coefficient": 0.3}],
    # the same kernel on the mosaic: adjacent, different-colour neighbours correlate (what simcam loop fits
    # from adjacent_corr)
    "spatial_correlation_adjacent": [{"type": "spatial_correlation", "coefficient": 0.2, "neighbours": "adjacent"}],
    # electrical crosstalk after the pixel: all the noise at read-out, cross kernel, variance kept
    "spatial_correlation_total": [{"type": "spatial_correlation", "coefficient": 0.12, "neighbours": "adjacent",
                                   "domain": "total"}],
    # oblique bands (read-out interference off the line rate)
    "periodic_pattern_oblique": [{"type": "periodic_pattern", "amplitude": 0.004, "period_px": 6.0, "axis": "rows",
                                  "cross_frequency": 0.07},
                                 {"type": "periodic_pattern", "amplitude": 0.003, "period_px": 9.0, "axis": "columns",
                                  "cross_frequency": -0.04}],
    "periodic_pattern": [{"type": "periodic_pattern", "amplitude": 0.004, "period_px": 7.0, "axis": "columns"},
                         {"type": "periodic_pattern", "amplitude": 0.003, "period_px": 5.0, "axis": "rows",
                          "random_phase": False, "phase": 0.7}],
    "black_level_offset": [{"type": "black_level_offset", "offset": [0.01, -0.005, 0.0, 0.02]}],
    "frame_flicker": [{"type": "frame_flicker", "sigma": 0.05}],
    "nonlinearity": [{"type": "nonlinearity", "strength": 0.3}],
    "channel_gain": [{"type": "channel_gain", "gain": [1.2, 1.0, 0.9, 0.7]}],
    "dead_pixels": [{"type": "dead_pixels", "dead_fraction": 0.02, "stuck_fraction": 0.02, "stuck_value": 0.8}],
    # dead pixels with no photo-response behind a working read-out (what simcam loop fits): black + read noise
    "dead_pixels_read_noise": [{"type": "dead_pixels", "dead_fraction": 0.05, "stuck_fraction": 0.02,
                                "stuck_value": 0.8, "dead_read_noise": True}],
    # stuck pixels at several levels (what simcam loop fits): each one's level drawn per sensor
    "dead_pixels_levels": [{"type": "dead_pixels", "dead_fraction": 0.02, "stuck_fraction": 0.04,
                            "stuck_values": [-0.02, 0.45, 1.0], "dead_read_noise": True}],
    "rtn": [{"type": "rtn", "fraction": 0.1, "amplitude": 0.02, "amplitude_log_sigma": 0.3, "p_high": 0.3}],
    "charge_crosstalk": [{"type": "charge_crosstalk", "coefficient": 0.08, "diagonal": 0.02}],
    "adc_dnl": [{"type": "adc_dnl", "range_dn": 200.0, "offset_dn": 16.0, "bits": 8, "dnl_sigma": 0.3}],
    # a coarse ADC (codes 4 DN apart) with unequal codes, then the quantiser of its grid (a no-op on its codes)
    "adc_dnl_coarse": [{"type": "adc_dnl", "range_dn": 800.0, "offset_dn": 16.0, "bits": 8, "dnl_sigma": 0.3,
                        "step_dn": 4.0},
                       {"type": "quantization", "range_dn": 800.0, "step_dn": 4.0, "offset_dn": 16.0}],
    "empirical_code": [{"type": "empirical_code", "range_dn": 100.0, "offset_dn": 8.0, "first_code": 2,
                        "edges": [float(v) for v in [0.5 + k + 0.3 * ((k * 7919) % 11 - 5) / 5 for k in range(120)]]}],
    "dark_current": [{"type": "dark_current", "rate": 20.0, "dcnu_log_sigma": 0.4, "electron": 2.5e-3,
                      "temperature_c": 35.0, "doubling_c": 7.0}],
    "amp_glow": [{"type": "amp_glow", "rate": 60.0, "origin": "top_right", "scale": 0.3, "electron": 2.5e-3}],
    "empirical_field": [{"type": "empirical_field", "field": [[0.05, 0.1, 0.2], [0.02, 0.04, 0.3]], "electron": 2.5e-3}],
    "empirical_offset": [{"type": "empirical_offset", "axis": "row", "quantiles": [-0.01, -0.002, 0.0, 0.003, 0.02]},
                         {"type": "empirical_offset", "axis": "frame", "temporal": True,
                          "quantiles": [-0.004, 0.0, 0.001, 0.006], "scale": 1.5},
                         {"type": "empirical_offset", "axis": "frame", "temporal": True,  # a level rising with t
                          "quantiles": [-0.002, 0.0, 0.002], "rate": 0.003}],
    "empirical_gain": [{"type": "empirical_gain", "axis": "pixel", "quantiles": [0.9, 0.97, 1.0, 1.02, 1.1]}],
    "empirical_lines": [{"type": "empirical_lines", "axis": "column", "lines": [[0.25, 0.01], [0.1, 0.004]]},
                        {"type": "empirical_lines", "axis": "row", "lines": [[0.125, 0.006]]},
                        # an offset and a gain part (a quarter of a cycle apart), and a gain-only line
                        {"type": "empirical_lines", "axis": "column",
                         "lines": [[0.25, 0.01, 0.02, 1.5708], [0.1, 0.0, 0.01, 0.0]]}],
    "empirical_spectrum": [{"type": "empirical_spectrum", "axis": "row", "frequencies": [0.01, 0.05, 0.2, 0.5],
                            "power": [4e-4, 1e-4, 2e-5, 1e-5]},
                           {"type": "empirical_spectrum", "axis": "column", "frequencies": [0.02, 0.5],
                            "power": [2e-4, 1e-5], "scale": 1.5}],
    "empirical_response": [{"type": "empirical_response", "quantiles": [-0.05, 0.0, 0.05, 0.15, 0.3]}],
}

#: exposure time (seconds) given to both samplers (exposure-dependent effects).
EXPOSURE_S = 2.0


def effect_entry(name: str) -> dict:
    return {"type": "composite", "base": PG1, "effects": EFFECT_CASES[name], "sensor_seed": 11}
