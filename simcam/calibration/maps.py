"""Measured fixed patterns kept beside the profile (``simcam loop --maps``).

The loop's effects describe a sensor's fixed patterns by their statistics (a DSNU sigma, a PRNU
sigma, a column-FPN sigma, a hot-pixel share), and the noise stage draws a new pattern of that law
from the sensor seed: a camera of the same *model*. With ``--maps`` the profile keeps *this*
sensor's patterns, measured on the whole frame (EMVA 1288 Release 4.0, sec. 8: the dark and the
bright temporal-mean images, from which the standard's DSNU and PRNU are computed; A. Abdelhamed,
*Noise Modelling for Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 3: noise
parameters measured per sensor), in ``maps.npz`` beside ``profile.yaml``:

* ``iso<N>_dark_offset`` (normalised raw): the temporal-mean image of the darks at the shortest
  exposure time minus its per-CFA-site median: DSNU, column offsets and hot pixels as this sensor
  has them. It replaces the model's ``dsnu``, ``column_fpn`` and ``hot_pixels`` entries by one
  ``empirical_offset`` ``{axis: pixel, map}`` entry (a hot pixel keeps its level at that exposure:
  its growth with the exposure time is not in the map).
* ``iso<N>_flat_gain`` (around 1): the flat's temporal-mean image minus the dark's, divided by its
  per-site median: PRNU as this sensor has it. It replaces ``prnu`` by ``empirical_gain``
  ``{axis: pixel, map}``.

* ``iso<N>_dark_rate`` (normalised raw per second, >= 0): with darks at two exposure times or more, each
  pixel's least-squares slope of its temporal-mean dark level against the exposure time (EMVA 1288
  Release 4.0, sec. 8.4: the dark signal's rise with the exposure time, here per pixel), less the rise
  the model's ``dark_current`` does not count as charge (``non_poisson_dn_per_s``): the dark current's
  non-uniformity and the amplifier glow as this sensor has them. It replaces ``dark_current`` and
  ``amp_glow`` by one ``empirical_field`` entry (Poisson electrons of that mean, ``electron`` the dark
  current's gain), and the dark offset map above becomes the intercept at zero exposure (so a hot
  pixel's rate is not counted twice).

Each map also holds the temporal noise of its frames' mean (variance sigma_t^2 / n per pixel, as
the standard's images do): with 16 dark frames and a DSNU comparable to the read noise, about 6 %
of the map's variance. A map is written only for an effect the loop added; an ISO without the frames
it needs keeps its parametric entries (the profile's notes say which).
"""

from __future__ import annotations

import numpy as np

from .diagnostics import exposure_slope, plane_medians

#: effects a dark offset map replaces, those a flat gain map replaces, and those a dark-rate map replaces
DARK_EFFECTS = ("dsnu", "column_fpn", "hot_pixels")
FLAT_EFFECTS = ("prnu",)
RATE_EFFECTS = ("dark_current", "amp_glow")
MAPS_FILE = "maps.npz"


def _site_median(m: np.ndarray, cfa: bool) -> np.ndarray:
    """Each CFA site's median as a map (:func:`diagnostics.plane_medians`); a monochrome frame's median."""
    return plane_medians(m) if cfa else np.full(m.shape, np.median(m))


def _mosaic(stats: list, cfa: str | None, shape: tuple[int, int]) -> np.ndarray:
    """The whole-frame temporal-mean image from the EMVA 1288 point statistics' per-channel mean maps."""
    from .emva1288 import cfa_channels

    out = np.empty(shape)
    for st, (_name, dy, dx) in zip(stats, cfa_channels(cfa)):
        step = 2 if cfa is not None else 1
        out[dy::step, dx::step] = st.mean_map
    return out


def _exposure(s) -> float:
    return float(s.exposure_s) if s.exposure_s is not None else -1.0


def dark_slope(darks: list) -> tuple[np.ndarray, np.ndarray] | None:
    """(slope DN/s, intercept DN) per pixel of the darks' temporal-mean images against their exposure
    times (the sequences of one time pooled, frame-weighted; :func:`diagnostics.exposure_slope`, the
    loop's dark-current fit's estimator); None with fewer than two exposure times."""
    by_t: dict[float, list] = {}
    for s in darks:
        if _exposure(s) >= 0:
            by_t.setdefault(float(s.exposure_s), []).append(s)
    if len(by_t) < 2:
        return None
    times = sorted(by_t)
    maps = [sum(s.n * s.stats().mean_map.astype(np.float64) for s in by_t[t]) / sum(s.n for s in by_t[t])
            for t in times]
    slope, _ = exposure_slope(times, maps)
    return slope, sum(maps) / len(maps) - slope * float(np.mean(times))


def measured_maps(capture, results) -> tuple[dict[str, np.ndarray], dict[int, dict], list[str]]:
    """(arrays for ``maps.npz``, per ISO ``{"replaces": [effect types], "effects": [entries]}``, notes)."""
    arrays: dict[str, np.ndarray] = {}
    per_iso: dict[int, dict] = {}
    notes: list[str] = []
    for r in results:
        m, fs = r.model, r.model.full_scale_dn
        cfa = m.cfa is not None
        group = capture.group(r.iso)
        darks = [s for s in group if s.kind == "dark" and s.stats().mean_map is not None]
        flats = [s for s in group if s.kind == "flat" and s.emva_stats and s.emva_stats[0].mean_map is not None]
        tag = f"iso{int(r.iso)}" if r.iso > 0 else "iso_unknown"
        replaces, effects = [], []
        dark = min(darks, key=_exposure) if darks else None
        intercept = None
        if any(e in m.effects for e in RATE_EFFECTS):
            fit = dark_slope(darks)
            dc = m.effects.get("dark_current")
            gain = float(dc.gain_dn_per_e) if dc is not None and dc.gain_dn_per_e > 0 else float(m.K)
            if fit is None or not gain > 0:
                notes.append(f"ISO {r.iso}: the dark-rate map needs darks at two exposure times or more and a "
                             "system gain: not written")
            else:
                slope, intercept = fit
                rise = slope - (float(dc.non_poisson_dn_per_s) if dc is not None else 0.0)
                arrays[f"{tag}_dark_rate"] = (np.maximum(rise, 0.0) / fs).astype(np.float32)
                replaces += [e for e in RATE_EFFECTS if e in m.effects]
                effects.append({"type": "empirical_field", "field": f"{MAPS_FILE}#{tag}_dark_rate",
                                "electron": gain / fs})
        if any(e in m.effects for e in DARK_EFFECTS):
            if dark is None:
                notes.append(f"ISO {r.iso}: no dark sequence: the dark offset map is not written")
            else:
                dm = dark.stats().mean_map.astype(np.float64) if intercept is None else intercept
                arrays[f"{tag}_dark_offset"] = ((dm - _site_median(dm, cfa)) / fs).astype(np.float32)
                replaces += [e for e in DARK_EFFECTS if e in m.effects]
                effects.append({"type": "empirical_offset", "axis": "pixel", "map": f"{MAPS_FILE}#{tag}_dark_offset"})
        if any(e in m.effects for e in FLAT_EFFECTS):
            if not flats or dark is None:
                notes.append(f"ISO {r.iso}: the flat gain map needs a flat with its exposure time and a dark: not "
                             "written")
            else:
                f = max(flats, key=lambda s: s.n)
                same_t = [s for s in darks if _exposure(s) == _exposure(f)]
                base = (same_t[0] if same_t else dark).stats().mean_map.astype(np.float64)
                resp = _mosaic(f.emva_stats, m.cfa, base.shape) - base
                med = _site_median(resp, cfa)
                if not np.all(med > 0):
                    notes.append(f"ISO {r.iso}: the flat is not above the dark level on every CFA site: the flat "
                                 "gain map is not written")
                else:
                    arrays[f"{tag}_flat_gain"] = (resp / med).astype(np.float32)
                    replaces += [e for e in FLAT_EFFECTS if e in m.effects]
                    effects.append({"type": "empirical_gain", "axis": "pixel", "map": f"{MAPS_FILE}#{tag}_flat_gain"})
        if replaces:
            per_iso[r.iso] = {"replaces": replaces, "effects": effects}
    return arrays, per_iso, notes
