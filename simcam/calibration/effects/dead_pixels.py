"""``dead_pixels``: pixels without photo-response (dead) and pixels stuck at one code (stuck).

Physics. A few pixels of every sensor are defective in a way no gain or offset describes: a
broken photodiode (or an open transfer gate) leaves a pixel *dead*, reading its dark level —
black plus the read noise of its still-working read-out chain — whatever the light; a shorted node
leaves a pixel *stuck*, reading the same code in every frame (often white) (EMVA 1288 Release 4.0,
sec. 8.5, defect pixels; A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD dissertation,
York University, 2020, ch. 2, defective pixels). Unlike a hot pixel (an extra dark signal on top of
a normal photo-response, ``hot_pixels``) neither carries image information.

Fit. On the flat with the most frames (:func:`simcam.calibration.diagnostics.defect_masks`): pixels
whose code is the same in every frame of that flat and of the darks are stuck; the others whose
response (flat mean minus dark mean, or minus the declared black) is under a quarter of their CFA
plane's median are dead. Their shares of the pixels are ``dead_fraction`` and ``stuck_fraction``.
The stuck pixels' levels above the black of their site are kept as ``stuck_values_dn`` (all of them
up to :data:`MAX_LEVELS`, else that many quantiles): one sensor's stuck pixels sit at several levels
(white, black, code 0), and a single level would put most of them where none is. ``stuck_value_dn``
is their median (the report's summary).

Profile. ``{type: dead_pixels, dead_fraction, stuck_fraction, stuck_value, stuck_values,
dead_read_noise: true}`` (levels on normalised raw): the noise stage draws the defect set and each
stuck pixel's level from the sensor seed and sets the dead ones to the frame's read noise about black.
"""

from __future__ import annotations

import numpy as np

from .. import diagnostics as dg
from .card import EffectCard, EffectParams, ProfileTerm, quantity


class DeadPixels(EffectParams):
    dead_fraction: float = quantity("%", "fraction of the pixels without photo-response (read black plus read noise)",
                                    scale=100.0)
    stuck_fraction: float = quantity("%", "fraction of the pixels that read one code in every frame", scale=100.0)
    stuck_value_dn: float = quantity("DN", "level of the stuck pixels above the black level (their median)")
    count: int | None = quantity("", "number of defect pixels detected in the analysed frames (fits only)",
                                 default=None)
    stuck_values_dn: list | None = quantity("DN", "levels of the stuck pixels above the black level (sorted; "
                                            "quantiles when there are many)", default=None)


#: stuck levels kept as they are up to this many, else as this many quantiles
MAX_LEVELS = 33


class DeadPixelsCard(EffectCard, name="dead_pixels", params=DeadPixels, diagnostics=("defect_pixels",),
                     fixed_pattern=True, gaussian=False):
    def fit(self, d, model, ctx):
        masks = dg.defect_masks(d)
        if masks is None:
            return DeadPixels(dead_fraction=0.0, stuck_fraction=0.0, stuck_value_dn=0.0, count=0)
        dead, stuck = masks
        value, levels = 0.0, None
        if stuck.any():
            f = max(d.flats, key=lambda a: (a.shape[0], float(a.mean())))
            black = np.empty(stuck.shape)
            for k, (dy, dx) in enumerate(dg.PLANE_OFFSETS):
                black[dy::2, dx::2] = np.asarray(model.black_dn, np.float64).ravel()[k] + model.black_offset_dn()[k]
            v = np.sort(f[0][stuck].astype(np.float64) - black[stuck])
            value = float(np.median(v))
            if v.size > MAX_LEVELS:
                v = np.quantile(v, np.linspace(0.0, 1.0, MAX_LEVELS))
            levels = [float(x) for x in v]
        return DeadPixels(dead_fraction=float(dead.mean()), stuck_fraction=float(stuck.mean()),
                          stuck_value_dn=value, count=int(dead.sum() + stuck.sum()), stuck_values_dn=levels)

    def format(self, p):
        if not isinstance(p, EffectParams):
            p = self.params.from_dict(p)
        text = (f"dead_fraction = {100 * p.dead_fraction:.3g} %, stuck_fraction = {100 * p.stuck_fraction:.3g} %, "
                f"stuck_value_dn = {p.stuck_value_dn:.4g} DN")
        if p.stuck_values_dn and len(p.stuck_values_dn) > 1:
            text += f" (levels from {min(p.stuck_values_dn):.4g} to {max(p.stuck_values_dn):.4g} DN)"
        return text + ("" if p.count is None else f", count = {p.count}")

    def is_null(self, p):
        return p.dead_fraction <= 0 and p.stuck_fraction <= 0

    def to_profile(self, p, model):
        fs = model.full_scale_dn
        entry = {"type": "dead_pixels", "dead_fraction": float(p.dead_fraction),
                 "stuck_fraction": float(p.stuck_fraction), "stuck_value": float(p.stuck_value_dn) / fs,
                 "dead_read_noise": True}
        if p.stuck_values_dn:
            entry["stuck_values"] = [float(x) / fs for x in p.stuck_values_dn]
        return ProfileTerm(effect=entry)

    def from_profile(self, entry, full_scale_dn):
        levels = entry.get("stuck_values")
        return DeadPixels(dead_fraction=float(entry.get("dead_fraction", 0.0)),
                          stuck_fraction=float(entry.get("stuck_fraction", 0.0)),
                          stuck_value_dn=float(entry.get("stuck_value", 1.0)) * full_scale_dn,
                          stuck_values_dn=None if levels is None else [float(x) * full_scale_dn for x in levels])
