"""The sensor model the calibration loop fits (parameters in DN) and its closed-form marginal.

The model is simcam's noise-stage composite (:mod:`simcam.noise`) written in
the units the loop measures (DN, electrons): a Poisson-Gaussian base (A. Abdelhamed,
"Noise Modelling for Smartphone Cameras", PhD dissertation, York University, 2020, eq. 3.6;
EMVA Standard 1288 Release 4.0, sec. 2) plus effects of the noise vocabulary. In signal-
chain order::

    e     ~ Poisson(mu_e * prnu_map * (1 + flicker_f))
    x     = K * g_c * e + read (crosstalk-filtered with shot noise) + row_f,r + periodic_f   (DN)
    y     = x + c * x**2 / (white - black)                     (nonlinearity on the noisy value)
    v     = black + offset_c + dsnu_map + col_map + hot_map + y
    frame = clip(round(v / q) * q, 0, white)                   (ADC, step q DN)

There is no second simulator: :func:`simcam.calibration.simulate.simulate_capture`
converts the model to the noise stage's composite entry
(:func:`simcam.calibration.profile.noise_entry`, the entry written to ``profile.yaml``)
and samples it, so the profile reproduces the bootstrap.

What each effect contributes (its parameters, its terms in the closed-form marginal and in the
read-noise bookkeeping) is on its card (:mod:`simcam.calibration.effects`); this module only
walks the cards of the model's effects.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from .effects import CARDS, EffectCard, EffectParams, card_for

PLANE_OFFSETS = ((0, 0), (0, 1), (1, 0), (1, 1))


@dataclass
class LoopModel:
    """Fitted sensor model at one ISO.

    ``black_dn`` (2, 2) black level per CFA site used by the model (the declared
    one when known, else the dark mean); ``white_dn`` ADC white level;
    ``K`` system gain (DN/e-); ``read_dn`` pixel read-noise sigma (DN, before
    quantisation); ``var_dark_dn2`` the measured temporal dark variance the read
    noise is derived from; ``effects`` name -> typed parameters (physical units,
    :mod:`simcam.calibration.effects`; a plain mapping is read as the effect's
    parameters), in the order they were added.
    """

    cfa: str | None
    black_dn: np.ndarray
    white_dn: float
    K: float
    read_dn: float
    var_dark_dn2: float
    black_declared: bool = True
    effects: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.effects = {name: _typed(name, p) for name, p in self.effects.items()}

    def copy(self) -> "LoopModel":
        return copy.deepcopy(self)

    def with_effect(self, name: str, params: EffectParams | Mapping) -> "LoopModel":
        m = self.copy()
        m.effects[name] = _typed(name, params)
        m.refit_read()
        return m

    def without_effect(self, name: str) -> "LoopModel":
        """The inverse of :meth:`with_effect`: ``name`` deleted and the read noise refitted (it takes back
        the temporal dark variance the effect held)."""
        m = self.copy()
        del m.effects[name]
        m.refit_read()
        return m

    def cards(self) -> list[tuple[EffectCard, EffectParams]]:
        """(card, parameters) of the model's effects, in signal-chain order."""
        return [(c, self.effects[name]) for name, c in CARDS.items() if name in self.effects]

    def param(self, effect: str, name: str, default):
        """Parameter ``name`` of ``effect``, or ``default`` when the model does not have the effect."""
        p = self.effects.get(effect)
        return default if p is None else getattr(p, name)

    @property
    def full_scale_dn(self) -> float:
        return float(self.white_dn - float(np.mean(self.black_dn)))

    @property
    def q(self) -> float:
        """The ADC's step (DN): the ``quantization`` effect's, else 1."""
        return float(self.param("quantization", "step_dn", 1.0))

    def codes(self, dn):
        """``dn`` on the model's ADC codes, ``round(dn / q) * q`` (DN; not clipped to [0, white])."""
        q = self.q
        return np.round(np.asarray(dn, np.float64) / q) * q

    def other_dark_variance(self, start: float) -> float:
        """``start`` plus the temporal dark variance (DN^2) the model's effects add besides the read
        noise (:meth:`EffectCard.dark_variance_dn2`), summed in signal-chain order."""
        for c, p in self.cards():
            start += c.dark_variance_dn2(p)
        return start

    def refit_read(self) -> None:
        """Read variance = measured dark variance minus the modelled temporal contributions."""
        other = self.other_dark_variance(self.q ** 2 / 12.0)
        self.read_dn = float(np.sqrt(max(self.var_dark_dn2 - other, 0.01)))

    def set_dark_variance_from_read(self) -> None:
        """The dark variance the model implies (read noise, quantisation, the effects' temporal terms):
        the inverse of :meth:`refit_read`, for a model read from a file."""
        self.var_dark_dn2 = self.other_dark_variance(self.read_dn ** 2 + self.q ** 2 / 12)

    def gains(self) -> np.ndarray:
        """Per-site gain after photon counting (the ``channel_gain`` effect's, else 1)."""
        return np.asarray(self.param("channel_gain", "gains", [1.0] * 4), dtype=np.float64)

    def black_offset_dn(self) -> np.ndarray:
        """Per-site offset of the dark level from ``black_dn`` (the ``black_level_offset`` effect's, else 0)."""
        return np.asarray(self.param("black_level_offset", "offset_dn", [0.0] * 4))

    def to_dict(self) -> dict:
        return {
            "cfa": self.cfa, "black_dn": np.asarray(self.black_dn).tolist(), "white_dn": float(self.white_dn),
            "K_dn_per_e": float(self.K), "read_dn": float(self.read_dn),
            "black_declared": bool(self.black_declared),
            "effects": _plain({k: p.to_dict() for k, p in self.effects.items()}),
        }


def _typed(name: str, params: EffectParams | Mapping) -> EffectParams:
    """``params`` as effect ``name``'s typed parameters (a mapping is converted by its card)."""
    want = card_for(name).params
    if isinstance(params, want):
        return params
    if isinstance(params, EffectParams) or not isinstance(params, Mapping):
        raise TypeError(f"{name}: parameters {type(params).__name__}; expected {want.__name__} or a mapping of its fields")
    try:
        return want.from_dict(params)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None


def _plain(v):
    if isinstance(v, Mapping):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_plain(x) for x in np.asarray(v).tolist()] if isinstance(v, np.ndarray) else [_plain(x) for x in v]
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    return v


@dataclass
class SimSpec:
    """What to simulate for one sequence: ``signal_dn`` (H, W) mean signal above black (DN,
    as measured, i.e. after the nonlinearity), ``n`` frames; ``fixed_in_clean`` when the
    signal is a temporal mean that already holds the fixed patterns (scene without clean);
    ``exposure_s`` its exposure time (0 when not given: exposure-dependent effects add nothing);
    ``series_only`` for darks at another exposure time than the diagnostics' darks (they enter the
    dark-current series and the held-out error only)."""

    kind: str
    n: int
    signal_dn: np.ndarray
    fixed_in_clean: bool = False
    exposure_s: float = 0.0
    series_only: bool = False


def site_map(values, shape) -> np.ndarray:
    """(H, W) map holding ``values[k]`` on 2x2 site k."""
    out = np.empty(shape, dtype=np.float64)
    for k, (dy, dx) in enumerate(PLANE_OFFSETS):
        out[dy::2, dx::2] = values[k]
    return out


def linear_signal(model: LoopModel, signal_dn: np.ndarray) -> np.ndarray:
    """Expected signal before the response (DN above black) whose response is ``signal_dn`` (as measured):
    each effect's inverse (:meth:`EffectCard.linear_signal`; the ``nonlinearity``'s is the noise stage's
    inverse with ``strength = -c``), from the end of the signal chain back."""
    y = np.maximum(np.asarray(signal_dn, dtype=np.float64), 0.0)
    for c, p in reversed(model.cards()):
        y = c.linear_signal(p, y, model)
    return y


def marginal_variance(model: LoopModel, signal_dn: np.ndarray, *, fixed_in_clean: bool = False) -> np.ndarray | None:
    """Per-pixel variance (DN^2) of the model's marginal about the plane mean, or None
    when the marginal is not Gaussian (heavy-tailed read noise, hot pixels).

    The base's ``K g_c x + read^2`` (x the linear signal, g_c the site's gain), then each effect's
    term (:meth:`EffectCard.marginal`) in ascending ``marginal_rank``: temporal and signal terms
    before the response, the response's squared slope (delta method), offsets after it; fixed
    patterns left out when ``fixed_in_clean``; the ADC's ``q^2 / 12`` last."""
    present = model.cards()
    if not all(c.gaussian for c, _ in present):
        return None
    shape = signal_dn.shape
    lin = linear_signal(model, signal_dn)
    kg = model.K * site_map(model.gains(), shape)
    v = kg * lin + model.read_dn ** 2
    terms = [(c, p) for c, p in present if c.marginal_rank is not None and not (fixed_in_clean and c.fixed_pattern)]
    for c, p in sorted(terms, key=lambda cp: cp[0].marginal_rank):
        v = c.marginal(p, v, lin, model)
    return v + model.q ** 2 / 12.0


def shot_factors(model: LoopModel, y: np.ndarray) -> np.ndarray:
    """Per flat point and site, the factor the current model's other effects put on the shot-noise
    term ``K g x`` of the temporal variance (``charge_crosstalk``: ``(1 - 4c)^2 + 4c^2``; 1 for most):
    the model's temporal variance at ``y`` less its dark variance, over ``K g x``. Without it a model
    whose PTC slope is not ``K g`` would have its K refitted as if it were (the crosstalk counted
    twice). 1 where the model has no Gaussian marginal (:func:`marginal_variance`)."""
    y = np.atleast_2d(np.asarray(y, dtype=np.float64))
    out = np.ones_like(y)
    v0 = marginal_variance(model, np.zeros((2, 2)), fixed_in_clean=True)
    if v0 is None:
        return out
    kg = model.K * site_map(model.gains(), (2, 2))
    for i, row in enumerate(y):
        sig = site_map(np.maximum(row, 0.0), (2, 2))
        lin = linear_signal(model, sig)
        vy = marginal_variance(model, sig, fixed_in_clean=True)
        shot = kg * lin
        f = np.where(shot > 0, (vy - v0) / np.where(shot > 0, shot, 1.0), 1.0)
        out[i] = [f[dy, dx] for dy, dx in PLANE_OFFSETS]
    return np.clip(out, 0.05, 20.0)
