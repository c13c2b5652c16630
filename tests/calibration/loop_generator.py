"""Test-owned hidden-effect sensor generator for the ``simcam loop`` tests.

Plain numpy; it deliberately does NOT import simcam's noise code, so the loop
is tested against an independent implementation of the physics.

Signal chain (all in DN, per pixel ``p`` of frame ``f``; EMVA 1288 R4.0 sec. 2,
seed eq. 3.6 for the Poisson-Gaussian core)::

    e      ~ Poisson(mu_e[p] * (1 + prnu[p]) * (1 + flicker[f]))        photo-electrons
    e      = (1 - 4 c_x) e + c_x * (4 adjacent e)                       charge crosstalk
    e     += Poisson(dark_rate[p] * t)                                  dark electrons (exposure t)
    x      = K * g[c] * e + read[f, p] + row[f, r] + periodic[f, r]     DN, linear
    y      = x + c_nl * x**2 / (white - black)                          compressive response
    v      = black + offset + dsnu[p] + col[c] + hot[p] + y
    frame  = clip(round(v / q) * q, 0, 2**bits - 1)                     ADC (or adc_dnl's codes)

* ``K`` system gain (DN/e-), ``g[c]`` per-CFA-site gain (``channel_gain``).
* ``read`` Gaussian N(0, read_dn^2), or Tukey-lambda(lam) scaled to the same
  variance (``heavy_tail_read``; ELD, Wei et al. CVPR 2020), optionally
  filtered inside each CFA plane by the separable kernel [a, 1, a]
  (``spatial_correlation``; with ``neighbours: adjacent``, on the mosaic), renormalised to keep its variance.
* ``row`` N(0, sigma^2) per frame and row (``row_noise``); ``periodic`` a sine
  along the row index with a random phase per frame (``periodic_pattern``).
* Fixed patterns are drawn once per sensor (``sensor_seed``) and shared by all
  sequences: ``dsnu`` N(0, s^2) per pixel, ``col`` N(0, s^2) per column
  (``column_fpn``), ``prnu`` N(0, s^2) per pixel, ``hot`` a set of pixels with
  an exponential extra offset (``hot_pixels``).
* ``dark_rate`` (``dark_current``) log-normal per pixel (mean ``rate_e_per_s``, log-spread
  ``log_sigma``), drawn once per sensor; with it, :func:`capture_set` adds a second dark at 1 s.
* ``amp_glow``: dark electrons at ``rate_e_per_s`` x exp(-d / (``scale`` L)) per second, d the distance
  from ``origin`` (a corner: L the diagonal; an edge: L the extent across it), added to ``dark_rate``;
  with it, too, :func:`capture_set` adds the dark at 1 s.
* ``charge_crosstalk``: photo-electrons (with their shot noise) shared with the 4 adjacent pixels,
  share ``c`` each (circular at the borders), before dark electrons and read noise.
* ``flicker`` N(0, s^2) per frame, only where there is light (``frame_flicker``).
* ``rtn``: a set of pixels (``fraction``, drawn once per sensor, after the other patterns) with steps
  log-normal about ``amplitude_dn`` (spread ``log_sigma``), added to ``x`` in the frames where the
  pixel's trap is in its high state (probability ``p_high``, independently per frame): random
  telegraph noise.
* ``adc_dnl``: the ADC's transition levels ``k + 1/2 + u_k``, ``u_k ~ N(0, dnl_sigma^2)`` LSB drawn once per
  sensor (sorted), instead of rounding: codes of unequal width (differential non-linearity).
* ``column_noise`` N(0, s^2) per frame and column: deliberately *outside* simcam's effect
  vocabulary (temporal column noise), to test that the loop reports it as unexplained.
* ``interleaved_columns``: columns in groups of ``period_px / 2`` alternate between two converters whose
  offsets differ by ``offset_dn`` (fixed, no random draw): also outside the vocabulary (a periodic
  column pattern, ``empirical_lines``).
* ``row_wander``: per frame, row offsets that follow a first-order autoregression down the frame
  (``o_i = rho o_(i-1) + sqrt(1 - rho^2) sigma_dn n_i``): coloured row noise, outside the vocabulary
  (``empirical_spectrum``).
* ``black_wander``: a black level that wanders from frame to frame, a first-order autoregression over
  the frames of each sequence (``b_f = rho b_(f-1) + sqrt(1 - rho^2) sigma_dn n_f``), the same for every
  pixel: outside the vocabulary (``empirical_offset``, frame form).
* ``pixel_curvature``: each pixel's response bends by its own amount, ``x + c_p x^2 / (white - black)``
  where ``nonlinearity`` acts, ``c_p ~ N(c_mean, c_sd^2)`` drawn once per sensor (after the other
  patterns): outside the vocabulary (``empirical_response``).
* ``checker_offset`` N(0, s^2) per frame, added with opposite signs to the 00/11 and the 01/10
  sites (interleaved readout channels, as in the EMVA 1288 CCD data): also outside the vocabulary.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

EFFECTS = (
    "row_noise", "column_fpn", "dsnu", "prnu", "hot_pixels", "heavy_tail_read", "quantization",
    "spatial_correlation", "periodic_pattern", "black_level_offset", "frame_flicker",
    "nonlinearity", "channel_gain", "dark_current", "dead_pixels", "amp_glow",
    "rtn", "adc_dnl", "charge_crosstalk",
)

#: Parameters the tests use for each effect alone (chosen well above the
#: detection floor of a 64x64, 12-frame capture set; units in the names).
DEFAULT_EFFECTS = {
    "row_noise": {"sigma_dn": 1.5},
    "column_fpn": {"sigma_dn": 1.5},
    "dsnu": {"sigma_dn": 2.5},
    "prnu": {"sigma": 0.02},
    "hot_pixels": {"fraction": 0.004, "mean_dn": 60.0},
    "heavy_tail_read": {"lam": -0.25},
    "quantization": {"step_dn": 4},
    "spatial_correlation": {"a": 0.35},
    "periodic_pattern": {"amplitude_dn": 2.0, "period_px": 8.0},
    "black_level_offset": {"offset_dn": 6.0},
    "frame_flicker": {"sigma": 0.01},
    "nonlinearity": {"c": -0.12},
    "channel_gain": {"gains": [1.15, 1.0, 1.0, 0.85]},
    "dark_current": {"rate_e_per_s": 40.0, "log_sigma": 0.3},
    "dead_pixels": {"dead_fraction": 0.004, "stuck_fraction": 0.002},
    "rtn": {"fraction": 0.015, "amplitude_dn": 20.0, "log_sigma": 0.3, "p_high": 0.4},
    "amp_glow": {"rate_e_per_s": 40.0, "origin": "top_right", "scale": 0.2},
    "adc_dnl": {"dnl_sigma": 0.2},
    "charge_crosstalk": {"c": 0.05},
}


@dataclass
class SensorSpec:
    """Base Poisson-Gaussian sensor + hidden effects (see the module docstring)."""

    height: int = 64
    width: int = 64
    bits: int = 10
    K: float = 2.0  # DN / e-
    read_dn: float = 3.0
    black_dn: float = 64.0
    cfa: str | None = "RGGB"
    iso: int = 800
    effects: dict = field(default_factory=dict)
    sensor_seed: int = 1

    @property
    def white_dn(self) -> float:
        return float(2 ** self.bits - 1)


def _tukey(lam: float, size, rng) -> np.ndarray:
    """Tukey-lambda quantile transform Q(u) = (u^lam - (1-u)^lam) / lam."""
    u = rng.random(size)
    u = np.clip(u, 1e-12, 1 - 1e-12)
    if abs(lam) < 1e-9:
        return np.log(u / (1 - u))
    return (u ** lam - (1 - u) ** lam) / lam


def _tukey_var(lam: float) -> float:
    from math import gamma

    if abs(lam) < 1e-9:
        return np.pi ** 2 / 3
    return 2.0 / lam ** 2 * (1.0 / (1 + 2 * lam) - gamma(lam + 1) ** 2 / gamma(2 * lam + 2))


def _plane_filter(noise: np.ndarray, a: float, step: int = 2) -> np.ndarray:
    """Separable [a, 1, a] filter inside each 2x2 CFA plane (circular), unit variance gain; ``step`` 1: on the
    mosaic (adjacent pixels)."""
    out = noise.copy()
    for axis in (-2, -1):
        out = out + a * (np.roll(out, step, axis=axis) + np.roll(out, -step, axis=axis))
    return out / (1 + 2 * a * a)


class HiddenEffectSensor:
    """A sensor whose fixed patterns are drawn once from ``spec.sensor_seed``."""

    def __init__(self, spec: SensorSpec):
        self.spec = spec
        eff = spec.effects
        rng = np.random.default_rng(spec.sensor_seed)
        h, w = spec.height, spec.width
        self.offset = np.zeros((h, w))
        if "dsnu" in eff:
            self.offset += rng.normal(0, eff["dsnu"]["sigma_dn"], (h, w))
        if "column_fpn" in eff:
            self.offset += rng.normal(0, eff["column_fpn"]["sigma_dn"], (1, w))
        if "interleaved_columns" in eff:  # NOT in the vocabulary: two column converters' offset mismatch
            p = eff["interleaved_columns"]
            half = int(p["period_px"]) // 2
            self.offset += np.where((np.arange(w) // half) % 2 == 0, 0.5, -0.5)[None, :] * p["offset_dn"]
        if "hot_pixels" in eff:
            p = eff["hot_pixels"]
            hot = rng.random((h, w)) < p["fraction"]
            self.offset += hot * rng.exponential(p["mean_dn"], (h, w))
            self.hot_mask = hot
        self.checker = np.ones((h, w))
        self.checker[0::2, 1::2] = -1.0
        self.checker[1::2, 0::2] = -1.0
        self.prnu = np.ones((h, w))
        if "prnu" in eff:
            self.prnu += rng.normal(0, eff["prnu"]["sigma"], (h, w))
        self.dark_rate = None
        if "dark_current" in eff:
            p = eff["dark_current"]
            self.dark_rate = p["rate_e_per_s"] * np.exp(p["log_sigma"] * rng.standard_normal((h, w))
                                                        - p["log_sigma"] ** 2 / 2)
        if "amp_glow" in eff:  # deterministic: draws nothing from the sensor's generator
            p = eff["amp_glow"]
            yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
            dy = yy if "top" in p["origin"] else h - 1 - yy
            dx = xx if "left" in p["origin"] else w - 1 - xx
            if p["origin"] in ("top", "bottom"):
                dist, length = dy, h
            elif p["origin"] in ("left", "right"):
                dist, length = dx, w
            else:
                dist, length = np.hypot(dy, dx), np.hypot(h, w)
            glow = p["rate_e_per_s"] * np.exp(-dist / (p["scale"] * length))
            self.dark_rate = glow if self.dark_rate is None else self.dark_rate + glow
        self.gain = np.ones((h, w))
        if "channel_gain" in eff:
            g = eff["channel_gain"]["gains"]
            for k, (dy, dx) in enumerate(((0, 0), (0, 1), (1, 0), (1, 1))):
                self.gain[dy::2, dx::2] = g[k]
        self.dead = self.stuck = None
        if "dead_pixels" in eff:  # drawn last: the other effects' patterns are those of a sensor without
            p = eff["dead_pixels"]
            u = rng.random((h, w))
            self.dead = u < p["dead_fraction"]  # no photo-response: black + read noise
            self.stuck = (u >= p["dead_fraction"]) & (u < p["dead_fraction"] + p["stuck_fraction"])  # white
        self.rtn_idx = self.rtn_amp = None
        if "rtn" in eff:  # drawn after the others: their patterns are those of a sensor without
            p = eff["rtn"]
            self.rtn_idx = np.flatnonzero(rng.random((h, w)) < p["fraction"])
            s = p.get("log_sigma", 0.0)
            self.rtn_amp = p["amplitude_dn"] * np.exp(s * rng.standard_normal(self.rtn_idx.size) - s * s / 2)
        self.adc_edges = None
        if "adc_dnl" in spec.effects:  # transition levels off their ideal places, drawn once (sorted: no overlap)
            n = 2 ** spec.bits
            self.adc_edges = np.sort(np.arange(n - 1) + 0.5 + rng.normal(0, spec.effects["adc_dnl"]["dnl_sigma"], n - 1))
        self.curvature = None
        if "pixel_curvature" in eff:  # NOT in the vocabulary; drawn last: the other patterns are a plain sensor's
            p = eff["pixel_curvature"]
            self.curvature = p["c_mean"] + p["c_sd"] * rng.standard_normal((h, w))

    def frames(self, mu_e: np.ndarray | float, n_frames: int, rng, exposure_s: float = 0.01) -> np.ndarray:
        """``n_frames`` x H x W frames in DN (float32 holding integer codes) at ``exposure_s`` seconds."""
        s, eff = self.spec, self.spec.effects
        h, w = s.height, s.width
        mu = np.broadcast_to(np.asarray(mu_e, dtype=np.float64), (h, w)) * self.prnu
        out = np.empty((n_frames, h, w), dtype=np.float32)
        wander = np.zeros(n_frames)
        if "black_wander" in eff:  # NOT in the vocabulary: a black level wandering over the sequence (AR(1))
            p = eff["black_wander"]
            rho = float(p["rho"])
            wander[0] = rng.normal(0, p["sigma_dn"])
            kick = rng.normal(0, p["sigma_dn"] * np.sqrt(1 - rho * rho), n_frames)
            for f in range(1, n_frames):
                wander[f] = rho * wander[f - 1] + kick[f]
        for f in range(n_frames):
            lam = mu
            if "frame_flicker" in eff:
                lam = lam * (1 + rng.normal(0, eff["frame_flicker"]["sigma"]))
            e = rng.poisson(np.maximum(lam, 0))
            if "charge_crosstalk" in eff:  # photo-electrons shared with the 4 adjacent pixels (circular)
                c = eff["charge_crosstalk"]["c"]
                e = (1 - 4 * c) * e + c * sum(np.roll(e, k, axis=a) for a in (0, 1) for k in (1, -1))
            if self.dark_rate is not None:
                e = e + rng.poisson(self.dark_rate * exposure_s)
            if self.dead is not None:
                e = np.where(self.dead, 0, e)
            x = s.K * self.gain * e
            if "heavy_tail_read" in eff:
                t = eff["heavy_tail_read"]["lam"]
                read = _tukey(t, (h, w), rng) / np.sqrt(_tukey_var(t))
            else:
                read = rng.standard_normal((h, w))
            if "spatial_correlation" in eff:
                sc = eff["spatial_correlation"]
                read = _plane_filter(read, sc["a"], 1 if sc.get("neighbours") == "adjacent" else 2)
            x = x + s.read_dn * read
            if self.rtn_idx is not None:  # each trap in its high state with probability p_high, every frame
                high = rng.random(self.rtn_idx.size) < eff["rtn"]["p_high"]
                x.reshape(-1)[self.rtn_idx] += self.rtn_amp * high
            if "row_noise" in eff:
                x = x + rng.normal(0, eff["row_noise"]["sigma_dn"], (h, 1))
            if "column_noise" in eff:  # NOT in simcam's vocabulary: tests the 'unexplained' path
                x = x + rng.normal(0, eff["column_noise"]["sigma_dn"], (1, w))
            if "row_wander" in eff:  # NOT in the vocabulary: row offsets wandering down the frame (AR(1))
                p = eff["row_wander"]
                rho = float(p["rho"])
                o = np.empty(h)
                o[0] = rng.normal(0, p["sigma_dn"])
                kick = rng.normal(0, p["sigma_dn"] * np.sqrt(1 - rho * rho), h)
                for i in range(1, h):
                    o[i] = rho * o[i - 1] + kick[i]
                x = x + o[:, None]
            if "checker_offset" in eff:  # NOT in the vocabulary: interleaved readout channels' offset
                x = x + rng.normal(0, eff["checker_offset"]["sigma_dn"]) * self.checker
            if "periodic_pattern" in eff:
                p = eff["periodic_pattern"]
                r = np.arange(h)[:, None]
                x = x + p["amplitude_dn"] * np.sin(2 * np.pi * r / p["period_px"] + rng.uniform(0, 2 * np.pi))
            if "nonlinearity" in eff:
                x = x + eff["nonlinearity"]["c"] * x ** 2 / (s.white_dn - s.black_dn)
            if self.curvature is not None:  # each pixel's response bends by its own amount
                x = x + self.curvature * x ** 2 / (s.white_dn - s.black_dn)
            v = s.black_dn + eff.get("black_level_offset", {}).get("offset_dn", 0.0) + self.offset + x + wander[f]
            q = eff.get("quantization", {}).get("step_dn", 1)
            if self.adc_edges is not None:  # code k spans [edges[k-1], edges[k])
                out[f] = np.clip(np.searchsorted(self.adc_edges, v, side="right"), 0, s.white_dn)
            else:
                out[f] = np.clip(np.round(v / q) * q, 0, s.white_dn)
            if self.stuck is not None:
                out[f][self.stuck] = s.white_dn
        return out


def capture_set(spec: SensorSpec, *, n_frames: int = 12, flat_levels=(0.15, 0.35, 0.55, 0.75),
                colour=(0.8, 1.0, 1.0, 0.7), seed: int = 7, scene: bool = False) -> dict:
    """A capture set ``{name: (kind, frames, meta)}``: one dark and several flat sequences.

    ``flat_levels`` are mean signals as fractions of (white - black); ``colour``
    the relative flux on the four CFA sites.
    """
    sensor = HiddenEffectSensor(spec)
    rng = np.random.default_rng(seed)
    full = spec.white_dn - spec.black_dn
    site = np.ones((spec.height, spec.width))
    if spec.cfa:
        for k, (dy, dx) in enumerate(((0, 0), (0, 1), (1, 0), (1, 1))):
            site[dy::2, dx::2] = colour[k]
    meta = {"iso": spec.iso, "cfa": spec.cfa, "black_level": spec.black_dn, "white_level": spec.white_dn}
    out = {"dark": ("dark", sensor.frames(0.0, n_frames, rng), dict(meta, exposure_s=0.01))}
    if "dark_current" in spec.effects or "amp_glow" in spec.effects:
        out["dark_long"] = ("dark", sensor.frames(0.0, n_frames, rng, 1.0), dict(meta, exposure_s=1.0))
    for i, lev in enumerate(flat_levels):
        mu_e = lev * full / spec.K * site
        out[f"flat_{i}"] = ("flat", sensor.frames(mu_e, n_frames, rng, 0.01 * (i + 1)),
                            dict(meta, exposure_s=0.01 * (i + 1)))
    if scene:
        yy, xx = np.mgrid[0:spec.height, 0:spec.width]
        mu_e = (0.1 + 0.5 * xx / spec.width) * full / spec.K * site
        out["scene"] = ("scene", sensor.frames(mu_e, n_frames, rng, 0.02), dict(meta, exposure_s=0.02))
    return out


def write_capture_set(root: Path, captures: dict) -> Path:
    """Write each sequence as ``root/<name>/frame_NNN.npy`` + ``sequence.yaml``."""
    root = Path(root)
    for name, (_kind, frames, meta) in captures.items():
        d = root / name
        d.mkdir(parents=True, exist_ok=True)
        for i, fr in enumerate(frames):
            np.save(d / f"frame_{i:03d}.npy", fr.astype(np.uint16))
        (d / "sequence.yaml").write_text(yaml.safe_dump({k: (float(v) if isinstance(v, float) else v)
                                                         for k, v in meta.items()}))
    return root


def write_capture_set_dng(root: Path, captures: dict) -> Path:
    """Write each sequence as ``root/<name>/frame_NNN.dng`` (simcam's DNG writer; ISO,
    exposure, CFA, black and white levels in the tags)."""
    from simcam.frame import CameraMeta
    from simcam.io.dng_write import write_dng

    root = Path(root)
    for name, (_kind, frames, meta) in captures.items():
        d = root / name
        d.mkdir(parents=True, exist_ok=True)
        cm = CameraMeta(make="loopgen", model="hidden-effect sensor", cfa=meta["cfa"] or "RGGB",
                        black_level=np.full((1, 1), float(meta["black_level"])),
                        white_level=float(meta["white_level"]), iso=float(meta["iso"]),
                        exposure_time_s=float(meta["exposure_s"]))
        for i, fr in enumerate(frames):
            write_dng(d / f"frame_{i:03d}.dng", fr, cm)
    return root
