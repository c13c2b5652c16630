"""The loop's fitted models as a calibration profile of simcam's noise stage (``simcam.profiles``, schema 1).

Each ISO becomes a ``composite`` entry: a ``poisson_gaussian`` base on normalised raw
(beta1 = K / (white - black), beta2 = read^2 / (white - black)^2, Abdelhamed, PhD dissertation, York University,
2020, eq. 3.6) and the effects in the noise stage's parameterisation (normalised raw offsets,
dimensionless gains), in signal-chain order, the order of the registry
(:data:`simcam.calibration.effects.CARDS`): signal effects (prnu, frame_flicker), then readout
effects: heavy-tailed read noise, crosstalk (on shot + read noise), row and periodic noise, the
response (nonlinearity, on the noisy value), fixed offsets, quantisation last.

The same entry is what the loop's bootstrap samples (:mod:`simcam.calibration.simulate`), so the
noise stage given ``profile.yaml`` draws the noise the loop fitted. Each effect's conversion, in
both directions, is on its card (``EffectCard.to_profile`` / ``from_profile``, the card's module
docstring says what it writes); the ones that are not one-to-one:

* ``heavy_tail_read``: the read noise *is* Tukey-lambda with the read variance: beta2 = 0 and
  ``scale = read / sqrt(var(TukeyLambda(lam)))``.
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

from ..noise.poisson_gaussian import LAMBDA_MAX
from .effects import CARDS
from .model import LoopModel


def noise_entry(model: LoopModel) -> tuple[dict, list[str]]:
    """(composite model entry for the noise stage, notes on approximations)."""
    fs = model.full_scale_dn
    notes = []
    beta1 = float(model.K / fs)
    beta2 = float(model.read_dn ** 2 / fs ** 2)
    effects = []
    for card, p in model.cards():
        term = card.to_profile(p, model)
        if term.beta1 is not None:
            beta1 = term.beta1
        if term.beta2 is not None:
            beta2 = term.beta2
        if term.effect is not None:
            effects.append(term.effect)
    base = {"type": "poisson_gaussian", "beta1": beta1, "beta2": beta2}
    if float(np.min(beta1)) * LAMBDA_MAX <= 1.0:  # no shot noise measured, or > 2^22 e- at white: Gaussian NLF
        base = {"type": "nlf", "beta1": beta1, "beta2": beta2}
        notes.append("gain not measurable or below the Poisson sampler's range: Gaussian NLF base (same variance)")
    if not effects:
        return base, notes
    return {"type": "composite", "base": base, "effects": effects}, notes


#: effect types measured maps go before (the offsets and the ADC end the signal chain)
_MAPS_BEFORE = ("black_level_offset", "quantization", "adc_dnl", "empirical_code")


def with_maps(entry: dict, maps: dict) -> dict:
    """``entry`` (a noise-stage model entry) with the effects ``maps["replaces"]`` names replaced by the
    measured-map entries ``maps["effects"]`` (:mod:`simcam.calibration.maps`)."""
    if entry["type"] != "composite":
        entry = {"type": "composite", "base": entry, "effects": []}
    effects = [e for e in entry["effects"] if e["type"] not in maps["replaces"]]
    at = next((i for i, e in enumerate(effects) if e["type"] in _MAPS_BEFORE), len(effects))
    effects[at:at] = [dict(e) for e in maps["effects"]]
    return dict(entry, effects=effects)


def noise_profile(results, capture, camera_id: str | None = None, maps: dict | None = None) -> dict:
    """A ``simcam.profiles`` schema-1 document of the final models (one camera, one entry per ISO);
    ``maps``: per ISO, measured maps replacing effects (``simcam loop --maps``, :func:`with_maps`)."""
    first = results[0].model
    entries, notes = [], []
    for r in results:
        entry, n = noise_entry(r.model)
        if maps and r.iso in maps:
            entry = with_maps(entry, maps[r.iso])
            n = n + [f"measured maps ({', '.join(maps[r.iso]['replaces'])} replaced by this sensor's patterns)"]
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
        for card in CARDS.values():  # effects carried by the base (a per-site beta1: channel_gain)
            p = card.from_base(b1_sites)
            if p is not None:
                effects[card.name] = p
        read = np.sqrt(b2) * fs
        for eff in m.get("effects", []) if m.get("type") == "composite" else []:
            card = CARDS.get(eff["type"])
            if card is None:  # an effect of the noise stage outside the loop's vocabulary
                continue
            effects[card.name] = card.from_profile(eff, fs)
            read = card.profile_read_dn(eff, fs, read)
        lm = LoopModel(cam.get("cfa"), np.full((2, 2), black), white, b1 * fs, float(read), 0.0, effects=effects)
        lm.set_dark_variance_from_read()
        out[int(round(float(ent["iso"])))] = lm
    return out
