"""``nonlinearity``: a compressive (or expansive) response acting on the noisy value.

Physics. The charge-to-voltage conversion and the ADC respond non-linearly to the charge actually
collected, shot noise included, and to the read, row and periodic noise added before them:
``y = x + c x^2 / (white - black)`` in DN above black (c < 0: compressive). By the delta method the
noise is scaled by the local slope, ``var(y) ~= (1 + 2 c x / (white - black))^2 var(x)``, so the
photon-transfer curve bends (EMVA 1288 Release 4.0, sec. 6: linearity and the linearity error,
which the standard's linear model, sec. 2, assumes away; A. Abdelhamed, *Noise Modelling for
Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 2, the camera's response). Fixed
offsets (DSNU, column FPN) and the quantisation come after the response in the signal chain.

Fit. Least squares of the photon-transfer points (``ptc_curvature``):
``var(y) = (1 + 2 c x / s)^2 (K g x + r)`` with ``y = x + c x^2 / s`` (s = white - black, r the dark
variance), relative residuals, K re-estimated with c (c within +-0.45). The shot term carries the
factor the model's other effects put on it (``FitContext.shot_factor``: charge sharing lowers a flat's
shot variance), so K stays the system gain.

Profile. ``{type: nonlinearity, strength}`` with ``strength = -c`` (the noise stage's
``y = x - strength x^2`` on normalised raw), clipped to the stage's +-0.45.
"""

from __future__ import annotations

import numpy as np

from .card import EffectCard, EffectParams, Fit, ProfileTerm, quantity


def response_inverse_dn(c: float, y, s: float):
    """``x`` (DN above black) with ``x + c x^2 / s = y``: the inverse of the noise stage's ``nonlinearity``
    (``strength = -c``, clipped to its +-0.45) on ``y`` in DN; ``y`` itself where ``c`` is 0."""
    if not c:
        return y
    from ...noise.effects.response import Nonlinearity as StageNonlinearity

    return StageNonlinearity(strength=float(np.clip(-c, -0.45, 0.45))).inverse(y / s) * s


class Nonlinearity(EffectParams):
    c: float = quantity("% at white", "curvature of y = x + c x^2 / (white - black) (dimensionless: the relative "
                        "response error at white; shown in %)", scale=100.0)


class NonlinearityCard(EffectCard, name="nonlinearity", params=Nonlinearity, null_field="c", diagnostics=("ptc_curvature",),
                       marginal_rank=50):
    def fit(self, d, model, ctx):
        """Least squares of var(y) = (1 + 2c x/s)^2 (K g x + r) with y = x + c x^2/s over the PTC points."""
        from scipy.optimize import least_squares

        _darks, flats = d.ptc_points()
        y = d.flat_levels(model.black_dn)
        v = np.array([f[:, 1] for f in flats])
        r = model.var_dark_dn2
        s = model.full_scale_dn
        g = model.gains() * ctx.shot_factor(model, y)

        def resid(p):
            K, c = p
            disc = np.maximum(1 + 4 * c * y / s, 1e-9)
            x = y if abs(c) < 1e-12 else (np.sqrt(disc) - 1) * s / (2 * c)
            pred = (1 + 2 * c * x / s) ** 2 * (K * g * x + r)
            return ((pred - v) / v).ravel()

        sol = least_squares(resid, x0=[model.K, 0.0], bounds=([1e-6, -0.45], [np.inf, 0.45]))
        return Fit(Nonlinearity(c=float(sol.x[1])), K=float(sol.x[0]))

    def marginal(self, p, v, lin, model):
        if not p.c:  # the response acts on the noisy value: variance times its squared slope (delta method)
            return v
        return v * (1 + 2 * p.c * lin / model.full_scale_dn) ** 2

    def linear_signal(self, p, y, model):
        """The inverse of the noise stage's ``nonlinearity`` (``strength = -c``) in DN."""
        return response_inverse_dn(p.c, y, model.full_scale_dn)

    def to_profile(self, p, model):
        return ProfileTerm(effect={"type": "nonlinearity", "strength": float(np.clip(-p.c, -0.45, 0.45))})

    def from_profile(self, entry, full_scale_dn):
        return Nonlinearity(c=-float(entry["strength"]))
