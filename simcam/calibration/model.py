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
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from math import gamma

import numpy as np

PLANE_OFFSETS = ((0, 0), (0, 1), (1, 0), (1, 1))


@dataclass
class LoopModel:
    """Fitted sensor model at one ISO.

    ``black_dn`` (2, 2) black level per CFA site used by the model (the declared
    one when known, else the dark mean); ``white_dn`` ADC white level;
    ``K`` system gain (DN/e-); ``read_dn`` pixel read-noise sigma (DN, before
    quantisation); ``var_dark_dn2`` the measured temporal dark variance the read
    noise is derived from; ``effects`` name -> parameters (physical units).
    """

    cfa: str | None
    black_dn: np.ndarray
    white_dn: float
    K: float
    read_dn: float
    var_dark_dn2: float
    black_declared: bool = True
    effects: dict = field(default_factory=dict)

    def copy(self) -> "LoopModel":
        return copy.deepcopy(self)

    def with_effect(self, name: str, params: dict) -> "LoopModel":
        m = self.copy()
        m.effects[name] = params
        m.refit_read()
        return m

    @property
    def full_scale_dn(self) -> float:
        return float(self.white_dn - float(np.mean(self.black_dn)))

    @property
    def q(self) -> float:
        return float(self.effects.get("quantization", {}).get("step_dn", 1.0))

    def refit_read(self) -> None:
        """Read variance = measured dark variance minus the modelled temporal contributions."""
        e = self.effects
        other = self.q ** 2 / 12.0
        other += e.get("row_noise", {}).get("sigma_dn", 0.0) ** 2
        if "periodic_pattern" in e:
            other += e["periodic_pattern"]["amplitude_dn"] ** 2 / 2
        self.read_dn = float(np.sqrt(max(self.var_dark_dn2 - other, 0.01)))

    def gains(self) -> np.ndarray:
        return np.asarray(self.effects.get("channel_gain", {}).get("gains", [1.0] * 4), dtype=np.float64)

    def to_dict(self) -> dict:
        return {
            "cfa": self.cfa, "black_dn": np.asarray(self.black_dn).tolist(), "white_dn": float(self.white_dn),
            "K_dn_per_e": float(self.K), "read_dn": float(self.read_dn),
            "black_declared": bool(self.black_declared), "effects": _plain(self.effects),
        }


def _plain(v):
    if isinstance(v, dict):
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
    signal is a temporal mean that already holds the fixed patterns (scene without clean)."""

    kind: str
    n: int
    signal_dn: np.ndarray
    fixed_in_clean: bool = False


def site_map(values, shape) -> np.ndarray:
    """(H, W) map holding ``values[k]`` on 2x2 site k."""
    out = np.empty(shape, dtype=np.float64)
    for k, (dy, dx) in enumerate(PLANE_OFFSETS):
        out[dy::2, dx::2] = values[k]
    return out


def tukey_var(lam: float) -> float:
    """Variance of the standard Tukey-lambda distribution (finite for lam > -1/2)."""
    if abs(lam) < 1e-9:
        return np.pi ** 2 / 3
    return 2.0 / lam ** 2 * (1.0 / (1 + 2 * lam) - gamma(lam + 1) ** 2 / gamma(2 * lam + 2))


def linear_signal(model: LoopModel, signal_dn: np.ndarray) -> np.ndarray:
    """Expected signal before the response (DN above black) whose response is ``signal_dn`` (as measured),
    i.e. the inverse of the noise stage's ``nonlinearity`` (``strength = -c``) in DN."""
    y = np.maximum(np.asarray(signal_dn, dtype=np.float64), 0.0)
    c = model.effects.get("nonlinearity", {}).get("c", 0.0)
    if not c:
        return y
    from ..noise.effects.response import Nonlinearity

    s = model.full_scale_dn
    return Nonlinearity(strength=float(np.clip(-c, -0.45, 0.45))).inverse(y / s) * s


def marginal_variance(model: LoopModel, signal_dn: np.ndarray, *, fixed_in_clean: bool = False) -> np.ndarray | None:
    """Per-pixel variance (DN^2) of the model's marginal about the plane mean, or None
    when the marginal is not Gaussian (heavy-tailed read noise, hot pixels)."""
    e = model.effects
    if "heavy_tail_read" in e or "hot_pixels" in e:
        return None
    shape = signal_dn.shape
    s = model.full_scale_dn
    c = e.get("nonlinearity", {}).get("c", 0.0)
    lin = linear_signal(model, signal_dn)
    kg = model.K * site_map(model.gains(), shape)
    v = kg * lin + model.read_dn ** 2
    v = v + e.get("row_noise", {}).get("sigma_dn", 0.0) ** 2
    if "periodic_pattern" in e:
        v = v + e["periodic_pattern"]["amplitude_dn"] ** 2 / 2
    if "frame_flicker" in e:
        v = v + (e["frame_flicker"]["sigma"] * lin) ** 2
    if not fixed_in_clean and "prnu" in e:
        v = v + (e["prnu"]["sigma"] * lin) ** 2
    if c:  # the response acts on the noisy value: variance times its squared slope (delta method)
        v = v * (1 + 2 * c * lin / s) ** 2
    if not fixed_in_clean:  # offsets come after the response
        v = v + e.get("dsnu", {}).get("sigma_dn", 0.0) ** 2 + e.get("column_fpn", {}).get("sigma_dn", 0.0) ** 2
    return v + model.q ** 2 / 12.0
