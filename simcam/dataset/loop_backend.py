"""Simulating the loop's model with simcam's own noise stage (``simcam.noise`` composite models).

:func:`simulate_simcam` draws the same sequences as :func:`simcam.dataset.loop_model.simulate`
through :func:`simcam.dataset.loop_profile.noise_entry` (the profile entry the loop writes)
and ``Composite.sample`` on normalised raw, then maps back to DN: per-site black differences
become a ``black_level_offset``, the ADC is the noise stage's ``quantization`` effect (step 1 DN
when the model has none) on the mean black level, and values are clipped to [0, white].

Semantics differ from the loop's reference simulator for two effects (see ``loop_profile``):
``nonlinearity`` acts on the expected signal only (no photon-transfer curvature), and
``spatial_correlation`` couples all noise (shot noise included) and inflates its variance by
1 + 4c^2 (compensated in beta2 for the read noise).
"""

from __future__ import annotations

import numpy as np

from .loop_model import LoopModel, SimSpec
from .loop_profile import noise_entry


def composite_for(model: LoopModel, sensor_seed: int):
    """The noise-stage composite model equivalent to ``model`` (normalised raw)."""
    from ..noise.base import model_from_entry

    entry, _notes = noise_entry(model)
    if entry["type"] != "composite":
        entry = {"type": "composite", "base": entry, "effects": []}
    fs = model.full_scale_dn
    effects = [dict(e) for e in entry["effects"]]
    black = np.asarray(model.black_dn, dtype=np.float64).ravel()
    site = (black - black.mean()) / fs
    if np.any(np.abs(site) > 0):
        found = [e for e in effects if e["type"] == "black_level_offset"]
        if found:
            found[0]["offset"] = [float(a + b) for a, b in zip(found[0]["offset"], site)]
        else:
            effects.append({"type": "black_level_offset", "offset": [float(x) for x in site]})
    if not any(e["type"] == "quantization" for e in effects):
        effects.append({"type": "quantization", "range_dn": float(fs), "step_dn": 1.0, "offset_dn": float(black.mean())})
    c = next((e["coefficient"] for e in effects if e["type"] == "spatial_correlation"), 0.0)
    base = dict(entry["base"])
    base["beta2"] = float(base["beta2"]) / (1 + 4 * c * c)
    for e in effects:
        if e["type"] == "heavy_tail_read":
            e["scale"] = float(e["scale"]) / np.sqrt(1 + 4 * c * c)
    return model_from_entry({"type": "composite", "base": base, "effects": effects, "sensor_seed": int(sensor_seed)},
                            where="loop model")


def simulate_simcam(model: LoopModel, spec: SimSpec, rng, sensor: dict) -> np.ndarray:
    """(n, H, W) float32 DN frames of one sequence drawn by simcam's noise stage."""
    from ..noise.base import NoiseCondition

    fs = model.full_scale_dn
    comp = sensor.setdefault("composite", composite_for(model, sensor["seed"]))
    if spec.fixed_in_clean:  # scene whose clean already holds the fixed pattern: drop fixed-pattern effects
        keep = [e for e in comp.effects if e.type not in ("dsnu", "column_fpn", "prnu", "hot_pixels")]
        comp = comp.model_copy(update={"effects": keep})
    clean = (np.maximum(spec.signal_dn, 0.0) / fs).astype(np.float32)
    cond = NoiseCondition(cfa=model.cfa or "RGGB", source="loop simulation")
    black = float(np.mean(model.black_dn))
    out = np.empty((spec.n,) + clean.shape, dtype=np.float32)
    for i in range(spec.n):
        x = comp.sample(clean, cond, rng).astype(np.float64)
        out[i] = np.clip(np.round(x * fs + black, 6), 0, model.white_dn)
    return out
