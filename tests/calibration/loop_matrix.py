"""Detection matrix of the calibration loop on hidden-effect capture sets (shared by the slow
test and ``benchmarks/loop_detection_matrix.py``)."""

from __future__ import annotations

import numpy as np

from loop_generator import DEFAULT_EFFECTS, EFFECTS, SensorSpec, capture_set

PAIRS = (
    ("row_noise", "column_fpn"),
    ("dsnu", "hot_pixels"),
    ("prnu", "nonlinearity"),
    ("quantization", "heavy_tail_read"),
    ("periodic_pattern", "frame_flicker"),
    ("channel_gain", "black_level_offset"),
    ("spatial_correlation", "dsnu"),
    ("column_fpn", "dsnu"),
    ("hot_pixels", "heavy_tail_read"),
    ("row_noise", "periodic_pattern"),
    ("black_level_offset", "column_fpn"),
    ("prnu", "channel_gain"),
    ("rtn", "hot_pixels"),
    ("rtn", "heavy_tail_read"),
    ("dark_current", "amp_glow"),
    ("adc_dnl", "heavy_tail_read"),
)
CASES = ((),) + tuple((e,) for e in EFFECTS) + PAIRS


def in_memory_capture(caps: dict):
    from simcam.calibration.capture import CaptureSet, Sequence

    seqs = [Sequence(name, kind, fr, meta["iso"], meta["exposure_s"], meta["cfa"],
                     np.full((2, 2), float(meta["black_level"])), meta["white_level"])
            for name, (kind, fr, meta) in caps.items()]
    return CaptureSet("memory", "directory", seqs)


def scaled(effect: str, scale: float) -> dict:
    """``DEFAULT_EFFECTS[effect]`` with its magnitude scaled (shape parameters kept; quantisation
    and Tukey shape moved towards their no-effect values 1 and 0.14)."""
    p = dict(DEFAULT_EFFECTS[effect])
    if scale == 1.0:
        return p
    for k in ("sigma_dn", "sigma", "amplitude_dn", "offset_dn", "mean_dn", "a", "c", "rate_e_per_s"):
        if k in p:
            p[k] = p[k] * scale
    if "gains" in p:
        p["gains"] = [1 + (g - 1) * scale for g in p["gains"]]
    if "lam" in p:
        p["lam"] = 0.14 + (p["lam"] - 0.14) * scale
    if "step_dn" in p:
        p["step_dn"] = max(1, round(1 + (p["step_dn"] - 1) * scale))
    return p


def run_case(effects: tuple, seed: int = 7, scale: float = 1.0, threads: int | None = None, **spec_kw):
    from simcam.calibration.loop import LoopConfig, run_loop

    spec = SensorSpec(effects={e: scaled(e, scale) for e in effects}, **spec_kw)
    return run_loop(in_memory_capture(capture_set(spec, seed=seed)), LoopConfig(threads=threads))[0]


def matrix(cases=CASES):
    rows = []
    for case in cases:
        r = run_case(case)
        rows.append({"hidden": case, "named": tuple(r.model.effects),
                     "unexplained": tuple(u["diagnostic"] for u in r.unexplained),
                     "kl_base": r.heldout_base["kl"], "kl_final": r.heldout_final["kl"],
                     "kl_structured_base": r.heldout_base["kl_structured"],
                     "kl_structured_final": r.heldout_final["kl_structured"],
                     "ok": set(case) == set(r.model.effects) and not r.unexplained})
    return rows
