"""``rtn``: random telegraph noise, a fixed set of pixels switching between two levels from frame to frame.

Physics. A single charge trap in the gate oxide of a pixel's source-follower transistor (or at its
silicon interface) captures and emits a carrier at random; while it holds it, the channel's
conductance, and so the pixel's output, is shifted by a fixed step. The output therefore switches
between two levels (sometimes more, with several traps) with exponentially distributed dwell times in
each state: random telegraph signal (Wang et al., "Random telegraph signal in CMOS image sensor
pixels", IEDM 2006; Janesick, *Photon Transfer*, SPIE 2007, on read noise and its non-Gaussian
outliers; A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD dissertation, York
University, 2020, ch. 2, noise sources); the linear model of EMVA 1288 Release 4.0, sec. 2, with
one temporal dark variance for all pixels, leaves them out. Only a small share of the pixels has
such a trap close enough to matter (a fixed set, drawn once per sensor); the step is a property of
the trap, spread over pixels. With dwell times longer than a frame's read-out but shorter than the time between
frames, each frame samples one state, independently: in the darks such a pixel's values over
frames are *bimodal*, two levels the step apart, each as tight as the read noise.

Told apart from its neighbours in the vocabulary: a hot pixel (``hot_pixels``) is high in every
frame (its temporal median is high; its temporal spread, if any, is the shot noise of its dark
charge, one wide level); heavy-tailed read noise (``heavy_tail_read``) gives every pixel the same
tail, one outlying frame here and there, no pixel twice on the same second level; an RTN pixel
switches, visits both levels, and its median may sit at the normal dark level.

Fit. :func:`simcam.calibration.diagnostics.telegraph_split` on the darks (all dark frames of the
shortest exposure time, each frame's row and column means removed): per pixel, the best split of its
sorted values into two levels of >= 2 frames each; two-level pixels have levels >= 5 read-noise sigma
apart and each level as tight as the read noise (sigma^2: the 1 %-trimmed mean of the per-pixel
temporal variances). From the detected pixels: the step ``amplitude_dn`` (mean gap between the level
means), its log-normal spread ``amplitude_log_sigma`` (the spread of the log gaps less what the
read noise adds to them), the high-state probability ``p_high`` (the share of frames on the high
level). The detection sees only part of the RTN pixels (a pixel must visit each level twice, its step
must clear the threshold), and it biases the gaps up and the shares towards 1/2; all three are
corrected by matching the same detection on synthetic two-level pixels (read noise sigma, the frame
count of the data) by fixed-point iteration, and ``fraction`` is the detected count over the
detected share of the synthetic pixels.

Profile. ``{type: rtn, fraction, amplitude, amplitude_log_sigma, p_high}`` (``amplitude`` on
normalised raw: ``amplitude_dn / (white - black)``): the noise stage's ``Rtn`` draws the pixel set and
the log-normal steps (mean ``amplitude``) from the sensor seed and each pixel's state every frame
(high with probability ``p_high``, independently). Its temporal dark variance,
``fraction p (1 - p) amplitude^2 exp(log_sigma^2)``, is not read noise (``LoopModel.refit_read``).
"""

from __future__ import annotations

import numpy as np

from .. import diagnostics as dg
from ..pixelwise import two_level_split
from .card import EffectCard, EffectParams, ProfileTerm, quantity

#: synthetic two-level pixels the detection's efficiency and biases are measured on
SYNTHETIC_PIXELS = 20000
#: fixed-point iterations of the bias correction
ITERATIONS = 4


class Rtn(EffectParams):
    fraction: float = quantity("%", "fraction of the pixels with a random-telegraph trap (dimensionless; shown in %)",
                               scale=100.0)
    amplitude_dn: float = quantity("DN", "mean step between a telegraph pixel's two levels")
    amplitude_log_sigma: float = quantity("", "log-normal spread of the steps over pixels (0: all equal)")
    p_high: float = quantity("", "probability of the high state in a frame")
    count: int | None = quantity("", "number of two-level pixels detected in the analysed dark frames (fits only)",
                                 default=None)


def detection(amplitude_dn: float, log_sigma: float, p_high: float, n: int, sigma2: float,
              rng: np.random.Generator, m: int = SYNTHETIC_PIXELS) -> tuple[float, float, float, float]:
    """(detected share, mean gap (DN) of the detected, standard deviation of their log gaps, mean share
    of their frames on the high level) of ``m`` synthetic telegraph pixels (log-normal steps of mean
    ``amplitude_dn``, high with probability ``p_high``, ``n`` frames, Gaussian read noise of variance
    ``sigma2``) under :func:`simcam.calibration.pixelwise.two_level_split`."""
    s = float(log_sigma)
    amp = amplitude_dn * np.exp(s * rng.standard_normal(m) - s * s / 2)
    v = np.sqrt(sigma2) * rng.standard_normal((n, m)) + amp * (rng.random((n, m)) < p_high)
    mask, gap, high = two_level_split(v, sigma2)
    if not mask.any():
        return 0.0, float("nan"), float("nan"), float("nan")
    return (float(mask.mean()), float(gap[mask].mean()), float(np.std(np.log(gap[mask]))),
            float(np.mean(high[mask] / n)))


class RtnCard(EffectCard, name="rtn", params=Rtn, null_field="fraction", diagnostics=("telegraph_pixels",),
              gaussian=False, needs_darks=True):
    def fit(self, d, model, ctx):
        t = dg.telegraph_split(d)
        if t is None or not t[0].any():
            return Rtn(fraction=0.0, amplitude_dn=0.0, amplitude_log_sigma=0.0, p_high=0.5, count=0)
        mask, gap_map, high_map, n, s2, _ = t
        gap, share = gap_map[mask], high_map[mask] / n
        k = high_map[mask]
        g_obs, l_obs, h_obs = float(gap.mean()), float(np.std(np.log(gap))), float(share.mean())
        # start: the spread of the log steps is that of the log gaps less the read noise's part,
        # s2 (1/k + 1/(n-k)) / gap^2
        noise = float(np.mean(s2 * (1.0 / k + 1.0 / (n - k)) / gap ** 2))
        log_sigma = float(np.clip(np.sqrt(max(l_obs ** 2 - noise, 0.0)), 0.0, 1.0))
        amp, p = g_obs, h_obs
        share_detected = float(mask.mean())
        for _ in range(ITERATIONS):  # common random numbers: the same synthetic draw every iteration
            eff, g_mc, l_mc, h_mc = detection(amp, log_sigma, p, n, s2, np.random.default_rng([ctx.seed, 1]))
            if not eff > 0:
                break
            share_detected = float(mask.mean()) / eff
            amp *= g_obs / g_mc
            if np.isfinite(l_mc):
                log_sigma = float(np.clip(log_sigma + (l_obs - l_mc), 0.0, 1.0))
            p = float(np.clip(p + (h_obs - h_mc), 0.02, 0.98))
        return Rtn(fraction=float(min(share_detected, 1.0)), amplitude_dn=float(amp), amplitude_log_sigma=log_sigma,
                   p_high=p, count=int(mask.sum()))

    def dark_variance_dn2(self, p):
        return float(p.fraction * p.p_high * (1 - p.p_high) * p.amplitude_dn ** 2 * np.exp(p.amplitude_log_sigma ** 2))

    def to_profile(self, p, model):
        return ProfileTerm(effect={"type": "rtn", "fraction": float(p.fraction),
                                   "amplitude": float(p.amplitude_dn) / model.full_scale_dn,
                                   "amplitude_log_sigma": float(p.amplitude_log_sigma), "p_high": float(p.p_high)})

    def from_profile(self, entry, full_scale_dn):
        return Rtn(fraction=float(entry.get("fraction", 0.0)),
                   amplitude_dn=float(entry.get("amplitude", 0.0)) * full_scale_dn,
                   amplitude_log_sigma=float(entry.get("amplitude_log_sigma", 0.0)),
                   p_high=float(entry.get("p_high", 0.5)))
