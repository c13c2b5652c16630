"""Attribution by held-out model comparison: which candidate effect explains a residual best.

The residual battery (:mod:`simcam.calibration.diagnostics`) only *proposes* effects: every
significant diagnostic names the effect whose card lists it. The loop fits every proposed effect,
then scores the current model and each candidate on the *held-out* frames with one criterion,
and adds the best candidate only when it beats the current model by more than the criterion's
sampling noise.

Criterion: held-out synthetic log-likelihood
--------------------------------------------
Each applicable diagnostic ``d`` is a statistic of the whole capture (an aggregate: a row-mean
variance, a tail fraction, a spectral peak). Simulating the model ``R`` times on the held-out
sequences gives its mean ``m_d`` and spread ``s_d``; the predictive law of one new capture's value
is Student t with ``R - 1`` degrees of freedom, location ``m_d`` and scale ``s_d sqrt(1 + 1/R)``
(the same law the loop's p-values use, :func:`simcam.calibration.diagnostics.discrepancy`). The
score is the sum of the log-densities of the held-out data's values under these laws,
statistics taken as independent: a synthetic likelihood (S. N. Wood, "Statistical inference for
noisy nonlinear ecological dynamic systems", Nature 466, 2010, with a Student-t rather than a
Gaussian predictive law for the small ``R``, and without the statistics' covariance). Every effect
moves at least the diagnostics that propose it, so every candidate is scored on the same scale;
the t law's log-density grows only like ``log z`` far in the tails, so a large residual that no
candidate touches cannot drown the comparison.

Statistics that count pixels (defects, telegraph pixels, the hot-pixel tail) take the negative
binomial predictive law of a count instead where the replicates are no more dispersed than Poisson
(:func:`predictive_logpdf`): a model that draws no defects gives a count of 0 in every replicate, and
the t law's floor would make 5 defective pixels in the data only a 5-sigma event.

Sampling noise
--------------
The candidate and the current model are simulated with the same random streams (replicate ``r``
of each from the same seed), and the gain ``score(candidate) - score(current)`` is jackknifed
over the replicate pairs (leave pair ``r`` out of both; B. Efron & C. Stein, "The jackknife
estimate of variance", Ann. Statist. 9, 1981): its standard error covers the simulated means and
spreads of every statistic, i.e. what a different set of replicates would have given. A candidate
is added when its gain exceeds :data:`GAIN_Z` standard errors and :data:`MIN_GAIN` nats.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats as sst

from . import diagnostics as dg

#: a candidate is added when its held-out gain exceeds GAIN_Z jackknife standard errors ...
GAIN_Z = 3.0
#: ... and MIN_GAIN nats (a gain of one nat is a likelihood ratio of e on one capture's statistics)
MIN_GAIN = 2.0


def gain_beats(gain: float, sd: float) -> bool:
    """A held-out gain (nats) with its SE beats the current model beyond the sampling noise: above
    :data:`MIN_GAIN` and :data:`GAIN_Z` SEs."""
    return gain > MIN_GAIN and gain > GAIN_Z * sd


def t_logpdf(value: float, sims: np.ndarray, floor: float) -> float:
    """Log-density of ``value`` under the Student-t predictive law of a new draw given the simulated
    values ``sims`` (``R - 1`` degrees of freedom, location their mean, scale their SD, at least
    ``floor``, times ``sqrt(1 + 1/R)``)."""
    s = np.asarray(sims, dtype=np.float64)
    R = s.size
    scale = max(float(s.std(ddof=1)), floor) * math.sqrt(1 + 1 / R)
    return float(sst.t.logpdf((value - float(s.mean())) / scale, R - 1) - math.log(scale))


@dataclass(frozen=True)
class Comparison:
    """Held-out score of a candidate against the current model.

    ``gain``: candidate minus current model (nats; > 0: the candidate reproduces the held-out
    statistics better); ``sd``: its jackknife standard error; ``per_diagnostic``: the gain of
    each statistic (the ones that moved most tell what the candidate explains);
    ``diagnostics``: how many statistics were compared.
    """

    gain: float
    sd: float
    per_diagnostic: dict
    diagnostics: int

    @property
    def z(self) -> float:
        return self.gain / self.sd if self.sd > 0 else (math.inf if self.gain > 0 else 0.0)

    def beats(self) -> bool:
        """The candidate beats the current model beyond the sampling noise (module docstring)."""
        return gain_beats(self.gain, self.sd)

    def top(self, n: int = 3) -> list[tuple[str, float]]:
        """The ``n`` statistics whose log-density changed most, with the change (nats)."""
        return sorted(self.per_diagnostic.items(), key=lambda kv: -abs(kv[1]))[:n]


def predictive_logpdf(name: str, value: float, sims: np.ndarray, floor: float, null: float | None = None) -> float:
    """Log-density of a statistic's held-out value: the count law of a pixel-share statistic whose
    replicates are not over-dispersed (:func:`simcam.calibration.diagnostics.count_law`: a probability
    per count, divided by the one-pixel ``floor`` to be a density on the share's scale), else
    :func:`t_logpdf`."""
    law = dg.count_law(name, sims, floor, null)
    if law is None:
        return t_logpdf(value, sims, floor)
    return float(law.logpmf(int(round(value / floor))) - math.log(floor))


def _scores(values: dict, sims: dict, floors: dict, names: list[str], drop: int | None, nulls: dict) -> np.ndarray:
    out = np.empty(len(names))
    for i, name in enumerate(names):
        s = np.asarray(sims[name], dtype=np.float64)
        if drop is not None:
            s = np.delete(s, drop)
        out[i] = predictive_logpdf(name, values[name], s, floors[name], nulls.get(name))
    return out


def _side(values: dict, sims: dict, floors: dict, names: list[str], nulls: dict) -> tuple[np.ndarray, list[np.ndarray]]:
    """One model's scores: on all its replicates, and with each replicate left out in turn."""
    R = len(sims[names[0]])
    return (_scores(values, sims, floors, names, None, nulls),
            [_scores(values, sims, floors, names, r, nulls) for r in range(R)])


def compare(values: dict, floors: dict, current: dict, candidate: dict, cache: dict | None = None,
            nulls: dict | None = None) -> Comparison:
    """Held-out synthetic log-likelihood gain of ``candidate`` over ``current`` (module docstring).

    ``values``: diagnostic -> its value on the held-out data; ``floors``: diagnostic -> the
    resolution below which its simulated spread is not trusted; ``current`` / ``candidate``:
    diagnostic -> the values on the models' R held-out replicates, replicate r of both drawn from
    the same seed. Statistics missing from either model, or undefined on a replicate, are left out.
    ``cache``: a dict kept with ``current`` (its scores are the same for every candidate compared with
    it on the same statistics and replicates).
    """
    names = [n for n in values if values[n] is not None and n in current and n in candidate
             and len(current[n]) == len(candidate[n]) >= 3
             and all(v is not None for v in current[n]) and all(v is not None for v in candidate[n])]
    if not names:
        return Comparison(0.0, 0.0, {}, 0)
    R = len(current[names[0]])
    if any(len(current[n]) != R for n in names):
        raise ValueError("held-out replicates differ in number between the statistics")
    nulls = nulls or {}
    a, a_loo = _side(values, candidate, floors, names, nulls)
    key = (R, tuple(names))
    if cache is not None and key in cache:
        b, b_loo = cache[key]
    else:
        b, b_loo = _side(values, current, floors, names, nulls)
        if cache is not None:
            cache[key] = (b, b_loo)
    loo = np.array([np.sum(x - y) for x, y in zip(a_loo, b_loo)])
    sd = float(np.sqrt((R - 1) / R * np.sum((loo - loo.mean()) ** 2)))
    per = {n: float(x - y) for n, x, y in zip(names, a, b)}
    return Comparison(float(np.sum(a - b)), sd, per, len(names))
