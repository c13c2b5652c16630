"""The loop's parametric bootstrap drawn by simcam's noise stage (``simcam.noise`` composite models).

A thin adapter, no noise physics of its own: the fitted :class:`LoopModel` becomes the
composite entry of :func:`simcam.calibration.profile.noise_entry` (the one written to
``profile.yaml``) plus what the capture's ADC adds to the noise stage's normalised raw:

* per-site black-level differences, as a ``black_level_offset`` (before quantisation);
* a 1-DN ``quantization`` on the mean black level when the model has no ADC effect (``quantization``,
  ``adc_dnl``);
* DN = normalised * (white - black) + black, clipped to [0, white].

The expected signal a sequence is simulated from is the measured one taken back through the
response (:func:`simcam.calibration.model.linear_signal`). Frames of a sequence come from
``Composite.sample_frames`` (fixed patterns drawn once per simulated sensor, base noise of all
frames in one kernel pass); each call of :func:`simulate_capture` is a new sensor (sensor seed
drawn from ``rng``). Every sequence is drawn with its own exposure time (``SimSpec.exposure_s``, the
``NoiseCondition``'s), which the exposure-dependent effects (``dark_current``) use.
"""

from __future__ import annotations

import numpy as np

from .effects import CARDS
from .model import LoopModel, SimSpec, linear_signal
from .profile import noise_entry

#: effects whose draw is a fixed pattern (left out when the clean reference already holds it): the cards'
#: ``fixed_pattern`` (an effect's name is its type in the composite entry).
FIXED_EFFECTS = tuple(name for name, card in CARDS.items() if card.fixed_pattern)


#: the effects that are the capture's ADC (the last step of the chain; the loop adds a 1-DN quantiser when
#: the model has none of them)
ADC_EFFECTS = ("quantization", "adc_dnl")


def composite_entry(model: LoopModel) -> dict:
    """The profile's composite entry for ``model`` with the capture's ADC (module docstring)."""
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
            at = next((i for i, e in enumerate(effects) if e["type"] in ADC_EFFECTS), len(effects))
            effects.insert(at, {"type": "black_level_offset", "offset": [float(x) for x in site]})
    if not any(e["type"] in ADC_EFFECTS for e in effects):
        effects.append({"type": "quantization", "range_dn": float(fs), "step_dn": 1.0, "offset_dn": float(black.mean())})
    return {"type": "composite", "base": entry["base"], "effects": effects}


def simulate_capture(model: LoopModel, specs: list[SimSpec], rng) -> list[np.ndarray]:
    """One simulated sensor, all sequences of ``specs``: (n, H, W) float32 DN frames each."""
    from ..noise.base import NoiseCondition, model_from_entry

    entry = composite_entry(model)
    entry["sensor_seed"] = int(rng.integers(0, 2**31))
    comp = model_from_entry(entry, where="loop model")
    bare = None
    fs = model.full_scale_dn
    black = float(np.mean(model.black_dn))
    out = []
    for sp in specs:
        m = comp
        if sp.fixed_in_clean:  # a scene whose clean reference (temporal mean) already holds the fixed patterns
            if bare is None:
                bare = comp.model_copy(update={"effects": [e for e in comp.effects if e.type not in FIXED_EFFECTS]})
            m = bare
        cond = NoiseCondition(cfa=model.cfa or "RGGB", source="loop simulation", exposure_s=float(sp.exposure_s))
        clean = (linear_signal(model, sp.signal_dn) / fs).astype(np.float32)
        x = m.sample_frames(clean, cond, rng, sp.n).astype(np.float64)
        x *= fs
        x += black
        # the composite ends with its quantization: snap the float32 round trip back onto the ADC codes
        out.append(np.clip(model.codes(x), 0, model.white_dn).astype(np.float32))
    return out
