"""``spatial_correlation``: crosstalk between same-colour neighbours.

The noise accumulated so far, ``n = x - signal``, is replaced by
``n + c * (sum of its four same-colour neighbours at distance 2)`` (reflecting
at the borders), which keeps the mean and gives, for white input noise of
variance v, ``var = v (1 + 4 c^2)`` and a correlation ``2 c / (1 + 4 c^2)``
between same-colour neighbours two pixels apart (the two share no other
neighbour), away from the borders.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from .base import Effect, register_effect


@register_effect
class SpatialCorrelation(Effect):
    """Same-colour crosstalk with coupling ``coefficient`` (dimensionless, |c| <= 0.25)."""

    type: Literal["spatial_correlation"] = "spatial_correlation"
    coefficient: float = Field(ge=-0.25, le=0.25)

    def apply(self, x, ctx):
        n = x - ctx.signal
        p = np.pad(n, 2, mode="reflect")
        h, w = n.shape
        s = p[0:h, 2:w + 2] + p[4:h + 4, 2:w + 2] + p[2:h + 2, 0:w] + p[2:h + 2, 4:w + 4]
        return (ctx.signal + n + np.float32(self.coefficient) * s).astype(np.float32)
