"""DNG NoiseProfile (Adobe DNG Specification 1.7, chapter 6, tag 51041) <-> per-site NLF of a noise model.

A NoiseProfile holds (S, O) pairs with ``var = S x + O`` per CFA plane (one pair for all planes, or one
per plane); simcam's models hold ``beta1``, ``beta2`` per CFA site (4 values, site order (0,0), (0,1),
(1,0), (1,1)).
"""

from __future__ import annotations

import numpy as np

from ..cfa import PACK_OFFSETS, check_pattern
from ..errors import ProfileError
from .base import site_values


def nlf_pairs(model) -> np.ndarray | None:
    """The DNG NoiseProfile (S, O) pairs of a model whose variance is ``beta1 * x + beta2``.

    One pair when all sites agree, else 4 pairs in site order (0,0), (0,1), (1,0), (1,1)
    (a writer must map them to CFA planes). None for models without that form.
    """
    m = model
    if m.type == "composite":
        m = m.base
    if m.type == "clipped":
        m = m.base
    if m.type == "poisson_mixture":
        zbar = m.p1 * m.z1 + (1 - m.p1) * m.z2
        b1 = site_values(m.beta1, name="beta1") * zbar
    elif m.type in ("nlf", "poisson_gaussian"):
        b1 = site_values(m.beta1, name="beta1")
    elif m.type == "gaussian":
        b1 = np.zeros(4)
    else:
        return None
    b2 = site_values(m.sigma, name="sigma") ** 2 if m.type == "gaussian" else site_values(m.beta2, name="beta2")
    pairs = np.stack([b1, b2], axis=1)
    if np.all(pairs == pairs[0]):
        return pairs[:1].copy()
    return pairs


def model_noise_profile(model, cfa: str | None) -> np.ndarray | None:
    """DNG NoiseProfile pairs for a model with ``var = beta1 x + beta2`` (1 pair, or 3 per R, G, B plane).

    Per-site values become per-colour planes (the two green sites averaged);
    None for a model without that form.
    """
    pairs = nlf_pairs(model)
    if pairs is None or pairs.shape[0] == 1 or cfa is None:
        return None if pairs is None else pairs[:1] if pairs.shape[0] == 1 else pairs.mean(axis=0, keepdims=True)
    cfa = check_pattern(cfa)
    out = np.zeros((3, 2))
    for c in range(3):
        sites = [i for i, (_, letter) in enumerate(zip(PACK_OFFSETS, cfa)) if letter == "RGB"[c]]
        out[c] = pairs[sites].mean(axis=0)
    return out


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
