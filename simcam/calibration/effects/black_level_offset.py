"""``black_level_offset``: the measured black level differs from the declared one, per CFA site.

Physics. The black level a camera declares (DNG BlackLevel, a descriptor's offset) is a nominal
value; the dark signal's actual mean (offset plus the dark current of the exposure) differs from
it by a constant per site (EMVA 1288 Release 4.0, sec. 2: the dark signal mu_y.dark of the linear
model; A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD dissertation, York University,
2020, ch. 2, dark current and the black level). A constant, it changes no variance.

Fit. ``black_offset``: per 2x2 site, the median of the dark temporal-mean map minus the declared
black level.

Profile. ``{type: black_level_offset, offset}``: the four offsets on normalised raw,
``offset_dn / (white - black)``.
"""

from __future__ import annotations

import numpy as np

from .. import diagnostics as dg
from .card import DeclaredProfileCard, EffectParams, quantity


class BlackLevelOffset(EffectParams):
    offset_dn: list = quantity("DN", "offset of the dark level from the declared black, per 2x2 site (00, 01, 10, 11), DN",
                               profile="offset", per_full_scale=True)


class BlackLevelOffsetCard(DeclaredProfileCard, name="black_level_offset", params=BlackLevelOffset, diagnostics=("black_offset",),
                           null_field="offset_dn"):
    def fit(self, d, model, ctx):
        m = d.dark_map()[0]
        return BlackLevelOffset(offset_dn=[float(np.median(m[dy::2, dx::2]) - d.black_dn[dy, dx])
                                           for dy, dx in dg.PLANE_OFFSETS])
