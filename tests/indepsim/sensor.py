"""An image-sensor model generated electron-domain first (EMVA 1288 R4.0 linear model).

Chain of one frame (EMVA Standard 1288 Release 4.0, sec. 2, eq. 1-6; Janesick,
"Photon Transfer", ch. 2-4; A. Abdelhamed, "Noise Modelling for Smartphone
Cameras", PhD dissertation, York University, 2020, chapter 2):

1. mean photo-electrons ``mu_p = flux_e * t`` per pixel (``flux_e`` = photons/s x QE,
   uniform for a flat, a smooth textured field for a scene, 0 for a dark);
   fixed multiplicative maps (PRNU, dead pixels) and illumination flicker act here;
2. mean dark electrons ``mu_d = offset_e + rate_e_per_s * t`` (dark current,
   hot pixels, amplifier glow);
3. shot noise: ``e = Poisson(mu_p) + Poisson(mu_d)``;
4. charge-domain effects (charge crosstalk, full-well clip, compressive non-linearity);
5. read-out in electrons (input-referred read noise ``read_noise_e``, row noise, RTN);
6. amplification: ``v = K(ISO) * g_c * e_read + N(0, adc_noise_dn)`` (``g_c`` per-CFA
   channel gain), DN-domain additive fields (column FPN, DSNU, periodic pattern,
   electrical crosstalk) and the true black level;
7. ADC: codes of width ``adc_step_dn`` (with optional DNL), clipped to ``[0, 2^bits-1]``;
8. output-level defects (stuck pixels).

``K(ISO) = k_base * ISO / iso_base`` (DN/e-), so the input-referred read noise is
``sqrt(read_noise_e^2 + (adc_noise_dn / K)^2)`` e- (Janesick, ch. 4: pre- and post-gain
noise). Every effect lives in :mod:`tests.indepsim.effects`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import effects as fx


@dataclass
class SensorSpec:
    """Sensor parameters in physical units.

    Parameters
    ----------
    width, height : int
        Pixels (even for a Bayer CFA).
    cfa : str or None
        "RGGB", "GRBG", "GBRG", "BGGR" or None for monochrome.
    bits : int
        ADC bit depth 8..16; white level ``2**bits - 1`` DN.
    black_dn : float or 2x2 list
        Declared black level (DN) per CFA site, written to the metadata.
    full_well_e : float
        Full-well capacity (e-).
    qe : float
        Quantum efficiency (photo-electrons per photon) for converting flux to photons.
    read_noise_e : float
        Pre-gain (input-referred) Gaussian read noise, e- rms.
    adc_noise_dn : float
        Post-gain noise (ADC / output buffer), DN rms.
    k_base : float or None
        System gain at ``iso_base`` (DN/e-); None = the ADC range maps to the full well.
    iso_base : int
        ISO of unity analogue gain.
    adc_step_dn : float
        Width of one ADC code in DN (1 for an ideal converter).
    """

    width: int = 192
    height: int = 128
    cfa: str | None = "RGGB"
    bits: int = 12
    black_dn: float | list = 256.0
    full_well_e: float = 12000.0
    qe: float = 0.6
    read_noise_e: float = 2.0
    adc_noise_dn: float = 0.6
    k_base: float | None = None
    iso_base: int = 100
    adc_step_dn: float = 1.0

    @property
    def white_dn(self) -> int:
        return 2 ** self.bits - 1

    def black_map2(self) -> np.ndarray:
        """Declared black level as a 2x2 array (DN)."""
        return np.broadcast_to(np.asarray(self.black_dn, dtype=np.float64), (2, 2)).copy()

    def gain(self, iso: float) -> float:
        """System gain K (DN/e-) at ``iso``."""
        kb = self.k_base
        if kb is None:
            kb = (self.white_dn - float(self.black_map2().max())) / self.full_well_e
        return float(kb) * float(iso) / float(self.iso_base)

    def saturation_e(self, iso: float) -> float:
        """Electrons at which the pixel saturates: full well or ADC top, whichever first."""
        return min(self.full_well_e, (self.white_dn - float(self.black_map2().max())) / self.gain(iso))

    def to_dict(self, isos=()) -> dict:
        d = {k: getattr(self, k) for k in self.__dataclass_fields__}
        d["white_dn"] = self.white_dn
        d["gain_dn_per_e"] = {str(i): self.gain(i) for i in isos}
        d["input_read_noise_e"] = {str(i): float(np.hypot(self.read_noise_e, self.adc_noise_dn / self.gain(i)))
                                   for i in isos}
        d["saturation_e"] = {str(i): self.saturation_e(i) for i in isos}
        return d


def scene_field(height: int, width: int, rng: np.random.Generator) -> np.ndarray:
    """A smooth, textured static scene: relative radiance in [0.05, 1] (float32).

    Sum of low-frequency sinusoids and Gaussian blobs plus a mid-frequency texture; the
    same ``rng`` gives the same scene.
    """
    y = np.linspace(0.0, 1.0, height, dtype=np.float32)[:, None]
    x = np.linspace(0.0, 1.0, width, dtype=np.float32)[None, :]
    f = np.zeros((height, width), np.float32)
    for _ in range(4):
        fx_, fy_ = rng.uniform(0.5, 3.0, 2)
        ph = rng.uniform(0, 2 * np.pi)
        f += np.float32(rng.uniform(0.3, 1.0)) * np.sin(2 * np.pi * (fx_ * x + fy_ * y) + ph).astype(np.float32)
    for _ in range(5):
        cx, cy, s = rng.uniform(0, 1), rng.uniform(0, 1), rng.uniform(0.05, 0.2)
        f += np.float32(rng.uniform(-1.5, 1.5)) * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * s * s))
    tex_f = rng.uniform(8, 20)
    f += np.float32(0.3) * (np.sin(2 * np.pi * tex_f * x) * np.sin(2 * np.pi * tex_f * 0.7 * y)).astype(np.float32)
    f -= f.min()
    f /= max(float(f.max()), 1e-6)
    return (0.05 + 0.95 * f).astype(np.float32)


@dataclass
class Context:
    """State of one frame passed to the effect hooks."""

    kind: str
    iso: float
    exposure_s: float
    gain: float
    index: int
    n_frames: int
    rng: np.random.Generator
    extra: dict = field(default_factory=dict)


class SensorModel:
    """A sensor plus its active effects; fixed patterns are drawn once from ``seed``.

    Parameters
    ----------
    spec : SensorSpec
    effects : dict
        ``{effect_name: {param: value}}`` (names from :data:`effects.REGISTRY`).
    seed : int
        Seed of the fixed patterns (per-frame noise uses its own streams).
    """

    def __init__(self, spec: SensorSpec, effects: dict | None = None, seed: int = 0):
        self.spec = spec
        self.seed = int(seed)
        self.effects = []
        for name in sorted(effects or {}):
            cls = fx.REGISTRY[name]
            e = cls(**(effects[name] or {}))
            e.setup(self, np.random.default_rng([self.seed, 2, fx.stable_id(name)]))
            self.effects.append(e)
        self.effects.sort(key=lambda e: e.order)
        H, W = spec.height, spec.width
        self.chan = channel_index(H, W, spec.cfa)  # 0..3 site index (dy*2+dx) or zeros for mono
        self.black_true = spec.black_map2()[np.arange(H)[:, None] % 2, np.arange(W)[None, :] % 2].astype(np.float32)
        for e in self.effects:
            e.adjust_black(self)

    # ------------------------------------------------------------------ helpers
    def has(self, name: str) -> bool:
        return any(e.name == name for e in self.effects)

    def frame(self, kind: str, iso: float, exposure_s: float, flux_e_per_s, rng: np.random.Generator,
              index: int = 0, n_frames: int = 1) -> np.ndarray:
        """One raw frame (H, W) uint16 in DN.

        ``flux_e_per_s`` is photo-electrons per pixel per second (scalar or (H, W)), 0 for a dark.
        """
        sp = self.spec
        H, W = sp.height, sp.width
        K = sp.gain(iso)
        ctx = Context(kind, float(iso), float(exposure_s), K, int(index), int(n_frames), rng)
        mu_p = np.broadcast_to(np.asarray(flux_e_per_s, dtype=np.float32) * np.float32(exposure_s), (H, W))
        mu_p = np.array(mu_p, dtype=np.float32)
        for e in self.effects:
            mu_p = e.mean_signal(self, mu_p, ctx)
        mu_d = np.zeros((H, W), np.float32)
        for e in self.effects:
            mu_d = e.mean_dark(self, mu_d, ctx)
        el = rng.poisson(np.maximum(mu_p, 0)).astype(np.float32)
        if np.any(mu_d):
            el += rng.poisson(np.maximum(mu_d, 0)).astype(np.float32)
        for e in self.effects:
            el = e.electrons(self, el, ctx)
        np.minimum(el, np.float32(sp.full_well_e), out=el)
        for e in self.effects:
            el = e.after_full_well(self, el, ctx)
        read = None
        for e in self.effects:
            r = e.read_noise(self, ctx)
            if r is not None:
                read = r
                break
        if read is None:
            read = rng.standard_normal((H, W), dtype=np.float32) * np.float32(sp.read_noise_e)
        el += read
        for e in self.effects:
            el = e.read_e(self, el, ctx)
        g = np.full((H, W), np.float32(K))
        for e in self.effects:
            g = e.analog_gain(self, g, ctx)
        v = el * g
        del el, g
        if sp.adc_noise_dn > 0:
            v += rng.standard_normal((H, W), dtype=np.float32) * np.float32(sp.adc_noise_dn)
        for e in self.effects:
            v = e.analog_dn(self, v, ctx)
        v += self.black_true
        code = None
        for e in self.effects:
            c = e.adc(self, v, ctx)
            if c is not None:
                code = c
                break
        if code is None:
            code = quantise(v, sp.adc_step_dn)
        np.clip(code, 0, sp.white_dn, out=code)
        for e in self.effects:
            code = e.output(self, code, ctx)
        return np.rint(code).astype(np.uint16)


def quantise(v: np.ndarray, step: float) -> np.ndarray:
    """Mid-tread quantiser of step ``step`` DN (EMVA 1288 R4.0 eq. 6: variance step^2 / 12)."""
    if step == 1:
        return np.floor(v + np.float32(0.5))
    return np.floor(v / np.float32(step) + np.float32(0.5)) * np.float32(step)


def channel_index(height: int, width: int, cfa: str | None) -> np.ndarray:
    """Index 0..3 of each pixel's 2x2 site (dy*2+dx); zeros for monochrome."""
    if cfa is None:
        return np.zeros((height, width), np.int8)
    return ((np.arange(height)[:, None] % 2) * 2 + (np.arange(width)[None, :] % 2)).astype(np.int8)
