"""Fits of the calibration loop: the Poisson-Gaussian base, and adding one effect to a model.

The base fit reads the photon-transfer points of the capture (:mod:`simcam.calibration.diagnostics`);
an effect's parameters are fitted by its card (:mod:`simcam.calibration.effects`: moment estimators
on the diagnostics' intermediates, or indirect inference through the loop's simulator).
"""

from __future__ import annotations

import numpy as np

from . import diagnostics as dg
from .effects import CARDS, EffectParams, Fit, FitContext, card_for
from .model import LoopModel


def base_fit(d: dg.CaptureData) -> LoopModel:
    """Poisson-Gaussian base: K from the photon-transfer slope (pooled over planes), read noise
    from the dark temporal variance (or the PTC intercept), black from the declaration (or darks)."""
    darks, flats = d.ptc_points()
    black_declared = d.black_dn is not None
    if darks:
        mu0 = np.mean([p[:, 0] for p in darks], axis=0)
        v0 = float(np.mean([p[:, 1] for p in darks]))
    else:
        mu0, v0 = None, None
    if flats:
        X = np.array([f[:, 0] for f in flats])
        Y = np.array([f[:, 1] for f in flats])
        if darks:
            x, y = X - mu0, Y - v0
            K = float((x * y).sum() / (x * x).sum())
        else:
            K, v0 = np.polyfit(X.ravel() - (np.mean(d.black_dn) if black_declared else 0.0), Y.ravel(), 1)
            K, v0 = float(K), float(max(v0, 0.1))
    elif d.scenes:  # scenes only: binned per-pixel temporal variance vs clean level
        K, v0 = _scene_ptc(d)
    else:  # darks only: no signal, no gain to measure (K = 0: no shot noise in the model)
        K = 0.0
    if black_declared:
        black = np.asarray(d.black_dn, dtype=np.float64).reshape(2, 2)
    elif mu0 is not None:
        black = np.asarray(mu0).reshape(2, 2)
    else:
        black = np.zeros((2, 2))
    if not np.isfinite(K) or K <= 0:  # no (or negative) shot-noise slope: the data show no photon noise
        K = 0.0
    if v0 is None or not np.isfinite(v0):
        v0 = 0.0
    m = LoopModel(cfa=d.cfa, black_dn=black, white_dn=d.white_dn, K=float(K), read_dn=1.0,
                  var_dark_dn2=v0, black_declared=black_declared)
    m.refit_read()
    return m


def _scene_ptc(d: dg.CaptureData) -> tuple[float, float]:
    xs, ys = [], []
    for frames, clean in d.scenes:
        f = frames.astype(np.float64)
        mean = f.mean(0) if clean is None else clean
        var = f.var(0, ddof=1)
        xs.append(mean.ravel())
        ys.append(var.ravel())
    x, y = np.concatenate(xs), np.concatenate(ys)
    black = float(np.mean(d.black_dn)) if d.black_dn is not None else 0.0
    edges = np.quantile(x, np.linspace(0, 1, 21))
    idx = np.clip(np.digitize(x, edges) - 1, 0, 19)
    bx = np.array([x[idx == i].mean() for i in range(20) if np.any(idx == i)])
    by = np.array([np.mean(y[idx == i]) for i in range(20) if np.any(idx == i)])  # mean: unbiased (ddof=1)
    K, v0 = np.polyfit(bx - black, by, 1)
    return float(K), float(max(v0, 0.1))


def _split(fitted: EffectParams | Fit) -> tuple[EffectParams, float | None, float | None]:
    return (fitted.params, fitted.K, fitted.read_dn) if isinstance(fitted, Fit) else (fitted, None, None)


def fit_effect(effect: str, d: dg.CaptureData, model: LoopModel, ctx: FitContext) -> LoopModel:
    """The model with ``effect`` added (parameters fitted on ``d`` by its card; a card that re-estimates
    the system gain sets K) and the read noise refitted; effects whose estimate depends on the rest of
    the model (``refit_on_change``), or on ``effect`` (``refit_after``), are fitted again, and one whose
    refit is the identity (:meth:`EffectCard.is_null`: ``row_noise`` once ``empirical_spectrum`` holds all
    the row offsets' variance) leaves the model."""
    params, newK, read = _split(card_for(effect).fit(d, model, ctx))
    m = model.with_effect(effect, params)
    if newK is not None:
        m.K = newK
    if read is not None:  # the card measured the read noise itself: the dark variance it implies
        m.read_dn = float(read)
        m.set_dark_variance_from_read()
    for other in CARDS.values():
        if (other.refit_on_change or effect in other.refit_after) and other.name in m.effects and other.name != effect:
            refit = _split(other.fit(d, m, ctx))[0]
            if other.is_null(refit):
                del m.effects[other.name]
            else:
                m.effects[other.name] = refit
            m.refit_read()
    return m
