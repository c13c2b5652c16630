"""Noise metrics: NLL per dimension, marginal KL (Noise Flow binning), variance vs intensity.

Marginal KL follows the Noise Flow code (Abdelhamed et al. 2019,
doi:10.1109/ICCV.2019.00326): histograms of the signed
noise with edges ``[-1000] + linspace(-0.1, 0.1, 65) + [1000]`` (64 inner bins
of width 0.2/64 plus two overflow bins), forward KL ``D(real || model)`` summed
over the bins where both histograms are non-empty. :data:`KL_BINNING` states it
and every result carries it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..cfa import PACK_OFFSETS, check_pattern
from ..errors import NoiseModelError
from .base import NoiseCondition, NoiseModel

KL_EDGES = np.concatenate([[-1000.0], np.linspace(-0.1, 0.1, 65), [1000.0]])
KL_BINNING = ("edges [-1000] + linspace(-0.1, 0.1, 65) + [1000] (64 bins of width 0.2/64 plus 2 overflow bins); "
              "forward KL D(real || model) over bins where both histograms are non-empty (Noise Flow code)")


def nll_per_dim(model: NoiseModel, noisy, clean, cond: NoiseCondition) -> float:
    """Mean negative log-likelihood per value (nats): ``-sum(log_prob) / N``."""
    lp = model.log_prob(noisy, clean, cond)
    return float(-np.mean(lp))


@dataclass
class KLResult:
    kl: float
    binning: str = KL_BINNING
    bins_used: int = 0

    def __str__(self) -> str:
        return f"marginal KL {self.kl:.6g} nats ({self.bins_used} bins; {self.binning})"


def marginal_kl(real_noise, model_noise) -> KLResult:
    """Forward KL D(real || model) between histograms of signed noise (see module docstring)."""
    a = np.asarray(real_noise, dtype=np.float64).ravel()
    b = np.asarray(model_noise, dtype=np.float64).ravel()
    if a.size == 0 or b.size == 0:
        raise NoiseModelError("marginal_kl: expected non-empty noise arrays")
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise NoiseModelError("marginal_kl: expected finite noise values, got NaN/inf")
    p = np.histogram(a, KL_EDGES)[0] / a.size
    q = np.histogram(b, KL_EDGES)[0] / b.size
    both = (p > 0) & (q > 0)
    kl = float(np.sum(p[both] * np.log(p[both] / q[both])))
    return KLResult(kl=kl, bins_used=int(both.sum()))


@dataclass
class VarianceCurve:
    """Noise variance against clean intensity for one CFA site."""

    site: tuple[int, int]
    colour: str | None
    centers: np.ndarray  # bin centres (normalised raw)
    mean_clean: np.ndarray
    variance: np.ndarray  # unbiased sample variance of noisy - clean
    count: np.ndarray
    extra: dict = field(default_factory=dict)

    @property
    def variance_se(self) -> np.ndarray:
        """Standard error of the variance under normality: var * sqrt(2 / (n - 1))."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.variance * np.sqrt(2.0 / (self.count - 1))


def variance_vs_intensity(noisy, clean, *, cfa: str | None = "RGGB", bins: int | np.ndarray = 32,
                          value_range: tuple[float, float] = (0.0, 1.0), min_count: int = 2) -> list[VarianceCurve]:
    """Per-CFA-site curves of noise variance against clean intensity.

    Parameters
    ----------
    noisy, clean : H x W arrays (normalised raw)
    cfa : Bayer pattern (labels the sites) or None
    bins : number of equal bins over ``value_range`` or explicit edges
    min_count : bins with fewer pixels are dropped
    """
    noisy = np.asarray(noisy, dtype=np.float64)
    clean = np.asarray(clean, dtype=np.float64)
    if noisy.shape != clean.shape or noisy.ndim != 2:
        raise NoiseModelError(
            f"variance_vs_intensity: expected two H x W arrays of one shape, got {noisy.shape} and {clean.shape}")
    if cfa is not None:
        cfa = check_pattern(cfa)
    edges = np.linspace(*value_range, bins + 1) if np.isscalar(bins) else np.asarray(bins, dtype=np.float64)
    curves = []
    for s, (dy, dx) in enumerate(PACK_OFFSETS):
        c = clean[dy::2, dx::2].ravel()
        n = noisy[dy::2, dx::2].ravel() - c
        idx = np.digitize(c, edges) - 1
        ok = (idx >= 0) & (idx < len(edges) - 1)
        idx, c, n = idx[ok], c[ok], n[ok]
        nb = len(edges) - 1
        cnt = np.bincount(idx, minlength=nb).astype(np.float64)
        s1 = np.bincount(idx, n, minlength=nb)
        s2 = np.bincount(idx, n * n, minlength=nb)
        sc = np.bincount(idx, c, minlength=nb)
        keep = cnt >= max(min_count, 2)
        mean = s1[keep] / cnt[keep]
        var = (s2[keep] - cnt[keep] * mean * mean) / (cnt[keep] - 1)
        curves.append(VarianceCurve(site=(dy, dx), colour=cfa[s] if cfa else None,
                                    centers=0.5 * (edges[:-1] + edges[1:])[keep], mean_clean=sc[keep] / cnt[keep],
                                    variance=var, count=cnt[keep]))
    return curves
