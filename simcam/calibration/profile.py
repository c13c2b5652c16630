"""The loop's fitted models as a calibration profile of simcam's noise stage (``simcam.profiles``, schema 1).

Each ISO becomes a ``composite`` entry: a ``poisson_gaussian`` base on normalised raw
(beta1 = K / (white - black), beta2 = read^2 / (white - black)^2, Abdelhamed, PhD dissertation, York University, 2020, eq. 3.6) and the effects
in the noise stage's parameterisation (normalised raw offsets, dimensionless gains), in signal-chain
order: signal effects (prnu, frame_flicker), then readout effects: heavy-tailed read noise,
crosstalk (on shot + read noise), row and periodic noise, the response (nonlinearity, on the noisy
value), fixed offsets, quantisation last.

The same entry is what the loop's bootstrap samples (:mod:`simcam.calibration.simulate`), so the
noise stage given ``profile.yaml`` draws the noise the loop fitted. Conversions:

* ``heavy_tail_read``: the read noise *is* Tukey-lambda with the read variance: beta2 = 0 and
  ``scale = read / sqrt(var(TukeyLambda(lam)))``.
* ``spatial_correlation``: the loop's ``a`` is the noise stage's ``coefficient`` (same kernel).
* ``nonlinearity``: ``strength = -c`` (``y = x + c x^2 / (white - black)`` in DN).
* ``hot_pixels``: the loop's log-normal fit (``log_mean``, ``log_sigma`` of the offsets in DN) is the
  noise stage's ``hot_offset`` = its mean exp(log_mean + log_sigma^2 / 2) / (white - black) and
  ``hot_log_sigma`` = log_sigma (the same log-normal).
* ``channel_gain``: the loop's per-site gain acts after photon counting (it changes the
  variance-to-mean ratio), so it is written as per-site ``beta1`` of the base, not as the noise
  stage's ``channel_gain`` effect (which scales the expected signal, i.e. a QE difference).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .model import LoopModel, tukey_var

SIGNAL_ORDER = ("prnu", "channel_gain", "frame_flicker")
READOUT_ORDER = ("heavy_tail_read", "spatial_correlation", "row_noise", "periodic_pattern", "nonlinearity",
                 "column_fpn", "dsnu", "hot_pixels", "black_level_offset", "quantization")


def noise_entry(model: LoopModel) -> tuple[dict, list[str]]:
    """(composite model entry for the noise stage, notes on approximations)."""
    fs = model.full_scale_dn
    e = model.effects
    notes = []
    beta1 = float(model.K / fs)
    beta2 = float(model.read_dn ** 2 / fs ** 2)
    effects = []
    for name in SIGNAL_ORDER:
        if name not in e:
            continue
        p = e[name]
        if name == "prnu":
            effects.append({"type": "prnu", "sigma": float(p["sigma"])})
        elif name == "channel_gain":  # a gain after photon counting: per-site beta1 (var / mean changes)
            beta1 = [float(model.K * g / fs) for g in p["gains"]]
        elif name == "frame_flicker":
            effects.append({"type": "frame_flicker", "sigma": float(p["sigma"])})
    for name in READOUT_ORDER:
        if name not in e:
            continue
        p = e[name]
        if name == "spatial_correlation":
            effects.append({"type": "spatial_correlation", "coefficient": float(p["a"])})
        elif name == "nonlinearity":
            effects.append({"type": "nonlinearity", "strength": float(np.clip(-p["c"], -0.45, 0.45))})
        elif name == "heavy_tail_read":
            scale = model.read_dn / np.sqrt(tukey_var(p["lam"])) / fs
            effects.append({"type": "heavy_tail_read", "lam": float(p["lam"]), "scale": float(scale)})
            beta2 = 0.0
        elif name == "row_noise":
            effects.append({"type": "row_noise", "sigma": float(p["sigma_dn"] / fs)})
        elif name == "periodic_pattern":
            effects.append({"type": "periodic_pattern", "amplitude": float(p["amplitude_dn"] / fs),
                            "period_px": float(p["period_px"]),
                            "axis": "rows" if p.get("axis", "row") == "row" else "columns", "random_phase": True})
        elif name in ("column_fpn", "dsnu"):
            effects.append({"type": name, "sigma": float(p["sigma_dn"] / fs)})
        elif name == "hot_pixels":
            mean = float(np.exp(p["log_mean"] + p["log_sigma"] ** 2 / 2))
            effects.append({"type": "hot_pixels", "hot_fraction": float(p["fraction"]), "hot_offset": mean / fs,
                            "hot_log_sigma": float(p["log_sigma"])})
        elif name == "black_level_offset":
            effects.append({"type": "black_level_offset", "offset": [float(x) / fs for x in p["offset_dn"]]})
        elif name == "quantization":
            effects.append({"type": "quantization", "range_dn": float(fs), "step_dn": float(p["step_dn"]),
                            "offset_dn": float(np.mean(model.black_dn))})
    base = {"type": "poisson_gaussian", "beta1": beta1, "beta2": beta2}
    if not effects:
        return base, notes
    return {"type": "composite", "base": base, "effects": effects}, notes


def noise_profile(results, capture, camera_id: str | None = None) -> dict:
    """A ``simcam.profiles`` schema-1 document of the final models (one camera, one entry per ISO)."""
    first = results[0].model
    entries, notes = [], []
    for r in results:
        entry, n = noise_entry(r.model)
        iso = float(r.iso) if r.iso > 0 else 100.0
        if r.iso <= 0:
            notes.append("ISO unknown in the data: entry stored at ISO 100")
        entries.append({"iso": iso, "model": entry})
        notes += [f"ISO {r.iso}: {x}" for x in n]
    return {
        "schema_version": 1,
        "provenance": {"source": str(capture.root), "method": "simcam loop: photon-transfer base fit, residual "
                       "diagnostics with parametric bootstrap, effect attribution and refit",
                       "tool": "simcam loop", "created": "", "licence": "", "notes": "; ".join(notes)},
        "cameras": [{
            "id": camera_id or Path(str(capture.root)).name or "camera",
            "make": "", "model": "",
            "cfa": first.cfa,
            "black_level_dn": float(np.mean(first.black_dn)),
            "white_level_dn": float(first.white_dn),
            "entries": entries,
        }],
    }


def models_from_noise_profile(doc: dict, where: str) -> dict[int, LoopModel]:
    """Inverse of :func:`noise_profile` (for ``--start-profile``): LoopModels per ISO."""
    from ..errors import ProfileError

    try:
        cam = doc["cameras"][0]
        white = float(cam["white_level_dn"])
        black = float(cam["black_level_dn"])
    except (KeyError, IndexError, TypeError, ValueError):
        raise ProfileError(f"{where}: cameras[0]: white_level_dn and black_level_dn are needed to start the loop "
                           "from a noise profile") from None
    fs = white - black
    out = {}
    for i, ent in enumerate(cam.get("entries") or []):
        m = ent.get("model") or {}
        base = m.get("base", m) if m.get("type") == "composite" else m
        if base.get("type") not in ("poisson_gaussian", "nlf"):
            raise ProfileError(f"{where}: cameras[0].entries[{i}].model: type {base.get('type')!r}; expected "
                               "poisson_gaussian or nlf (or a composite of one)")
        b1_sites = np.broadcast_to(np.asarray(base["beta1"], dtype=np.float64), (4,))
        b1 = float(np.mean(b1_sites))
        b2 = float(np.mean(base["beta2"]))
        effects: dict = {}
        if np.ptp(b1_sites) > 0:
            effects["channel_gain"] = {"gains": [float(x) for x in b1_sites / b1]}
        read = np.sqrt(b2) * fs
        for eff in m.get("effects", []) if m.get("type") == "composite" else []:
            t = eff["type"]
            if t == "prnu" or t == "frame_flicker":
                effects[t] = {"sigma": float(eff["sigma"])}
            elif t == "channel_gain":
                effects[t] = {"gains": list(np.broadcast_to(np.asarray(eff["gain"], float), (4,)))}
            elif t == "nonlinearity":
                effects[t] = {"c": -float(eff["strength"])}
            elif t == "spatial_correlation":
                effects[t] = {"a": float(eff["coefficient"])}
            elif t == "heavy_tail_read":
                effects[t] = {"lam": float(eff["lam"])}
                read = float(np.sqrt(read ** 2 + (eff["scale"] * fs) ** 2 * tukey_var(eff["lam"])))
            elif t in ("row_noise", "column_fpn", "dsnu"):
                effects[t] = {"sigma_dn": float(eff["sigma"]) * fs}
            elif t == "periodic_pattern":
                effects[t] = {"amplitude_dn": float(eff["amplitude"]) * fs, "period_px": float(eff["period_px"]),
                              "axis": "row" if eff.get("axis", "rows") == "rows" else "col"}
            elif t == "hot_pixels":
                ls = float(eff.get("hot_log_sigma", 0.0))
                effects[t] = {"fraction": float(eff.get("hot_fraction", 0.0)),
                              "log_mean": float(np.log(max(eff.get("hot_offset", 0.05) * fs, 1e-6)) - ls * ls / 2),
                              "log_sigma": ls}
            elif t == "black_level_offset":
                effects[t] = {"offset_dn": list(np.broadcast_to(np.asarray(eff["offset"], float) * fs, (4,)))}
            elif t == "quantization":
                effects[t] = {"step_dn": float(eff.get("step_dn", 1.0))}
        lm = LoopModel(cam.get("cfa"), np.full((2, 2), black), white, b1 * fs, float(read), 0.0, effects=effects)
        q = lm.q
        lm.var_dark_dn2 = lm.read_dn ** 2 + q ** 2 / 12 + effects.get("row_noise", {}).get("sigma_dn", 0.0) ** 2 + \
            (effects["periodic_pattern"]["amplitude_dn"] ** 2 / 2 if "periodic_pattern" in effects else 0.0)
        out[int(round(float(ent["iso"])))] = lm
    return out
