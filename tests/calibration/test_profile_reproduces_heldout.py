"""An independent check of a calibration: ``simcam synth`` from the loop's ``profile.yaml`` gives dark and
flat frames whose statistics match held-out measured frames within their sampling error.

The capture set and the held-out frames come from ``tests/indepsim`` (a simulator written by another
hand than the loop), the held-out frames from a *different* sensor of the same law (another sensor
seed: a profile without measured maps carries the laws of the fixed patterns, not this sensor's
maps). Synthesis goes through :func:`simcam.synth.synth` with the noise stage, as ``simcam synth``
does, and the frames are read back with rawpy. The statistics (:mod:`frame_stats`, numpy only) are
what a sensor engineer compares: the mean, temporal variance, row / column / pixel spread of the
mean map, its outliers, the tail of the temporal residuals and the code occupancy, for darks at the
capture's two exposure times and flats at its two levels, at the same ISO, exposure time and clean
level as the measured ones. The profile is synthesised as three sensors (three ``sensor_seed``s): the
measured sensor is one draw of the law, and so is each synthesised one, so a statistic that rests on a
few pixels (the spread of a map with 12 hot pixels where the law gives 33 +- 6) is compared with the
spread of the synthesised sensors, not with one sensor's sampling error alone.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from frame_stats import compare, sequence_stats

from tests.indepsim.capture import write_capture_set
from tests.indepsim.sensor import SensorModel, SensorSpec

rawpy = pytest.importorskip("rawpy")

ISO = 800
#: effects of the independent simulator (its own names and units), magnitudes inside its documented
#: ranges (tests/indepsim/effects.py) and spread over them from case to case
CASES = {
    "row_dsnu_column": {"row_noise": {"sigma_e": 1.0}, "dsnu": {"sigma_dn": 1.5}, "column_fpn": {"sigma_dn": 1.0}},
    "dark_current_prnu": {"dark_current": {"rate_e_per_s": 8.0, "spread": 0.4}, "prnu": {"sigma_rel": 0.01}},
    "hot_pixels_growing_heavy_tail": {"hot_pixels": {"fraction": 0.002, "offset_e": 60.0, "rate_e_per_s": 30.0},
                                      "heavy_tail_read": {"nu": 4.0}},
    "quantization_black_offset": {"quantization": {"step_dn": 4.0}, "black_level_offset": {"offset_dn": 3.0}},
    "dead_stuck_column": {"dead_pixels": {"fraction": 0.003}, "stuck_pixels": {"fraction": 0.002, "white_share": 0.5},
                          "column_fpn": {"sigma_dn": 2.0}},
}
#: combined standard errors a statistic may differ by (14 statistics x 4 sequences per case)
Z_MAX = 5.0
#: sensor seeds the profile is synthesised with: a profile carries the laws of the fixed patterns, and one
#: sensor's draw of them (its count of hot pixels, say) is a matter of chance like the measured sensor's
SENSORS = (0, 1, 2)


def _measured(model: SensorModel, kind: str, t: float, mean_e: float, n: int, seed: int) -> np.ndarray:
    flux = mean_e / t
    return np.stack([model.frame(kind, ISO, t, flux, np.random.default_rng([seed, i]), i, n).astype(np.float64)
                     for i in range(n)])


def _synthesised(profile, sp: SensorSpec, clean_dn: np.ndarray, t: float, n: int, out) -> np.ndarray:
    from simcam.frame import CameraMeta, RawFrame
    from simcam.stages.noise import Noise
    from simcam.synth import synth

    black, white = float(sp.black_dn), float(2 ** sp.bits - 1)
    meta = CameraMeta(cfa=sp.cfa, black_level=np.full((1, 1), black), white_level=white, iso=float(ISO),
                      exposure_time_s=t)
    clean = RawFrame(((clean_dn - black) / (white - black)).astype(np.float32), meta, kind="raw")
    synth(clean, out, stage=Noise(profile=str(profile), iso=ISO), frames=n, seed=5)
    frames = []
    for i in range(n):
        with rawpy.imread(str(out / f"frame_{i:03d}.dng")) as r:
            frames.append(r.raw_image_visible.astype(np.float64))
    return np.stack(frames)


def _with_sensor_seed(profile, seed: int, out):
    """A copy of ``profile.yaml`` whose noise models draw the fixed patterns of sensor ``seed``."""
    import yaml

    doc = yaml.safe_load(profile.read_text())
    for cam in doc["cameras"] if isinstance(doc["cameras"], list) else [doc["cameras"]]:
        entries = cam["entries"] if isinstance(cam["entries"], list) else [cam["entries"]]
        for e in entries:
            if e["model"].get("type") == "composite":
                e["model"]["sensor_seed"] = seed
    out.mkdir(parents=True, exist_ok=True)
    (out / "profile.yaml").write_text(yaml.safe_dump(doc))
    for extra in profile.parent.glob("*.npz"):  # measured maps beside it
        (out / extra.name).write_bytes(extra.read_bytes())
    return out / "profile.yaml"


def _over_sensors(stats: list[dict]) -> dict:
    """Statistics of the synthesised sensors as one prediction ``(mean, sd)`` for another sensor of the
    same law: the sd of a new draw from the spread of the k sensors' values (their sampling noise and
    their fixed-pattern draws), ``sd sqrt(1 + 1/k)``, at least the sensors' own sampling error. A statistic
    some sensor does not have (the outliers' level, with fewer than 5 outliers) is left out."""
    out = {}
    for name in set.intersection(*(set(s) for s in stats)):
        v = np.array([s[name][0] for s in stats])
        se = np.array([s[name][1] for s in stats])
        sd = max(float(v.std(ddof=1)), float(np.sqrt(np.mean(se * se))))
        out[name] = (float(v.mean()), sd * float(np.sqrt(1 + 1 / v.size)))
    return out


def _site_means(x: np.ndarray) -> np.ndarray:
    """The 2x2-site medians of an image (the level of a site's pixels, defects aside), tiled back to its shape."""
    h, w = x.shape
    cell = np.array([[np.median(x[dy::2, dx::2]) for dx in (0, 1)] for dy in (0, 1)])
    return np.tile(cell, (h // 2, w // 2))


@pytest.mark.parametrize("case", list(CASES))
def test_synth_from_the_loop_profile_matches_held_out_frames(case, tmp_path):
    from simcam.calibration.loop import LoopConfig
    from simcam.calibration.report import run_and_write

    effects = CASES[case]
    spec = {"effects": effects, "isos": [ISO], "scene": None}
    write_capture_set(tmp_path / "set", spec, seed=3)
    run_and_write(tmp_path / "set", tmp_path / "out", cfg=LoopConfig(progress=False))
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    profiles = [_with_sensor_seed(tmp_path / "out" / "profile.yaml", k, tmp_path / f"sensor{k}") for k in SENSORS]

    sp = SensorSpec()
    held_out = SensorModel(sp, effects, seed=1234)  # another sensor of the same law
    sat = sp.saturation_e(ISO)
    black = float(sp.black_dn)
    failures = []
    for t in (0.02, 2.0):
        m = _measured(held_out, "dark", t, 0.0, 16, seed=77)
        s = _over_sensors([sequence_stats(_synthesised(p, sp, np.full(m.shape[1:], black), t, 16, p.parent / f"dark_{t}"))
                           for p in profiles])
        failures += [(f"dark {t} s", r) for r in compare(sequence_stats(m), s, z_max=Z_MAX)]
    dark = _measured(held_out, "dark", 0.01, 0.0, 12, seed=78).mean(0)
    for level in (0.15, 0.55):
        m = _measured(held_out, "flat", 0.01, level * sat, 12, seed=79)
        clean = black + _site_means(m.mean(0) - dark)  # the measured signal per CFA site above the dark level
        s = _over_sensors([sequence_stats(_synthesised(p, sp, clean, 0.01, 12, p.parent / f"flat_{level}"))
                           for p in profiles])
        failures += [(f"flat {level:.0%}", r) for r in compare(sequence_stats(m), s, z_max=Z_MAX)]
    bad = [f"{seq} {r['stat']}: measured {r['measured']:.4g}, synthesised {r['synthesised']:.4g} (z {r['z']:.1f})"
           for seq, r in failures if not r["ok"]]
    assert not bad, f"{case} (loop added {report['isos'][0]['effects']}): " + "; ".join(bad)
