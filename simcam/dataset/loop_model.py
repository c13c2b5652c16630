"""The sensor model the calibration loop fits, and its simulator (parametric bootstrap).

A Poisson-Gaussian base (seed eq. 3.6; EMVA 1288 sec. 2) in DN plus any of the
effects of simcam's noise vocabulary, all in physical units::

    e     ~ Poisson(mu_e * prnu_map * (1 + flicker_f))
    x     = K * g_c * e + read + row_f,r + periodic_f          (DN, linear)
    y     = x + c * x**2 / (white - black)                     (nonlinearity)
    v     = black + offset_c + dsnu_map + col_map + hot_map + y
    frame = clip(round(v / q) * q, 0, white)                   (ADC, step q DN)

``simulate(model, spec, rng, sensor)`` is the small internal interface the
loop depends on; fixed patterns (DSNU, column FPN, PRNU, hot pixels) are drawn
once per simulated *sensor* (:func:`draw_sensor`) and shared by all its
sequences. (Independent of ``simcam.noise``, which was not available when
this was written; the profile written by the loop uses the same effect names.)
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from math import gamma

import numpy as np

EFFECTS = (
    "row_noise", "column_fpn", "dsnu", "prnu", "hot_pixels", "heavy_tail_read", "quantization",
    "spatial_correlation", "periodic_pattern", "black_level_offset", "frame_flicker",
    "nonlinearity", "channel_gain",
)
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


def tukey_sample(lam: float, size, rng) -> np.ndarray:
    """Tukey-lambda variates by the quantile function Q(u) = (u^lam - (1-u)^lam) / lam."""
    u = np.clip(rng.random(size), 1e-12, 1 - 1e-12)
    if abs(lam) < 1e-9:
        return np.log(u / (1 - u))
    return (u ** lam - (1 - u) ** lam) / lam


def draw_sensor(model: LoopModel, shape: tuple[int, int], rng) -> dict:
    """Fixed patterns of one simulated sensor: additive offset map (DN) and PRNU map."""
    e = model.effects
    h, w = shape
    offset = site_map(e.get("black_level_offset", {}).get("offset_dn", [0.0] * 4), shape)
    if "dsnu" in e:
        offset = offset + rng.normal(0, e["dsnu"]["sigma_dn"], shape)
    if "column_fpn" in e:
        offset = offset + rng.normal(0, e["column_fpn"]["sigma_dn"], (1, w))
    if "hot_pixels" in e:
        p = e["hot_pixels"]
        hot = rng.random(shape) < p["fraction"]
        offset = offset + hot * rng.lognormal(p["log_mean"], p["log_sigma"], shape)
    prnu = 1.0 + rng.normal(0, e["prnu"]["sigma"], shape) if "prnu" in e else None
    return {"offset": offset, "prnu": prnu}


def _nonlin(x, c, s):
    return x + c * x * x / s


def _nonlin_inv(y, c, s):
    if abs(c) < 1e-12:
        return y
    disc = np.maximum(1 + 4 * c * y / s, 0.0)
    return (np.sqrt(disc) - 1) * s / (2 * c)


def _plane_filter(noise: np.ndarray, a: float) -> np.ndarray:
    out = noise
    for axis in (-2, -1):
        out = out + a * (np.roll(out, 2, axis=axis) + np.roll(out, -2, axis=axis))
    return out / (1 + 2 * a * a)


def simulate(model: LoopModel, spec: SimSpec, rng, sensor: dict) -> np.ndarray:
    """(n, H, W) float32 frames in DN drawn from ``model`` for one sequence."""
    e = model.effects
    shape = spec.signal_dn.shape
    n = spec.n
    s = model.full_scale_dn
    c = e.get("nonlinearity", {}).get("c", 0.0)
    lin = _nonlin_inv(np.maximum(spec.signal_dn, 0.0), c, s)
    kg = model.K * site_map(model.gains(), shape)
    mu_e = lin / kg
    if sensor["prnu"] is not None and not spec.fixed_in_clean:
        mu_e = mu_e * sensor["prnu"]
    lam = np.broadcast_to(mu_e, (n,) + shape)
    if "frame_flicker" in e:
        lam = lam * (1 + rng.normal(0, e["frame_flicker"]["sigma"], (n, 1, 1)))
    x = kg * rng.poisson(np.maximum(lam, 0)).astype(np.float64) if np.any(mu_e > 0) else np.zeros((n,) + shape)
    if "heavy_tail_read" in e:
        t = e["heavy_tail_read"]["lam"]
        read = tukey_sample(t, (n,) + shape, rng) / np.sqrt(tukey_var(t))
    else:
        read = rng.standard_normal((n,) + shape)
    if "spatial_correlation" in e:
        read = _plane_filter(read, e["spatial_correlation"]["a"])
    x += model.read_dn * read
    if "row_noise" in e:
        x += rng.normal(0, e["row_noise"]["sigma_dn"], (n, shape[0], 1))
    if "periodic_pattern" in e:
        p = e["periodic_pattern"]
        phase = rng.uniform(0, 2 * np.pi, (n, 1, 1))
        if p.get("axis", "row") == "row":
            idx = np.arange(shape[0])[None, :, None]
        else:
            idx = np.arange(shape[1])[None, None, :]
        x += p["amplitude_dn"] * np.sin(2 * np.pi * idx / p["period_px"] + phase)
    if c:
        x = _nonlin(x, c, s)
    v = site_map(model.black_dn.ravel(), shape) + x
    if not spec.fixed_in_clean:
        v += sensor["offset"]
    q = model.q
    return np.clip(np.round(v / q) * q, 0, model.white_dn).astype(np.float32)


#: Which simulator the loop uses: "internal" (this module) or "simcam" (simcam.noise composite,
#: :mod:`simcam.dataset.loop_backend`).
BACKENDS = ("internal", "simcam")


def simulate_capture(model: LoopModel, specs: list[SimSpec], rng, backend: str = "internal") -> list[np.ndarray]:
    """One simulated sensor, all sequences of ``specs`` (same geometry)."""
    if backend == "simcam":
        from .loop_backend import simulate_simcam

        sensor = {"seed": int(rng.integers(0, 2**31))}
        return [simulate_simcam(model, sp, rng, sensor) for sp in specs]
    sensor = draw_sensor(model, specs[0].signal_dn.shape, rng)
    return [simulate(model, sp, rng, sensor) for sp in specs]


def marginal_variance(model: LoopModel, signal_dn: np.ndarray, *, fixed_in_clean: bool = False) -> np.ndarray | None:
    """Per-pixel variance (DN^2) of the model's marginal about the plane mean, or None
    when the marginal is not Gaussian (heavy-tailed read noise, hot pixels)."""
    e = model.effects
    if "heavy_tail_read" in e or "hot_pixels" in e:
        return None
    shape = signal_dn.shape
    s = model.full_scale_dn
    c = e.get("nonlinearity", {}).get("c", 0.0)
    lin = _nonlin_inv(np.maximum(signal_dn, 0.0), c, s)
    kg = model.K * site_map(model.gains(), shape)
    v = kg * lin + model.read_dn ** 2
    v = v + e.get("row_noise", {}).get("sigma_dn", 0.0) ** 2
    if "periodic_pattern" in e:
        v = v + e["periodic_pattern"]["amplitude_dn"] ** 2 / 2
    if "frame_flicker" in e:
        v = v + (e["frame_flicker"]["sigma"] * lin) ** 2
    if not fixed_in_clean:
        if "prnu" in e:
            v = v + (e["prnu"]["sigma"] * lin) ** 2
        v = v + e.get("dsnu", {}).get("sigma_dn", 0.0) ** 2 + e.get("column_fpn", {}).get("sigma_dn", 0.0) ** 2
    if c:
        v = v * (1 + 2 * c * lin / s) ** 2
    return v + model.q ** 2 / 12.0
