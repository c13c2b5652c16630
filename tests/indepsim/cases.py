"""Named test cases: base sensors, every effect alone, pairs, undeclared effects, special sets.

Each case is a dict ``name, effects (list of names), seed, held_out, overrides``; its
magnitudes are NOT fixed: :func:`case_spec` draws each effect's parameters from the effect's
documented range (``Effect.ranges``; log-uniform for ``Effect.log_params``) with
``numpy.random.default_rng([seed, crc32(name)])``, so a case at another seed has other magnitudes.

Held-out rule: ``held_out = int(sha256(name).hexdigest()[:8], 16) % 10 < 3`` (about 30 %),
fixed by the name alone. Loop developers must not tune on held-out cases.
"""

from __future__ import annotations

import hashlib
import zlib

import numpy as np

from .effects import NAMED_NEW, NAMED_OLD, REGISTRY, UNDECLARED


def held_out(name: str) -> bool:
    return int(hashlib.sha256(name.encode()).hexdigest()[:8], 16) % 10 < 3


def _case(name, effects=(), seed=0, **overrides):
    return {"name": name, "effects": list(effects), "seed": int(seed), "held_out": held_out(name),
            "overrides": overrides}


OLD_NEW_PAIRS = [
    ("dsnu", "dark_current"), ("hot_pixels", "dark_current"), ("prnu", "charge_crosstalk"),
    ("spatial_correlation", "charge_crosstalk"), ("quantization", "adc_dnl"), ("heavy_tail_read", "rtn"),
    ("column_fpn", "amp_glow"), ("row_noise", "rtn"), ("black_level_offset", "dead_pixels"),
    ("hot_pixels", "stuck_pixels"), ("nonlinearity", "charge_crosstalk"), ("frame_flicker", "amp_glow"),
    ("channel_gain", "dead_pixels"), ("periodic_pattern", "dark_current"),
]
NEW_NEW_PAIRS = [
    ("dark_current", "amp_glow"), ("dead_pixels", "stuck_pixels"), ("rtn", "adc_dnl"),
    ("charge_crosstalk", "dark_current"), ("amp_glow", "rtn"), ("stuck_pixels", "charge_crosstalk"),
    ("adc_dnl", "dark_current"),
]
UNDECLARED_PAIRS = [
    ("undeclared_column_temporal", "column_fpn"), ("undeclared_gain_drift", "frame_flicker"),
    ("undeclared_black_drift", "black_level_offset"), ("undeclared_interleaved_adc", "channel_gain"),
    ("undeclared_row_1f", "row_noise"), ("undeclared_pixel_nonlinearity", "prnu"),
    ("undeclared_smear", "dark_current"),
]

SUBCODE_8BIT = {"sensor": {"bits": 8, "black_dn": 16.0, "full_well_e": 6000.0, "read_noise_e": 1.5,
                           "adc_noise_dn": 0.45}, "isos": [100, 400]}
MONO = {"sensor": {"cfa": None}, "fmt": "npy"}


def _build():
    cases = [_case(f"base_s{s}", (), seed=s) for s in range(4)]
    cases += [_case(f"alone_{n}", (n,), seed=11) for n in NAMED_OLD + NAMED_NEW + UNDECLARED]
    cases += [_case(f"pair_{a}__{b}", (a, b), seed=12) for a, b in OLD_NEW_PAIRS + NEW_NEW_PAIRS + UNDECLARED_PAIRS]
    cases += [
        _case("triple_dsnu_prnu_dark_current", ("dsnu", "prnu", "dark_current"), seed=13),
        _case("triple_row_column_undeclared_column_temporal", ("row_noise", "column_fpn", "undeclared_column_temporal"),
              seed=13),
        _case("special_8bit_subcode_dark", (), seed=21, **SUBCODE_8BIT),
        _case("special_8bit_subcode_dsnu", ("dsnu",), seed=22, **SUBCODE_8BIT),
        _case("special_mono_npy", ("dark_current",), seed=23, **MONO),
        _case("special_mono_emva", ("dsnu", "prnu"), seed=24, sensor={"cfa": None, "bits": 12},
              fmt="emva", scene=None, isos=[100]),
        _case("special_grbg_npy_perchannel_black", ("channel_gain",), seed=25,
              sensor={"cfa": "GRBG", "black_dn": [[256, 260], [252, 258]]}, fmt="npy"),
        _case("special_darks_only", ("dark_current", "hot_pixels"), seed=26, flats=None, scene=None),
        _case("special_flats_only", ("prnu",), seed=27, darks=None, scene=None),
        _case("special_two_frames", ("dsnu",), seed=28, darks={"exposures_s": [0.02, 2.0], "frames": 2},
              flats={"exposure_s": 0.01, "levels": [0.15, 0.55], "frames": 2},
              scene={"exposure_s": 0.01, "level": 0.4, "frames": 2}),
        _case("special_coarse_quantization_16bit", ("quantization",), seed=29,
              sensor={"bits": 16, "black_dn": 4096.0, "full_well_e": 30000.0}),
        _case("special_14bit_bggr", ("dark_current", "prnu"), seed=30,
              sensor={"bits": 14, "cfa": "BGGR", "black_dn": 1024.0, "full_well_e": 20000.0}),
    ]
    return cases


CASES = _build()


def case_spec(case: dict, seed: int | None = None) -> dict:
    """The capture-set spec of ``case`` with magnitudes drawn at ``seed`` (default: the case's)."""
    seed = case["seed"] if seed is None else int(seed)
    rng = np.random.default_rng([seed, zlib.crc32(case["name"].encode())])
    effects = {n: REGISTRY[n].draw(rng) for n in case["effects"]}
    spec = {k: (dict(v) if isinstance(v, dict) else v) for k, v in case["overrides"].items()}
    spec["effects"] = effects
    spec["case"] = case["name"]
    spec["held_out"] = case["held_out"]
    return spec


def magnitude_ranges() -> dict:
    """``{effect: {param: (lo, hi, "log"|"lin")}}`` for the report."""
    return {n: {k: (lo, hi, "log" if k in c.log_params else "lin") for k, (lo, hi) in c.ranges.items()}
            for n, c in REGISTRY.items()}
