"""Build calibration profiles from other tools' noise data.

``import_darktable``
    darktable's ``noiseprofiles.json`` (GPL-3+ data: read as input only,
    never copied into simcam). Each profile holds Poisson-Gaussian (a, b) per
    RGB channel, ``var = a * x + b``, fitted by darktable's ``tools/noise``
    scripts on images exported with its "raw linear" style: ``rawprepare``
    scales the raw to [0, 1] (black subtracted, divided by white - black),
    white balance is pass-through (``temperature`` coefficients 1, 1, 1) and
    the colour profile is linear camera RGB. darktable's ``denoiseprofile``
    module multiplies a and b by the white-balance coefficients
    (``processed_maximum``) at run time because the stored values refer to
    un-balanced data. That scale is simcam's normalised raw, so the conversion
    is the identity: ``nlf: beta1 = a, beta2 = b`` per colour, mapped to the
    CFA sites of the chosen pattern. Caveat: darktable measures after
    demosaicking, so for interpolated sites the per-site raw variance can be
    somewhat larger than these values. Negative ``b`` (a few fits) is set to 0
    and listed in the provenance notes; repeated ISOs are averaged.

``profile_from_dng``
    the DNG NoiseProfile tag (DNG 1.6 spec, tag 51041): (S, O) pairs of
    ``var = S * x + O`` on normalised raw, one pair for all planes or one per
    CFA plane (CFAPlaneColor order, R, G, B) -> one ``nlf`` entry at the
    file's ISO.
"""

from __future__ import annotations

import datetime as _dt
import difflib
import json
from pathlib import Path

import numpy as np

from ..cfa import PACK_OFFSETS, check_pattern
from ..errors import ProfileError
from ..profiles import CalibrationProfile, profile_from_dict


def _today() -> str:
    return _dt.date.today().isoformat()


def _per_site(rgb: list[float], cfa: str) -> list[float] | float:
    vals = [float(rgb["RGB".index(c)]) for c in cfa]
    return vals[0] if all(v == vals[0] for v in vals) else vals


def import_darktable(path: str | Path, camera: str, *, cfa: str = "RGGB", camera_id: str | None = None) -> CalibrationProfile:
    """Profile of one camera (``"MAKE MODEL"``, case-insensitive) from a darktable noiseprofiles.json.

    Parameters
    ----------
    path : path to ``noiseprofiles.json``
    camera : ``"<maker> <model>"`` as darktable names them, e.g. ``"Sony ILCE-7M3"``
    cfa : Bayer pattern used to map the per-colour values to CFA sites
    camera_id : id in the profile (default: ``camera``)
    """
    path = Path(path)
    cfa = check_pattern(cfa, where="--cfa")
    try:
        doc = json.loads(path.read_text())
    except OSError as exc:
        raise ProfileError(f"{path}: cannot read ({exc.strerror})") from None
    except json.JSONDecodeError as exc:
        raise ProfileError(f"{path}: invalid JSON (line {exc.lineno}: {exc.msg})") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("noiseprofiles"), list):
        raise ProfileError(f"{path}: noiseprofiles: expected darktable's format (a list of makers with models)")
    names = {}
    for mk in doc["noiseprofiles"]:
        for mo in mk.get("models", []):
            names[f"{mk.get('maker', '')} {mo.get('model', '')}".strip().lower()] = (mk, mo)
    hit = names.get(" ".join(camera.split()).lower())
    if hit is None:
        close = difflib.get_close_matches(camera.lower(), list(names), n=3)
        raise ProfileError(f"{path}: --camera: no camera {camera!r}; expected \"MAKE MODEL\" as darktable names it"
                           + (f", e.g. {close}" if close else ""))
    mk, mo = hit
    by_iso: dict[float, list[tuple[list[float], list[float]]]] = {}
    for i, p in enumerate(mo.get("profiles", [])):
        try:
            iso, a, b = float(p["iso"]), [float(x) for x in p["a"]], [float(x) for x in p["b"]]
        except (KeyError, TypeError, ValueError):
            raise ProfileError(f"{path}: {mk.get('maker')} {mo.get('model')}: profiles[{i}]: expected iso, a[3], b[3]") from None
        if len(a) != 3 or len(b) != 3:
            raise ProfileError(f"{path}: {mk.get('maker')} {mo.get('model')}: profiles[{i}]: expected 3 values of a and b")
        by_iso.setdefault(iso, []).append((a, b))
    if not by_iso:
        raise ProfileError(f"{path}: {camera}: no profiles")
    entries, clamped, averaged, skipped = [], [], [], []
    for iso in sorted(by_iso):
        a = np.mean([x[0] for x in by_iso[iso]], axis=0)
        b = np.mean([x[1] for x in by_iso[iso]], axis=0)
        if len(by_iso[iso]) > 1:
            averaged.append(iso)
        if (a < 0).any() or not np.isfinite(a).all() or not np.isfinite(b).all():
            # darktable's fit can go negative where the shot-noise term is unidentifiable; such an
            # entry is no noise model: skip it (named in the notes) and keep the valid ISOs
            skipped.append(f"ISO {iso:g} skipped: shot-noise slope a = {[float(f'{v:.4g}') for v in a]} "
                           "(expected a >= 0 for every colour)")
            continue
        if (b < 0).any():
            clamped.append(iso)
            b = np.maximum(b, 0.0)
        entries.append({"iso": iso, "model": {"type": "nlf", "beta1": _per_site(list(a), cfa), "beta2": _per_site(list(b), cfa)}})
    notes = [f"darktable comment: {mo.get('comment', '')}".strip(),
             f"per-colour (a, b) mapped to the CFA sites of {cfa}"]
    if averaged:
        notes.append(f"ISOs measured twice, averaged: {[int(i) if i.is_integer() else i for i in averaged]}")
    if clamped:
        notes.append(f"negative b set to 0 at ISOs {[int(i) if i.is_integer() else i for i in clamped]}")
    notes += skipped
    if not entries:
        raise ProfileError(f"{path}: {camera}: no valid profile; " + "; ".join(skipped))
    return profile_from_dict({
        "schema_version": 1,
        "provenance": {
            "source": f"{path.name} (darktable noise profiles, version {doc.get('version')}), camera {mk.get('maker')} {mo.get('model')}",
            "method": "darktable Poisson-Gaussian fit var = a x + b per RGB on raw scaled to [0, 1], white balance "
                      "pass-through ('raw linear' style; = simcam normalised raw): beta1 = a, beta2 = b. darktable "
                      "fits after demosaicking: per-site raw variance of interpolated sites may be higher",
            "tool": "simcam profile import-darktable",
            "created": _today(),
            "licence": "darktable data is GPL-3.0-or-later; this file is derived from it",
            "notes": "; ".join(n for n in notes if n),
        },
        "cameras": [{"id": camera_id or f"{mk.get('maker')} {mo.get('model')}", "make": str(mk.get("maker", "")),
                     "model": str(mo.get("model", "")), "cfa": cfa, "entries": entries}],
    }, source=str(path))


def noise_profile_site_values(pairs: np.ndarray, cfa: str | None, *, where: str = "NoiseProfile"):
    """(beta1, beta2) per site (float or 4 floats) from DNG NoiseProfile pairs."""
    pairs = np.asarray(pairs, dtype=np.float64).reshape(-1, 2)
    if pairs.shape[0] == 1:
        return float(pairs[0, 0]), float(pairs[0, 1])
    if pairs.shape[0] == 3:
        if cfa is None:
            raise ProfileError(f"{where}: 3 per-plane pairs need the CFA pattern to map them to sites")
        b1 = [float(pairs["RGB".index(c), 0]) for c in cfa]
        b2 = [float(pairs["RGB".index(c), 1]) for c in cfa]
        return b1, b2
    raise ProfileError(f"{where}: {pairs.shape[0]} (S, O) pairs; expected 1 or 3 (one per CFA plane)")


def profile_from_dng(path: str | Path, *, camera_id: str | None = None) -> CalibrationProfile:
    """One-entry profile from a DNG's NoiseProfile tag and ISO."""
    from ..io.dng import read_dng_meta

    path = Path(path)
    meta = read_dng_meta(path)
    if meta.noise_profile is None:
        raise ProfileError(f"{path}: NoiseProfile: tag absent; expected (S, O) pairs to build a profile from")
    if meta.iso is None:
        raise ProfileError(f"{path}: ISOSpeedRatings: tag absent; expected the ISO the NoiseProfile belongs to")
    b1, b2 = noise_profile_site_values(meta.noise_profile, meta.cfa, where=f"{path}: NoiseProfile")
    cam = camera_id or " ".join(x for x in (meta.make, meta.model) if x) or meta.unique_camera_model or path.stem
    return profile_from_dict({
        "schema_version": 1,
        "provenance": {"source": f"{path.name}: DNG NoiseProfile tag (51041)", "method": "var = S x + O per CFA plane, copied",
                       "tool": "simcam profile from-dng", "created": _today()},
        "cameras": [{"id": cam, "make": meta.make, "model": meta.model, "cfa": meta.cfa,
                     "black_level_dn": float(np.mean(meta.black_level)), "white_level_dn": float(meta.white_level),
                     "entries": [{"iso": float(meta.iso), "model": {"type": "nlf", "beta1": b1, "beta2": b2}}]}],
    }, source=str(path))


def model_noise_profile(model, cfa: str | None) -> np.ndarray | None:
    """DNG NoiseProfile pairs for a model with ``var = beta1 x + beta2`` (1 pair, or 3 per R, G, B plane).

    Per-site values become per-colour planes (the two green sites averaged);
    None for a model without that form.
    """
    from ..stages.noise import nlf_pairs

    pairs = nlf_pairs(model)
    if pairs is None or pairs.shape[0] == 1 or cfa is None:
        return None if pairs is None else pairs[:1] if pairs.shape[0] == 1 else pairs.mean(axis=0, keepdims=True)
    cfa = check_pattern(cfa)
    out = np.zeros((3, 2))
    for c in range(3):
        sites = [i for i, (_, letter) in enumerate(zip(PACK_OFFSETS, cfa)) if letter == "RGB"[c]]
        out[c] = pairs[sites].mean(axis=0)
    return out
