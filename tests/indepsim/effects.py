"""Switchable sensor effects, each with its physics, parameters (physical units) and magnitude range.

Every class has ``name`` (the truth-manifest name), ``ranges`` (``{param: (lo, hi)}``: the
realistic range a case draws each magnitude from, uniformly or log-uniformly when
``log_params`` lists it) and hooks called by :class:`tests.indepsim.sensor.SensorModel`
in chain order. Effects named ``undeclared_*`` carry a ``family`` dict
(temporal|fixed; pixel|row|column|frame|smooth_field|code; additive|multiplicative;
exposure_dependent: the DN magnitude grows with exposure time or collected charge).
Sources: EMVA Standard 1288 Release 4.0 (sec. 2 linear model, sec. 8 non-uniformity);
A. Abdelhamed, "Noise Modelling for Smartphone Cameras", PhD dissertation, York
University, 2020, chapter 2 (noise sources); J. Janesick, "Photon Transfer", SPIE 2007.
"""

from __future__ import annotations

import zlib
from typing import ClassVar

import numpy as np


def stable_id(name: str) -> int:
    return zlib.crc32(name.encode())


def _smooth_noise(rng, H, W, scale):
    """Zero-mean unit-rms smooth field: white noise low-passed in Fourier space (scale in pixels)."""
    n = rng.standard_normal((H, W))
    fy = np.fft.fftfreq(H)[:, None]
    fx = np.fft.rfftfreq(W)[None, :]
    f = np.fft.irfft2(np.fft.rfft2(n) * np.exp(-0.5 * (fy ** 2 + fx ** 2) * (2 * np.pi * scale) ** 2), s=(H, W))
    return (f / max(f.std(), 1e-12)).astype(np.float32)


def _shift_sum4(a):
    """Sum of the 4 nearest neighbours with edge replication."""
    p = np.pad(a, 1, mode="edge")
    return p[:-2, 1:-1] + p[2:, 1:-1] + p[1:-1, :-2] + p[1:-1, 2:]


class Effect:
    name = ""
    order = 50
    ranges: ClassVar[dict] = {}
    log_params: tuple = ()
    family: ClassVar[dict | None] = None

    def __init__(self, **params):
        unknown = set(params) - set(self.ranges)
        if unknown:
            raise ValueError(f"effect {self.name}: unknown parameter(s) {sorted(unknown)}; expected {sorted(self.ranges)}")
        missing = set(self.ranges) - set(params)
        if missing:
            raise ValueError(f"effect {self.name}: missing parameter(s) {sorted(missing)}")
        self.params = {k: float(v) for k, v in params.items()}
        for k, v in self.params.items():
            setattr(self, k, v)

    @classmethod
    def draw(cls, rng: np.random.Generator) -> dict:
        """Draw every magnitude from its range (log-uniform for ``log_params``)."""
        out = {}
        for k, (lo, hi) in cls.ranges.items():
            if k in cls.log_params:
                out[k] = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
            else:
                out[k] = float(rng.uniform(lo, hi))
        return out

    # hooks (identity by default)
    def setup(self, m, rng): pass
    def adjust_black(self, m): pass
    def mean_signal(self, m, mu, ctx): return mu
    def mean_dark(self, m, mu, ctx): return mu
    def electrons(self, m, e, ctx): return e
    def after_full_well(self, m, e, ctx): return e
    def read_noise(self, m, ctx): return None
    def read_e(self, m, e, ctx): return e
    def analog_gain(self, m, g, ctx): return g
    def analog_dn(self, m, v, ctx): return v
    def adc(self, m, v, ctx): return None
    def output(self, m, code, ctx): return code

    def truth(self) -> dict:
        d = {"params": dict(self.params), "doc": " ".join(x.strip() for x in (self.__doc__ or "").split())}
        if self.family:
            f = self.family
            d["family"] = dict(f)
            d["family_str"] = (f"{f['time']};{f['support']};{f['mode']};"
                               f"exposure_dependent={'true' if f['exposure_dependent'] else 'false'}")
        return d


# ----------------------------------------------------------------- named effects
class RowNoise(Effect):
    """Temporal row noise: each row gets a fresh offset every frame (shared row amplifier / reference).

    ``sigma_e``: rms of the per-row offset, input-referred e- (so in DN it grows with ISO).
    """
    name, order = "row_noise", 60
    ranges: ClassVar[dict] = {"sigma_e": (0.3, 3.0)}
    log_params = ("sigma_e",)

    def read_e(self, m, e, ctx):
        return e + (ctx.rng.standard_normal((e.shape[0], 1)) * self.sigma_e).astype(np.float32)


class ColumnFPN(Effect):
    """Fixed column offsets (column amplifier / column ADC offset mismatch), constant over frames.

    ``sigma_dn``: rms of the per-column offset in DN (post-gain, ISO-independent).
    """
    name, order = "column_fpn", 70
    ranges: ClassVar[dict] = {"sigma_dn": (0.3, 4.0)}
    log_params = ("sigma_dn",)

    def setup(self, m, rng):
        self.col = (rng.standard_normal((1, m.spec.width)) * self.sigma_dn).astype(np.float32)

    def analog_dn(self, m, v, ctx):
        return v + self.col


class DSNU(Effect):
    """Dark signal non-uniformity: fixed per-pixel offset (source-follower threshold mismatch).

    ``sigma_dn``: rms of the per-pixel offset in DN, Gaussian (EMVA 1288 R4.0 sec. 8, DSNU).
    """
    name, order = "dsnu", 70
    ranges: ClassVar[dict] = {"sigma_dn": (0.3, 5.0)}
    log_params = ("sigma_dn",)

    def setup(self, m, rng):
        self.map = (rng.standard_normal((m.spec.height, m.spec.width)) * self.sigma_dn).astype(np.float32)

    def analog_dn(self, m, v, ctx):
        return v + self.map


class PRNU(Effect):
    """Photo-response non-uniformity: fixed per-pixel relative gain of the photo signal.

    ``sigma_rel``: rms of ``(1 + n)``'s deviation, Gaussian n (EMVA 1288 R4.0 sec. 8, PRNU); acts on
    the mean photo-electrons, so the shot noise follows the pixel's own mean.
    """
    name, order = "prnu", 10
    ranges: ClassVar[dict] = {"sigma_rel": (0.003, 0.03)}
    log_params = ("sigma_rel",)

    def setup(self, m, rng):
        self.map = np.maximum(1.0 + rng.standard_normal((m.spec.height, m.spec.width)) * self.sigma_rel,
                              0.0).astype(np.float32)

    def mean_signal(self, m, mu, ctx):
        return mu * self.map


class HotPixels(Effect):
    """Hot pixels: a few pixels with large fixed dark signal (lattice defects with high generation).

    ``fraction``: share of pixels; ``offset_e``: median fixed charge (e-, log-normal spread 0.5);
    ``rate_e_per_s``: median extra dark current (e-/s, log-normal spread 0.7). Poisson-sampled.
    """
    name, order = "hot_pixels", 20
    ranges: ClassVar[dict] = {"fraction": (2e-4, 2e-3), "offset_e": (50.0, 600.0), "rate_e_per_s": (20.0, 500.0)}
    log_params = ("fraction", "offset_e", "rate_e_per_s")

    def setup(self, m, rng):
        H, W = m.spec.height, m.spec.width
        n = max(1, round(self.fraction * H * W))
        self.idx = rng.choice(H * W, n, replace=False)
        self.off = (self.offset_e * rng.lognormal(0, 0.5, n)).astype(np.float32)
        self.rate = (self.rate_e_per_s * rng.lognormal(0, 0.7, n)).astype(np.float32)

    def mean_dark(self, m, mu, ctx):
        mu.reshape(-1)[self.idx] += self.off + self.rate * np.float32(ctx.exposure_s)
        return mu


class HeavyTailRead(Effect):
    """Non-Gaussian read noise: Student-t with ``nu`` degrees of freedom, same rms as the Gaussian.

    Replaces the Gaussian pre-gain read noise (source-follower 1/f and RTS bursts give heavy
    tails). ``nu`` in (2.5, 8): smaller = heavier tails (excess kurtosis 6/(nu-4) for nu>4).
    """
    name, order = "heavy_tail_read", 50
    ranges: ClassVar[dict] = {"nu": (2.5, 8.0)}

    def read_noise(self, m, ctx):
        H, W = m.spec.height, m.spec.width
        t = ctx.rng.standard_t(self.nu, (H, W))
        return (t * np.sqrt((self.nu - 2) / self.nu) * m.spec.read_noise_e).astype(np.float32)


class Quantization(Effect):
    """Coarse ADC: codes ``step_dn`` DN wide (a lower-resolution ADC scaled to the full range).

    ``step_dn``: code width in DN (integer 4..16); quantisation variance step^2/12 (EMVA 1288 eq. 6).
    """
    name, order = "quantization", 90
    ranges: ClassVar[dict] = {"step_dn": (4.0, 16.0)}

    def __init__(self, **p):
        super().__init__(**p)
        self.step_dn = float(round(self.step_dn))
        self.params["step_dn"] = self.step_dn

    def adc(self, m, v, ctx):
        from .sensor import quantise
        dnl = next((e for e in m.effects if e.name == "adc_dnl"), None)
        if dnl is not None:  # a coarse ADC whose codes have unequal widths: the DNL acts on its codes
            return dnl.codes(v / np.float32(self.step_dn)) * np.float32(self.step_dn)
        return quantise(v, self.step_dn)


class SpatialCorrelation(Effect):
    """Electrical crosstalk: after read-out, each pixel's analogue value leaks ``coupling`` to each of
    its 4 neighbours (charge-conserving 3x3 cross kernel), so signal AND read noise are correlated.

    ``coupling``: fraction to each neighbour (0.01..0.08); adjacent-pixel correlation ~2c/(1-4c+...)
    on white noise.
    """
    name, order = "spatial_correlation", 80
    ranges: ClassVar[dict] = {"coupling": (0.01, 0.08)}

    def analog_dn(self, m, v, ctx):
        c = np.float32(self.coupling)
        return (1 - 4 * c) * v + c * _shift_sum4(v)


class PeriodicPattern(Effect):
    """Periodic interference (EMI / switching supply) banding: an oblique sinusoid whose phase is
    random each frame.

    ``amplitude_dn``: sine amplitude (DN); ``period_px``: spatial period along its direction (px);
    ``angle_deg``: 0 = vertical bands, near 90 = horizontal banding.
    """
    name, order = "periodic_pattern", 70
    ranges: ClassVar[dict] = {"amplitude_dn": (0.3, 3.0), "period_px": (6.0, 40.0), "angle_deg": (60.0, 89.0)}

    def analog_dn(self, m, v, ctx):
        H, W = v.shape
        a = np.deg2rad(self.angle_deg)
        y = np.arange(H, dtype=np.float32)[:, None]
        x = np.arange(W, dtype=np.float32)[None, :]
        ph = ctx.rng.uniform(0, 2 * np.pi)
        return v + np.float32(self.amplitude_dn) * np.sin(
            np.float32(2 * np.pi / self.period_px) * (x * np.float32(np.cos(a)) + y * np.float32(np.sin(a))) + ph
        ).astype(np.float32)


class BlackLevelOffset(Effect):
    """The true black level differs from the declared (metadata) black by ``offset_dn`` DN
    (black clamp error). Draw: ``|offset_dn|`` log-uniform in [1, 12] DN, sign +/- with equal odds."""
    name, order = "black_level_offset", 5
    ranges: ClassVar[dict] = {"offset_dn": (-12.0, 12.0)}

    @classmethod
    def draw(cls, rng):
        mag = float(np.exp(rng.uniform(np.log(1.0), np.log(12.0))))
        return {"offset_dn": mag if rng.uniform() < 0.5 else -mag}

    def adjust_black(self, m):
        m.black_true = m.black_true + np.float32(self.offset_dn)


class FrameFlicker(Effect):
    """Per-frame global change: illumination / gain flicker ``gain_sigma`` (relative rms of a per-frame
    factor on the photo signal) and per-frame black offset ``offset_sigma_dn`` (DN rms)."""
    name, order = "frame_flicker", 12
    ranges: ClassVar[dict] = {"gain_sigma": (0.002, 0.02), "offset_sigma_dn": (0.2, 2.0)}
    log_params = ("gain_sigma", "offset_sigma_dn")

    def mean_signal(self, m, mu, ctx):
        ctx.extra["flicker"] = ctx.rng.standard_normal(2)
        return mu * np.float32(max(1 + self.gain_sigma * ctx.extra["flicker"][0], 0))

    def analog_dn(self, m, v, ctx):
        return v + np.float32(self.offset_sigma_dn * ctx.extra["flicker"][1])


class Nonlinearity(Effect):
    """Compressive response near full well: ``e' = e / (1 + beta * e / FW)`` (floating-diffusion
    capacitance grows with charge; EMVA 1288 R4.0 sec. 6 linearity). ``beta``: 0.02..0.2, the
    relative compression at full well is beta/(1+beta)."""
    name, order = "nonlinearity", 40
    ranges: ClassVar[dict] = {"beta": (0.02, 0.2)}

    def after_full_well(self, m, e, ctx):
        return e / (1 + np.float32(self.beta / m.spec.full_well_e) * np.maximum(e, 0))


class ChannelGain(Effect):
    """Per-CFA-channel gain mismatch (separate column amplifiers per colour site): the 4 sites of the
    2x2 tile get gains ``1 + sigma_rel * n_c`` (n_c standard normal), fixed."""
    name, order = "channel_gain", 60
    ranges: ClassVar[dict] = {"sigma_rel": (0.01, 0.08)}

    def setup(self, m, rng):
        self.g = np.maximum(1 + rng.standard_normal(4) * self.sigma_rel, 0.5).astype(np.float32)

    def analog_gain(self, m, g, ctx):
        return g * self.g[m.chan]

    def truth(self):
        d = super().truth()
        d["site_gains"] = [float(x) for x in self.g]
        return d


# ------------------------------------------------------------------- new named
class DarkCurrent(Effect):
    """Thermal dark current: Poisson electrons with mean ``rate * t``, the rate per pixel log-normal
    with median ``rate_e_per_s`` (e-/s) and log-sigma ``spread`` (EMVA 1288 R4.0 sec. 7)."""
    name, order = "dark_current", 20
    ranges: ClassVar[dict] = {"rate_e_per_s": (0.5, 30.0), "spread": (0.2, 0.8)}
    log_params = ("rate_e_per_s",)

    def setup(self, m, rng):
        self.rate = (self.rate_e_per_s * rng.lognormal(0, self.spread, (m.spec.height, m.spec.width))).astype(np.float32)

    def mean_dark(self, m, mu, ctx):
        return mu + self.rate * np.float32(ctx.exposure_s)

    def truth(self):
        d = super().truth()
        d["mean_rate_e_per_s"] = float(self.rate.mean())
        return d


class DeadPixels(Effect):
    """Dead pixels: no photo-response (broken photodiode); they read black plus read noise whatever
    the light. ``fraction`` of pixels."""
    name, order = "dead_pixels", 11
    ranges: ClassVar[dict] = {"fraction": (1e-4, 1e-3)}
    log_params = ("fraction",)

    def setup(self, m, rng):
        H, W = m.spec.height, m.spec.width
        self.idx = rng.choice(H * W, max(1, round(self.fraction * H * W)), replace=False)

    def mean_signal(self, m, mu, ctx):
        mu.reshape(-1)[self.idx] = 0
        return mu


class StuckPixels(Effect):
    """Stuck pixels: read a fixed code whatever happens (shorted node); ``fraction`` of pixels,
    ``white_share`` of them stuck at the white level, the rest at a random code."""
    name, order = "stuck_pixels", 99
    ranges: ClassVar[dict] = {"fraction": (5e-5, 5e-4), "white_share": (0.3, 1.0)}
    log_params = ("fraction",)

    def setup(self, m, rng):
        H, W = m.spec.height, m.spec.width
        n = max(1, round(self.fraction * H * W))
        self.idx = rng.choice(H * W, n, replace=False)
        white = rng.uniform(size=n) < self.white_share
        self.val = np.where(white, m.spec.white_dn, rng.integers(0, m.spec.white_dn, n)).astype(np.float32)

    def output(self, m, code, ctx):
        code.reshape(-1)[self.idx] = self.val
        return code


class AdcDNL(Effect):
    """ADC differential non-linearity: code transition levels displaced by ``inl_dn`` (uniform
    random per code) plus a ``major_dn`` error at every 64-code major carry (SAR capacitor mismatch),
    so codes have unequal widths (DNL_k = w_k - 1). Mid-tread ideal code k spans [k-0.5, k+0.5).
    Beside ``quantization`` the ADC is the coarse one: the displacements are fractions of its code
    (``step_dn`` DN), and its codes are ``step_dn`` apart."""
    name, order = "adc_dnl", 91
    ranges: ClassVar[dict] = {"inl_dn": (0.1, 0.45), "major_dn": (0.0, 0.4)}

    def setup(self, m, rng):
        n = m.spec.white_dn + 1
        k = np.arange(n, dtype=np.float64)
        d = rng.uniform(-self.inl_dn, self.inl_dn, n)
        d += np.where(k % 64 == 0, self.major_dn, 0.0)
        self.edges = (k + 0.5 + d).astype(np.float64)  # upper edge of code k
        self.edges = np.maximum.accumulate(self.edges)

    def codes(self, v):
        """The codes of values ``v`` in code widths (code k spans ``[edges[k-1], edges[k])``)."""
        return np.searchsorted(self.edges, v.ravel(), side="right").reshape(v.shape).astype(np.float32)

    def adc(self, m, v, ctx):
        return self.codes(v)

    def truth(self):
        d = super().truth()
        w = np.diff(self.edges)
        d["dnl_rms"] = float(np.std(w - 1))
        return d


class RTN(Effect):
    """Random telegraph noise: ``fraction`` of pixels (a trap in the source-follower) switch between
    two levels ``amplitude_e`` apart (e-, log-normal spread 0.5 per pixel), state drawn each frame
    with probability ``p_high``."""
    name, order = "rtn", 55
    ranges: ClassVar[dict] = {"fraction": (0.002, 0.02), "amplitude_e": (4.0, 30.0), "p_high": (0.2, 0.5)}
    log_params = ("fraction", "amplitude_e")

    def setup(self, m, rng):
        H, W = m.spec.height, m.spec.width
        n = max(1, round(self.fraction * H * W))
        self.idx = rng.choice(H * W, n, replace=False)
        self.amp = (self.amplitude_e * rng.lognormal(0, 0.5, n)).astype(np.float32)

    def read_e(self, m, e, ctx):
        st = ctx.rng.uniform(size=self.idx.size) < self.p_high
        e.reshape(-1)[self.idx] += self.amp * st
        return e


class AmpGlow(Effect):
    """Amplifier glow: an on-chip amplifier near a corner emits photons, adding dark charge at
    ``rate_e_per_s`` (e-/s at the corner) decaying as exp(-d / ``length_frac`` * diagonal) with distance
    d from the corner; Poisson, exposure dependent."""
    name, order = "amp_glow", 21
    ranges: ClassVar[dict] = {"rate_e_per_s": (5.0, 200.0), "length_frac": (0.1, 0.4)}
    log_params = ("rate_e_per_s",)

    def setup(self, m, rng):
        H, W = m.spec.height, m.spec.width
        self.corner = int(rng.integers(0, 4))
        y = np.arange(H, dtype=np.float32)[:, None]
        x = np.arange(W, dtype=np.float32)[None, :]
        if self.corner & 1:
            x = (W - 1) - x
        if self.corner & 2:
            y = (H - 1) - y
        L = self.length_frac * np.hypot(H, W)
        self.map = (self.rate_e_per_s * np.exp(-np.sqrt(x * x + y * y) / L)).astype(np.float32)

    def mean_dark(self, m, mu, ctx):
        return mu + self.map * np.float32(ctx.exposure_s)

    def truth(self):
        d = super().truth()
        d["corner"] = ["top-left", "top-right", "bottom-left", "bottom-right"][self.corner]
        return d


class ChargeCrosstalk(Effect):
    """Charge crosstalk (diffusion): each pixel's photo-/dark electrons spill ``fraction`` to each of its
    4 neighbours BEFORE read-out (after shot noise), so flats show lower temporal variance
    (by ~(1-4f)^2+4f^2) and neighbour-correlated shot noise, but read noise stays white."""
    name, order = "charge_crosstalk", 30
    ranges: ClassVar[dict] = {"fraction": (0.01, 0.06)}

    def electrons(self, m, e, ctx):
        f = np.float32(self.fraction)
        return (1 - 4 * f) * e + f * _shift_sum4(e)


# -------------------------------------------------------------------- undeclared
class UColumnTemporal(Effect):
    """Column-wise temporal noise: each column gets a fresh offset each frame (column ADC comparator
    noise), ``sigma_dn`` DN rms."""
    name, order = "undeclared_column_temporal", 71
    ranges: ClassVar[dict] = {"sigma_dn": (0.3, 2.5)}
    log_params = ("sigma_dn",)
    family: ClassVar[dict | None] = {"time": "temporal", "support": "column", "mode": "additive", "exposure_dependent": False}

    def analog_dn(self, m, v, ctx):
        return v + (ctx.rng.standard_normal((1, v.shape[1])) * self.sigma_dn).astype(np.float32)


class UGainDrift(Effect):
    """System gain drifts linearly over a sequence (amplifier warming): frame i of n has gain
    ``1 + drift_rel * (i/(n-1) - 0.5)``; ``drift_rel`` total relative change over the sequence."""
    name, order = "undeclared_gain_drift", 61
    ranges: ClassVar[dict] = {"drift_rel": (0.005, 0.05)}
    family: ClassVar[dict | None] = {"time": "temporal", "support": "frame", "mode": "multiplicative", "exposure_dependent": True}

    def analog_gain(self, m, g, ctx):
        r = ctx.index / max(ctx.n_frames - 1, 1) - 0.5
        return g * np.float32(1 + self.drift_rel * r)


class UBlackDrift(Effect):
    """Black level drifts with die temperature over a sequence: offset ``drift_dn * (i/(n-1) - 0.5)``
    DN (a ramp, total ``drift_dn``) plus an exposure term ``per_s_dn * t`` (self-heating)."""
    name, order = "undeclared_black_drift", 72
    ranges: ClassVar[dict] = {"drift_dn": (0.5, 4.0), "per_s_dn": (0.0, 2.0)}
    family: ClassVar[dict | None] = {"time": "temporal", "support": "frame", "mode": "additive", "exposure_dependent": True}

    def analog_dn(self, m, v, ctx):
        r = ctx.index / max(ctx.n_frames - 1, 1) - 0.5
        return v + np.float32(self.drift_dn * r + self.per_s_dn * ctx.exposure_s)


class UInterleavedADC(Effect):
    """Interleaved column ADCs: columns in groups of 2 alternate between two converters (period 4
    columns, so not a CFA channel) with offset mismatch ``offset_dn`` and gain mismatch ``gain_rel``."""
    name, order = "undeclared_interleaved_adc", 73
    ranges: ClassVar[dict] = {"offset_dn": (0.5, 4.0), "gain_rel": (0.002, 0.02)}
    family: ClassVar[dict | None] = {"time": "fixed", "support": "column", "mode": "additive", "exposure_dependent": False}

    def analog_dn(self, m, v, ctx):
        W = v.shape[1]
        sgn = np.where((np.arange(W) // 2) % 2 == 0, 0.5, -0.5).astype(np.float32)[None, :]
        return v + sgn * np.float32(self.offset_dn) + sgn * np.float32(self.gain_rel) * v


class URow1f(Effect):
    """Row-correlated 1/f noise: per-frame row offsets whose spectrum along the row index falls as
    1/f^``alpha`` (flicker noise of the shared reference sampled row by row), ``sigma_e`` e- rms."""
    name, order = "undeclared_row_1f", 62
    ranges: ClassVar[dict] = {"sigma_e": (0.5, 4.0), "alpha": (0.7, 1.5)}
    log_params = ("sigma_e",)
    family: ClassVar[dict | None] = {"time": "temporal", "support": "row", "mode": "additive", "exposure_dependent": False}

    def read_e(self, m, e, ctx):
        H = e.shape[0]
        f = np.fft.rfftfreq(H)
        amp = np.zeros_like(f)
        amp[1:] = f[1:] ** (-self.alpha / 2)
        z = ctx.rng.standard_normal(f.size) + 1j * ctx.rng.standard_normal(f.size)
        r = np.fft.irfft(z * amp, n=H)
        r = r / max(np.sqrt(np.mean(r ** 2)), 1e-12) * self.sigma_e
        return e + r.astype(np.float32)[:, None]


class UPixelNonlinearity(Effect):
    """Pixel-dependent non-linearity: each pixel's response is ``e * (1 - c_p * e / FW)`` with
    ``c_p = |N(0, sigma)|`` fixed per pixel (floating-diffusion capacitance spread)."""
    name, order = "undeclared_pixel_nonlinearity", 41
    ranges: ClassVar[dict] = {"sigma": (0.01, 0.08)}
    family: ClassVar[dict | None] = {"time": "fixed", "support": "pixel", "mode": "multiplicative", "exposure_dependent": True}

    def setup(self, m, rng):
        self.c = np.abs(rng.standard_normal((m.spec.height, m.spec.width)) * self.sigma).astype(np.float32)

    def after_full_well(self, m, e, ctx):
        return e * (1 - self.c * np.maximum(e, 0) / np.float32(m.spec.full_well_e))


class USmear(Effect):
    """Vertical smear (frame-transfer CCD / global-shutter storage leakage): each pixel gains
    ``fraction`` x its column's mean photo-charge during transfer (shot-noise sampled); exposure-time
    independent at fixed signal, proportional to the collected light."""
    name, order = "undeclared_smear", 31
    ranges: ClassVar[dict] = {"fraction": (0.002, 0.02)}
    log_params = ("fraction",)
    family: ClassVar[dict | None] = {"time": "fixed", "support": "column", "mode": "additive", "exposure_dependent": True}

    def mean_signal(self, m, mu, ctx):
        return mu + np.float32(self.fraction) * mu.mean(axis=0, keepdims=True)


REGISTRY = {c.name: c for c in Effect.__subclasses__()}
NAMED_OLD = ["row_noise", "column_fpn", "dsnu", "prnu", "hot_pixels", "heavy_tail_read", "quantization",
             "spatial_correlation", "periodic_pattern", "black_level_offset", "frame_flicker", "nonlinearity",
             "channel_gain"]
NAMED_NEW = ["dark_current", "dead_pixels", "stuck_pixels", "adc_dnl", "rtn", "amp_glow", "charge_crosstalk"]
UNDECLARED = sorted(n for n in REGISTRY if n.startswith("undeclared_"))
