"""Indirect inference for the effects that have no closed-form estimator.

Shapes such as Tukey-lambda tails under quantisation, or plane crosstalk diluted by quantisation
noise, are fitted by indirect inference: the parameter whose simulated statistic matches the
measured one (linear interpolation on a small grid; Gourieroux, Monfort & Renault 1993,
doi:10.1002/jae.3950080507). The simulator is the loop's bootstrap, passed in by the caller
(``FitContext.simulate``).
"""

from __future__ import annotations

import numpy as np

from .. import diagnostics as dg


def simulated_statistics(d, model, effect, make_params, grid, stat_names, specs, rng_seed, simulate,
                         reps=3) -> np.ndarray:
    """(len(grid), reps, len(stat_names)) statistics of captures simulated (``simulate(model, specs,
    rng)``) from ``model`` with ``effect`` at each ``grid`` value (``reps`` sensors each, seeds
    ``[rng_seed, j, r]``)."""
    vals = np.empty((len(grid), reps, len(stat_names)))
    for j, g in enumerate(grid):
        m = model.with_effect(effect, make_params(g))
        for r in range(reps):
            cd = d.like(simulate(m, specs, np.random.default_rng([rng_seed, j, r])), specs)
            vals[j, r] = [dg.STATISTICS[n](cd) for n in stat_names]
    return vals


def indirect_fit(d, model, effect, make_params, grid, stat_name, specs, rng_seed, simulate, reps=3):
    """Parameter on ``grid`` whose simulated ``stat_name`` (mean of ``reps`` sensors) matches the data."""
    target = dg.STATISTICS[stat_name](d)
    means = simulated_statistics(d, model, effect, make_params, grid, (stat_name,), specs, rng_seed, simulate,
                                 reps)[:, :, 0].mean(1)
    order = np.argsort(means)
    return float(np.interp(target, means[order], np.asarray(grid)[order]))


def indirect_fit_joint(d, model, effect, make_params, grid, stat_names, specs, rng_seed, simulate, reps=3, fine=401):
    """Parameter whose simulated statistics ``stat_names`` jointly match the data: each statistic's
    simulated mean (``reps`` sensors per ``grid`` point) is interpolated linearly on a fine grid
    and the sum of squared discrepancies, each in units of its pooled simulation SD, is minimised
    (indirect inference, Gourieroux, Monfort & Renault 1993, doi:10.1002/jae.3950080507)."""
    targets = np.array([dg.STATISTICS[n](d) for n in stat_names])
    vals = simulated_statistics(d, model, effect, make_params, grid, stat_names, specs, rng_seed, simulate, reps)
    means = vals.mean(1)  # (grid, stats)
    sd = np.sqrt(np.mean(vals.var(1, ddof=1), axis=0)) + 1e-12  # pooled over the grid
    g = np.asarray(grid, dtype=np.float64)
    gf = np.linspace(g.min(), g.max(), fine)
    order = np.argsort(g)
    mf = np.stack([np.interp(gf, g[order], means[order, k]) for k in range(len(stat_names))], axis=1)
    cost = np.sum(((mf - targets) / sd) ** 2, axis=1)
    return float(gf[int(np.argmin(cost))])
