"""Base fit and per-effect parameter fits of the calibration loop.

Moment estimators read the same intermediates as the diagnostics
(:mod:`simcam.calibration.diagnostics`); shapes that have no closed-form
estimator (Tukey-lambda tails under quantisation, plane crosstalk diluted by
quantisation noise, flicker) are fitted by indirect inference: the parameter
whose simulated statistic matches the measured one (linear interpolation on a
small grid, Gourieroux et al. 1993, doi:10.1002/jae.3950080507).
"""

from __future__ import annotations

import numpy as np

from . import diagnostics as dg
from .model import LoopModel, SimSpec, site_map
from .simulate import simulate_capture

PLANE_OFFSETS = dg.PLANE_OFFSETS


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
    else:  # scenes only: binned per-pixel temporal variance vs clean level
        K, v0 = _scene_ptc(d)
    if black_declared:
        black = np.asarray(d.black_dn, dtype=np.float64).reshape(2, 2)
    elif mu0 is not None:
        black = np.asarray(mu0).reshape(2, 2)
    else:
        black = np.zeros((2, 2))
    m = LoopModel(cfa=d.cfa, black_dn=black, white_dn=d.white_dn, K=max(K, 1e-6), read_dn=1.0,
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


# ------------------------------------------------------------------ moment fits

def fit_row_noise(d, model, ctx):
    res = d.temporal_residuals("dark") or d.temporal_residuals("flat")
    vals = []
    for r in res:
        rm = r.mean(axis=2)
        vals.append(np.var(rm, axis=1).mean() - np.var(r) / r.shape[2])
    s2 = float(np.mean(vals))
    per = model.effects.get("periodic_pattern")
    if per and per.get("axis", "row") == "row":  # a modelled row-wise sinusoid is already part of it
        s2 -= per["amplitude_dn"] ** 2 / 2
    return {"sigma_dn": float(np.sqrt(max(s2, 0.0)))}


def fit_periodic(d, model, ctx, axis_name):
    """Sinusoid in the row (or column) means of the temporal residual: peak of the whitened
    periodogram, frequency refined to 1/40 bin, amplitude^2 from the per-frame sine/cosine
    projections minus their noise bias, frames weighted by the inverse square of their noise level."""
    axis = 2 if axis_name == "row" else 1
    lm = np.concatenate(dg._line_means("all", axis, d))  # (frames, L)
    lm = lm - lm.mean(axis=1, keepdims=True)
    L = lm.shape[1]
    p = dg.whitened_periodogram(d, axis)
    k = int(np.argmax(p[1:])) + 1
    noise = np.median(np.abs(np.fft.rfft(lm, axis=1))[:, 1:] ** 2, axis=1)  # per-frame noise level
    w_f = 1.0 / noise
    idx = np.arange(L)
    best = (-1.0, k / L)
    for f in np.linspace((k - 0.5) / L, (k + 0.5) / L, 41):
        c, s_ = np.cos(2 * np.pi * f * idx), np.sin(2 * np.pi * f * idx)
        pw = float(np.sum(w_f * ((lm @ c) ** 2 + (lm @ s_) ** 2)))
        if pw > best[0]:
            best = (pw, f)
    f = best[1]
    c, s_ = np.cos(2 * np.pi * f * idx), np.sin(2 * np.pi * f * idx)
    a = 2 / L * (lm @ c)
    b = 2 / L * (lm @ s_)
    resid = lm - a[:, None] * c - b[:, None] * s_
    bias = 4 * np.var(resid, axis=1) / L  # E[a^2 + b^2] = A^2 + 4 sigma^2 / L for white noise sigma^2
    w = w_f ** 2
    A2 = float(np.sum(w * (a * a + b * b - bias)) / np.sum(w))
    return {"amplitude_dn": float(np.sqrt(max(A2, 0.0))), "period_px": float(1.0 / f), "axis": axis_name}


def fit_column_fpn(d, model, ctx):
    """sigma_col^2 = covariance of the column profiles of the even- and odd-frame mean maps."""
    (ca, _va, _h), (cb, _vb, _) = dg.column_profiles(d)
    s2 = float(np.mean((ca - ca.mean()) * (cb - cb.mean())))
    return {"sigma_dn": float(np.sqrt(max(s2, 0.0)))}


def fit_dsnu(d, model, ctx):
    m, vt, n = d.dark_map()
    s2 = dg.robust_sigma(dg.remove_profiles(m)) ** 2 - vt / n
    return {"sigma_dn": float(np.sqrt(max(s2, 0.0)))}


def fit_hot_pixels(d, model, ctx):
    """Hot pixels: pixels whose dark temporal median (row/column profiles removed) is above 6
    robust sigma (:func:`~simcam.calibration.diagnostics.hot_pixel_mask`); ``fraction`` of pixels,
    and a log-normal of their offsets in the dark temporal-mean map (DN) by the moments of the
    log offsets (``log_mean``, ``log_sigma``; written to the noise stage as ``hot_offset`` = the
    mean exp(log_mean + log_sigma^2 / 2) and ``hot_log_sigma``).

    A log-normal is an approximation of whatever law the offsets follow (dark-current outliers
    are often closer to exponential): it is fitted to the *detected* part, offsets above the
    threshold (~6 x the map's noise), which is all the data says about them; smaller offsets are
    indistinguishable from DSNU. On exponential offsets of mean 60 DN above a 9-DN threshold it
    matches the detected offsets' quartiles within ~10 % and their mean within ~2 %.
    """
    m, _vt, _n = d.dark_map()
    r = dg.remove_profiles(m)
    hot = dg.hot_pixel_mask(d)  # persistent outliers (temporal median), offsets from the mean map
    vals = r[hot]
    logs = np.log(np.maximum(vals, 1e-3))
    return {"fraction": float(hot.mean()), "log_mean": float(logs.mean()),
            "log_sigma": float(max(logs.std(), 0.05)), "count": int(hot.sum())}


def fit_prnu(d, model, ctx):
    """PRNU from the flat-minus-dark pixel variance; with a modelled nonlinearity y(x) the
    measured relative spread is the linear one times the elasticity x y'(x) / y."""
    v = dg.prnu_excess(d)
    sigma = float(np.sqrt(max(v, 0.0)))
    c = model.effects.get("nonlinearity", {}).get("c", 0.0)
    if c:
        fm, dm = d.flat_map(), d.dark_map()
        y = float(fm[0].mean() - (dm[0].mean() if dm is not None else np.mean(model.black_dn)))
        s = model.full_scale_dn
        x = (np.sqrt(max(1 + 4 * c * y / s, 1e-9)) - 1) * s / (2 * c)
        sigma /= (x * (1 + 2 * c * x / s)) / y
    return {"sigma": sigma}


def fit_black_offset(d, model, ctx):
    m = d.dark_map()[0]
    off = [float(np.median(m[dy::2, dx::2]) - d.black_dn[dy, dx]) for dy, dx in PLANE_OFFSETS]
    return {"offset_dn": off}


def fit_flicker(d, model, ctx):
    excess = ctx["value"] - ctx["sim_mean"]
    return {"sigma": float(np.sqrt(max(excess, 0.0)))}


def fit_quantization(d, model, ctx):
    src = d.darks or sorted(d.flats, key=lambda a: float(a.mean()))[:1]
    v = np.concatenate([s.ravel() for s in src])
    lo, hi = np.percentile(v, [1, 99])
    codes = np.unique(np.round(v[(v >= lo) & (v <= hi)]))
    gaps = np.diff(codes)
    step = float(np.median(gaps)) if gaps.size else 1.0
    return {"step_dn": max(step, 1.0)}


def fit_channel_gain(d, model, ctx):
    k = dg.plane_slopes(d)
    g = k / k.mean()
    return {"gains": [float(x) for x in g], "_K": float(k.mean())}


def fit_nonlinearity(d, model, ctx):
    """Least squares of var(y) = (1 + 2c x/s)^2 (K g x + r) with y = x + c x^2/s over the PTC points."""
    from scipy.optimize import least_squares

    darks, flats = d.ptc_points()
    mu0 = np.mean([p[:, 0] for p in darks], axis=0) if darks else model.black_dn.ravel()
    y = np.array([f[:, 0] for f in flats]) - mu0
    v = np.array([f[:, 1] for f in flats])
    r = model.var_dark_dn2
    s = model.full_scale_dn
    g = model.gains()

    def resid(p):
        K, c = p
        disc = np.maximum(1 + 4 * c * y / s, 1e-9)
        x = y if abs(c) < 1e-12 else (np.sqrt(disc) - 1) * s / (2 * c)
        pred = (1 + 2 * c * x / s) ** 2 * (K * g * x + r)
        return ((pred - v) / v).ravel()

    sol = least_squares(resid, x0=[model.K, 0.0], bounds=([1e-6, -0.45], [np.inf, 0.45]))
    return {"c": float(sol.x[1]), "_K": float(sol.x[0])}


# ------------------------------------------------------------------ indirect fits

def simulated_statistics(d, model, effect, make_params, grid, stat_names, specs, rng_seed, reps=3) -> np.ndarray:
    """(len(grid), reps, len(stat_names)) statistics of captures simulated from ``model`` with
    ``effect`` at each ``grid`` value (``reps`` sensors each, seeds ``[rng_seed, j, r]``)."""
    vals = np.empty((len(grid), reps, len(stat_names)))
    for j, g in enumerate(grid):
        m = model.with_effect(effect, make_params(g))
        for r in range(reps):
            cd = ctx_like(d, simulate_capture(m, specs, np.random.default_rng([rng_seed, j, r])), specs)
            vals[j, r] = [dg.STATISTICS[n](cd) for n in stat_names]
    return vals


def indirect_fit(d, model, effect, make_params, grid, stat_name, specs, rng_seed, reps=3):
    """Parameter on ``grid`` whose simulated ``stat_name`` (mean of ``reps`` sensors) matches the data."""
    target = dg.STATISTICS[stat_name](d)
    means = simulated_statistics(d, model, effect, make_params, grid, (stat_name,), specs, rng_seed, reps)[:, :, 0].mean(1)
    order = np.argsort(means)
    return float(np.interp(target, means[order], np.asarray(grid)[order]))


def ctx_like(d: dg.CaptureData, sims: list, specs: list[SimSpec]) -> dg.CaptureData:
    """A CaptureData with the same structure as ``d`` holding simulated frames."""
    darks, flats, scenes = [], [], []
    it = iter(sims)
    for sp in specs:
        f = next(it)
        if sp.kind == "dark":
            darks.append(f)
        elif sp.kind == "flat":
            flats.append(f)
        else:
            scenes.append((f, None if sp.fixed_in_clean else sp.signal_dn))
    return dg.CaptureData(darks, flats, scenes, d.black_dn, d.white_dn, d.cfa)


def indirect_fit_joint(d, model, effect, make_params, grid, stat_names, specs, rng_seed, reps=3, fine=401):
    """Parameter whose simulated statistics ``stat_names`` jointly match the data: each statistic's
    simulated mean (``reps`` sensors per ``grid`` point) is interpolated linearly on a fine grid
    and the sum of squared discrepancies, each in units of its pooled simulation SD, is minimised
    (indirect inference, Gourieroux, Monfort & Renault 1993, doi:10.1002/jae.3950080507)."""
    targets = np.array([dg.STATISTICS[n](d) for n in stat_names])
    vals = simulated_statistics(d, model, effect, make_params, grid, stat_names, specs, rng_seed, reps)
    means = vals.mean(1)  # (grid, stats)
    sd = np.sqrt(np.mean(vals.var(1, ddof=1), axis=0)) + 1e-12  # pooled over the grid
    g = np.asarray(grid, dtype=np.float64)
    gf = np.linspace(g.min(), g.max(), fine)
    order = np.argsort(g)
    mf = np.stack([np.interp(gf, g[order], means[order, k]) for k in range(len(stat_names))], axis=1)
    cost = np.sum(((mf - targets) / sd) ** 2, axis=1)
    return float(gf[int(np.argmin(cost))])


def fit_heavy_tail(d, model, ctx):
    """Tukey lambda of the read noise matching both the dark tail mass and the PPCC lambda (the
    two heavy-tail diagnostics) through the full model (quantisation and all)."""
    lam = indirect_fit_joint(d, model, "heavy_tail_read", lambda g: {"lam": float(g)},
                             [-0.45, -0.35, -0.25, -0.15, -0.05, 0.05, 0.14],
                             ("dark_tail_mass", "dark_ppcc_lambda"), ctx["dark_specs"], ctx["seed"])
    return {"lam": float(np.clip(lam, -0.45, 0.14))}


def fit_spatial_correlation(d, model, ctx):
    a = indirect_fit(d, model, "spatial_correlation", lambda g: {"a": float(g)},
                     [0.0, 0.1, 0.2, 0.3, 0.4, 0.5], "lag1_corr", ctx["dark_specs"], ctx["seed"])
    return {"a": float(np.clip(a, 0.0, 0.5))}


FITTERS = {
    "row_noise": fit_row_noise,
    "column_fpn": fit_column_fpn,
    "dsnu": fit_dsnu,
    "prnu": fit_prnu,
    "hot_pixels": fit_hot_pixels,
    "heavy_tail_read": fit_heavy_tail,
    "quantization": fit_quantization,
    "spatial_correlation": fit_spatial_correlation,
    "black_level_offset": fit_black_offset,
    "frame_flicker": fit_flicker,
    "nonlinearity": fit_nonlinearity,
    "channel_gain": fit_channel_gain,
}


def fit_effect(effect: str, diagnostic: str, d: dg.CaptureData, model: LoopModel, ctx: dict) -> LoopModel:
    """The model with ``effect`` added (parameters fitted on ``d``) and the base refitted."""
    if effect == "periodic_pattern":
        params = fit_periodic(d, model, ctx, "row" if diagnostic == "row_spectrum_peak" else "col")
    else:
        params = FITTERS[effect](d, model, ctx)
    newK = params.pop("_K", None)
    m = model.with_effect(effect, params)
    if newK is not None:
        m.K = newK
    for other in REFIT_ON_CHANGE:  # effects whose moment estimate depends on the rest of the model
        if other in m.effects and other != effect:
            m.effects[other] = FITTERS[other](d, m, ctx)
    return m


#: Effects refitted whenever another effect is added (PRNU's estimate depends on the nonlinearity).
REFIT_ON_CHANGE = ("prnu",)


def site_black(model: LoopModel, shape) -> np.ndarray:
    return site_map(model.black_dn.ravel(), shape)
