"""``black_level_offset``: the measured black level differs from the declared one, per CFA site.

Physics. The black level a camera declares (DNG BlackLevel, a descriptor's offset) is a nominal
value; the dark signal's actual mean (offset plus the dark current of the exposure) differs from
it by a constant per site (EMVA 1288 Release 4.0, sec. 2: the dark signal mu_y.dark of the linear
model; A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD dissertation, York University,
2020, ch. 2, dark current and the black level). A constant, it changes no variance.

Fit. ``black_offset``: per 2x2 site, the median of the dark temporal-mean map minus the declared
black level. With an ADC coarser than 1 DN in the model (``quantization``: codes ``q`` DN apart) the
darks tell the dark level only to a code: the offset is measured from the code the declared black
reads as (``LoopModel.codes``, the model's quantiser), so darks that sit on that code have no
offset (a 0.6-DN read noise under 14-DN codes puts every dark value of a 256-DN black on code 252: not
a black level 4 DN low).

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
        black = np.asarray(d.black_dn, np.float64)
        ref = model.codes(black) if model.q > 1.0 else black
        return BlackLevelOffset(offset_dn=[float(np.median(m[dy::2, dx::2]) - ref[dy, dx])
                                           for dy, dx in dg.PLANE_OFFSETS])
