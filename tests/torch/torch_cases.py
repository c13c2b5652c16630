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
    "heavy_tail_read": [{"type": "heavy_tail_read", "lam": -0.2, "scale": 0.002}],
    "quantization": [{"type": "quantization", "range_dn": 200.0, "step_dn": 2.0, "offset_dn": 16.3}],
    "spatial_correlation": [{"type": "heavy_tail_read", "lam": 0.0, "scale": 0.002},
                            {"type": "spatial_correlation", "coefficient": 0.3}],
    "periodic_pattern": [{"type": "periodic_pattern", "amplitude": 0.004, "period_px": 7.0, "axis": "columns"},
                         {"type": "periodic_pattern", "amplitude": 0.003, "period_px": 5.0, "axis": "rows",
                          "random_phase": False, "phase": 0.7}],
    "black_level_offset": [{"type": "black_level_offset", "offset": [0.01, -0.005, 0.0, 0.02]}],
    "frame_flicker": [{"type": "frame_flicker", "sigma": 0.05}],
    "nonlinearity": [{"type": "nonlinearity", "strength": 0.3}],
    "channel_gain": [{"type": "channel_gain", "gain": [1.2, 1.0, 0.9, 0.7]}],
}


def effect_entry(name: str) -> dict:
    return {"type": "composite", "base": PG1, "effects": EFFECT_CASES[name], "sensor_seed": 11}
