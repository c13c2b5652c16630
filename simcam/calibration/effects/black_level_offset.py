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

Darks whose values (``diagnostics.SPLIT_SHARE`` of a site's) sit on the declared black's code and at most one
neighbouring code (some on the black's own), on the data's own codes (``adc_step``: the step whether or not the model has it yet),
tell only where the one transition level between those two codes lies relative to the dark level: an
offset of the black and a displaced transition (the ADC's differential non-linearity, IEEE Std
1241-2010, sec. 4.1.3) give the same two-code split, and nothing in such darks tells them apart (EMVA
1288 Release 4.0, sec. 2: darks below 0.24 DN^2 per code width squared give the dark level and variance
only as bounds). Such a site has no offset from this fit. An independent simulator's ADC with 11-DN
codes and a transition 3 DN below its place (a 256-DN black, 1-DN read noise: two thirds of the dark
values on the code above) once got a 3.9-DN ``black_level_offset`` at ISO 100; its ISO 800 and 3200
darks, spread over many codes, showed the same ADC's unequal codes and no offset.

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
    split_codes_dn: float | None = quantity("DN", "only where a site's darks sit on the declared black's code and one "
                                            "neighbour: the width of those codes", default=None)


class BlackLevelOffsetCard(DeclaredProfileCard, name="black_level_offset", params=BlackLevelOffset, diagnostics=("black_offset",),
                           null_field="offset_dn"):
    def fit(self, d, model, ctx):
        m = d.dark_map()[0]
        black = np.asarray(d.black_dn, np.float64)
        ref = model.codes(black) if model.q > 1.0 else black
        step = max(dg.adc_step(d), float(model.q))
        darks = np.concatenate(d.darks)
        out, split = [], False
        for dy, dx in dg.PLANE_OFFSETS:
            if dg.split_on_black_code(darks[:, dy::2, dx::2], float(black[dy, dx]), step):
                out.append(0.0)
                split = True
            else:
                out.append(float(np.median(m[dy::2, dx::2]) - ref[dy, dx]))
        return BlackLevelOffset(offset_dn=out, split_codes_dn=step if split else None)

    def null_reason(self, p):
        if p.split_codes_dn:
            return (f"the darks sit on the declared black's code (and at most one neighbour) of codes "
                    f"{p.split_codes_dn:.3g} DN wide: they tell where the transition next to it lies, which an "
                    "offset and the ADC's unequal codes move alike")
        return None
