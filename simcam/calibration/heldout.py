"""Held-out marginal KL of the calibration loop: the estimator, its sampling floor, and the
structured (aggregated-noise) marginals.

Estimator
---------
Forward KL D(data || model) between two histograms on the same bins: data probabilities
``p_k = n_k / N`` (plug-in), model probabilities smoothed with a Jeffreys prior, half a count per
bin, ``q_k = (m_k + 1/2) / (M + B/2)``, summed over every bin the *data* occupies. Without the
smoothing, bins where the simulated sample is empty would be dropped and the data's tail (hot
pixels, a heavy-tailed read noise) would be invisible to the KL; with it, a data count where the
model puts (almost) nothing costs ``p_k log(p_k / q_k)`` with ``q_k`` ~ 1 / (2M).

Sampling floor
--------------
The plug-in KL between two finite samples of the *same* law is positive: to second order
(Miller-Madow) ``(B_occ - 1) / 2N + (B_occ - 1) / 2M``. :func:`kl_floor` gives its exact
expectation for this estimator: the KL is a sum over bins and, the two samples being independent,
``E[KL] = sum_k E[p_k log p_k] - E[p_k] E[log q_k]`` with ``n_k ~ Bin(N, pi_k)``,
``m_k ~ Bin(M, pi_k)``; the binomial expectations are summed exactly where a bin holds few counts
and by their second-order expansion elsewhere. ``pi`` is the pooled histogram of both samples (the
law's estimate if the model were right). ``kl_excess = max(kl - floor, 0)`` is the part of the KL
the finite samples do not explain.

Structured marginals
--------------------
Effects such as row noise, column FPN, a periodic pattern, frame flicker, crosstalk, DSNU or hot
pixels barely change the one-pixel marginal but dominate marginals of *aggregated* noise (EMVA 1288
sec. 8: spatial variances of row/column means and of temporal-mean maps; ELD, Wei et al. 2020: row
means). :func:`structured_kl` computes the same estimator on fixed aggregations of the signed noise
(frame minus the model's clean level, :func:`simcam.calibration.loop.noise_values`), per sequence and
CFA plane, families:

``pixel``     single values, one histogram per (sequence, plane): the joint law of (group, value),
              i.e. the group-size-weighted mean of the per-group KLs (per-channel gain and the
              signal-dependent response change the spread of some groups only);
``row``       row means per frame;           ``column``  column means per frame;
``temporal``  per-pixel means over the frames of the sequence (fixed patterns);
``block``     means of same-plane 2x2 blocks (neighbour correlation);
``frame``     frame means (minus their mean over the sequence's frames).

For every family but ``pixel`` the groups are pooled into one histogram, each group's values
divided by the white-noise standard deviation of that aggregate *measured on the data*
(sqrt(temporal pixel variance / pixels averaged), a fixed transform applied to data and model
alike), so a family with few values per group (frames) still has a usable sample. Binning is pinned
from the data only: 24 equal bins over median +- 4 robust sigma (1.4826 MAD) of the data's values
plus two open outer bins, so it is the same for every model compared.

Values of one family are not independent (the frames of one pixel share its DSNU, the pixels of a
column its FPN), so each family's floor and sampling SD are taken from the model's replicates (each
one sensor like the data: replicate r against the pool of the others, :func:`_family`). The
structured KL is the sum over families of their floor-corrected KLs ``max(kl - floor, 0)``, each
counted where it exceeds :data:`GATE_Z` sampling SDs: the families' noise levels differ by orders
of magnitude (120 frame means, ~10^5 pixels), and without the gate the sampling noise of the few-value
families (SD ~ 0.03 for the frame means) would swamp the real excess of the many-value ones (~0.002
for a 15 % channel gain) in the sum.
"""

from __future__ import annotations

import numpy as np

from .binning import hist_uniform

PLANE_OFFSETS = ((0, 0), (0, 1), (1, 0), (1, 1))
JEFFREYS = 0.5  # counts added to every model bin
GATE_Z = 4.0  # a family's excess counts in the structured KL when above GATE_Z sampling SDs
FAMILIES = ("pixel", "row", "column", "temporal", "block", "frame")
N_BINS = 24
RANGE_SIGMA = 4.0
STRUCTURED_BINNING = (f"per family: {N_BINS} equal bins over median +- {RANGE_SIGMA:g} x 1.4826 MAD of the held-out "
                      "data's values + 2 open outer bins; forward KL D(data||model), model counts + 1/2 per bin")

#: Noise Flow marginal-KL binning (Noise Flow, Abdelhamed, Brubaker, Brown, ICCV 2019), normalised raw units.
KL_EDGES = np.concatenate([[-1000.0], np.linspace(-0.1, 0.1, 65), [1000.0]])
KL_BINNING = ("edges [-1000] + linspace(-0.1, 0.1, 65) + [1000] on normalised raw noise; forward KL D(real||model) "
              "over the bins the data occupies, model counts + 1/2 per bin (Jeffreys)")



# ------------------------------------------------------------------ estimator

def kl_counts(n: np.ndarray, m: np.ndarray) -> float:
    """Forward KL D(p || q) of data counts ``n`` and model counts ``m`` on the same bins (module docstring)."""
    n = np.asarray(n, dtype=np.float64)
    m = np.asarray(m, dtype=np.float64)
    p = n / n.sum()
    q = (m + JEFFREYS) / (m.sum() + JEFFREYS * m.size)
    occ = p > 0
    return float(np.sum(p[occ] * np.log(p[occ] / q[occ])))


def _e_xlogx(pi: float, n: int) -> float:
    """E[(k/n) log(k/n)] for k ~ Bin(n, pi)."""
    mu, var = n * pi, n * pi * (1 - pi)
    if var > 200:
        return pi * np.log(pi) + (1 - pi) / (2 * n)
    from scipy.stats import binom

    k = np.arange(1, int(mu + 12 * np.sqrt(var) + 30) + 1)
    x = k / n
    return float(np.sum(binom.pmf(k, n, pi) * x * np.log(x)))


def _e_log_smoothed(pi: float, m: int, bins: int) -> float:
    """E[log((k + a) / (m + a B))] for k ~ Bin(m, pi), a = :data:`JEFFREYS`."""
    a = JEFFREYS
    mu, var = m * pi, m * pi * (1 - pi)
    if var > 200:
        return float(np.log(mu + a) - var / (2 * (mu + a) ** 2) - np.log(m + a * bins))
    from scipy.stats import binom

    k = np.arange(0, int(mu + 12 * np.sqrt(var) + 30) + 1)
    return float(np.sum(binom.pmf(k, m, pi) * np.log(k + a)) - np.log(m + a * bins))


def kl_floor(pi: np.ndarray, n: int, m: int) -> float:
    """Expected :func:`kl_counts` between a sample of ``n`` and one of ``m`` values, both drawn from the
    binned law ``pi`` (module docstring): the KL a perfect model still shows."""
    pi = np.asarray(pi, dtype=np.float64)
    pi = pi / pi.sum()
    out = 0.0
    for p in pi[pi > 0]:
        out += _e_xlogx(float(p), n) - p * _e_log_smoothed(float(p), m, pi.size)
    return float(max(out, 0.0))


def kl_with_floor(n_counts: np.ndarray, m_counts: np.ndarray) -> tuple[float, float]:
    """(KL, its sampling floor) for data / model counts; the floor's law is the pooled histogram."""
    n_counts = np.asarray(n_counts, dtype=np.float64)
    m_counts = np.asarray(m_counts, dtype=np.float64)
    N, M = int(n_counts.sum()), int(m_counts.sum())
    return kl_counts(n_counts, m_counts), kl_floor(n_counts + m_counts, N, M)


def kl_sd(floor: float, n_counts: np.ndarray) -> float:
    """Sampling SD of the KL between two samples of one law: 2 N_eff KL ~ chi^2 with B_occ - 1 degrees
    of freedom (the G-test), so SD = floor * sqrt(2 / (B_occ - 1))."""
    b = int(np.count_nonzero(n_counts))
    return float(floor * np.sqrt(2.0 / max(b - 1, 1)))


# ------------------------------------------------------------------ structured marginals

def _robust_sigma(x: np.ndarray) -> float:
    med = np.median(x)
    s = 1.4826 * float(np.median(np.abs(x - med)))
    if s <= 0:
        s = float(np.std(x))
    return s


def data_edges(x: np.ndarray) -> np.ndarray | None:
    """The pinned binning of one family: :data:`N_BINS` equal bins over median +- 4 robust sigma of the
    data's values, plus two open outer bins; None when the data have no spread."""
    s = _robust_sigma(x)
    if not np.isfinite(s) or s <= 0:
        return None
    med = float(np.median(x))
    inner = np.linspace(med - RANGE_SIGMA * s, med + RANGE_SIGMA * s, N_BINS + 1)
    return np.concatenate([[-np.inf], inner, [np.inf]])


def _aggregates(r: np.ndarray, fixed_in_clean: bool) -> dict[str, tuple[np.ndarray, float]]:
    """Family -> (values, pixels averaged) for one plane's residual ``r`` (n, h, w); the values keep
    their shape (the pixel family is ``r`` itself, a strided view of the sequence's frames)."""
    n, h, w = r.shape
    out = {"pixel": (r, 1.0), "row": (r.mean(axis=2), float(w)), "column": (r.mean(axis=1), float(h))}
    if not fixed_in_clean:  # a temporal-mean reference leaves no temporal mean to compare
        out["temporal"] = (r.mean(axis=0), float(n))
    h2, w2 = h // 2 * 2, w // 2 * 2
    if h2 and w2:
        # the 2x2 block means as four strided slices summed (8x faster than a reshape and a mean over
        # two non-adjacent axes, which copies the strided plane first)
        b = r[:, 0:h2:2, 0:w2:2] + r[:, 1:h2:2, 0:w2:2]
        b += r[:, 0:h2:2, 1:w2:2]
        b += r[:, 1:h2:2, 1:w2:2]
        b *= 0.25
        out["block"] = (b, 4.0)
    if n >= 2:
        fm = r.mean(axis=(1, 2))
        out["frame"] = (fm - fm.mean(), float(h * w) * n / (n - 1))  # centred: variance (n-1)/n of the raw one
    return out


def _scales(residuals: list[np.ndarray]) -> list[np.ndarray]:
    """Per sequence, the 4 per-plane temporal standard deviations (the white-noise scale of one pixel)."""
    scales = []
    for r in residuals:
        s = []
        for dy, dx in PLANE_OFFSETS:
            p = r[:, dy::2, dx::2]
            v = float(np.mean(np.var(p, axis=0, ddof=1))) if p.shape[0] >= 2 else float(np.var(p))
            s.append(np.sqrt(max(v, 1e-30)))
        scales.append(np.asarray(s))
    return scales


def group_values(residuals: list[np.ndarray], fixed: list[bool], scales: list[np.ndarray] | None = None):
    """Per family, the list of per-(sequence, plane) value arrays of ``residuals`` (each (n, H, W)),
    standardised by ``scales`` (per sequence, 4 per-plane temporal sds; from the data when None).
    Returns (values, scales)."""
    if scales is None:
        scales = _scales(residuals)
    vals: dict[str, list] = {f: [] for f in FAMILIES}
    for r, fic, sc in zip(residuals, fixed, scales):
        for j, (dy, dx) in enumerate(PLANE_OFFSETS):
            for fam, (x, k) in _aggregates(r[:, dy::2, dx::2], fic).items():
                vals[fam].append(np.ravel(x) / (sc[j] / np.sqrt(k)))
    return vals, scales


def group_counts(residuals: list[np.ndarray], fixed: list[bool], scales: list[np.ndarray], edges: dict) -> dict:
    """The histograms of :func:`group_values` without building them: ``edges`` maps a family to its bin
    edges (one array, the groups pooled) or to a list of edges per group (``None`` for a group not
    histogrammed); returns the same structure of counts (:func:`simcam.calibration.binning.hist_uniform`,
    each group's values scaled in place of a standardised copy)."""
    out = {fam: ([None if e is None else np.zeros(e.size - 1, np.int64) for e in ed] if isinstance(ed, list)
                 else np.zeros(ed.size - 1, np.int64)) for fam, ed in edges.items()}
    gi = 0
    for r, fic, sc in zip(residuals, fixed, scales):
        for j, (dy, dx) in enumerate(PLANE_OFFSETS):
            for fam, (x, k) in _aggregates(r[:, dy::2, dx::2], fic).items():
                if fam not in edges:
                    continue
                ed = edges[fam]
                scale = float(np.sqrt(k) / sc[j])
                if isinstance(ed, list):
                    if ed[gi] is not None:
                        hist_uniform(x, ed[gi], scale, out[fam][gi])
                else:
                    hist_uniform(x, ed, scale, out[fam])
            gi += 1
    return out


class StructuredKL:
    """:func:`structured_kl` one replicate at a time: the data's values, scales and bin edges are fixed
    at construction; :meth:`add` histograms one simulated replicate (its frames can then be freed)."""

    def __init__(self, real: list[np.ndarray], fixed: list[bool]):
        self.fixed = fixed
        dvals, self.scales = group_values(real, fixed)
        self.fams = {}  # family -> list of (weight, edges, data counts, per-replicate model counts, group), ntot
        self.edges: dict = {}  # family -> edges (groups pooled) or per-group edges (pixel): group_counts' bins
        for fam in FAMILIES:
            groups = dvals[fam]
            if not groups:
                continue
            hists = []
            if fam == "pixel":  # joint law of (group, value): group-weighted mean of per-group KLs
                ntot = sum(g.size for g in groups)
                per = []
                for gi, g in enumerate(groups):
                    edges = data_edges(g)
                    per.append(edges)
                    if edges is not None:
                        hists.append((g.size / ntot, edges, hist_uniform(g, edges), [], gi))
                if hists:
                    self.edges[fam] = per
            else:  # groups pooled (values standardised per group)
                x = np.concatenate(groups)
                ntot = x.size
                edges = data_edges(x)
                if edges is not None:
                    hists.append((1.0, edges, hist_uniform(x, edges), [], None))
                    self.edges[fam] = edges
            if hists:
                self.fams[fam] = (hists, ntot)

    def fresh(self) -> "StructuredKL":
        """A new accumulator on the same data (its values, scales, bins and counts shared, no replicates):
        models whose held-out residuals are the same bytes need the data side once."""
        new = object.__new__(StructuredKL)
        new.fixed, new.scales, new.edges = self.fixed, self.scales, self.edges
        new.fams = {fam: ([(w, e, nc, [], gi) for w, e, nc, _m, gi in hists], ntot)
                    for fam, (hists, ntot) in self.fams.items()}
        return new

    def counts(self, sim: list[np.ndarray]) -> list[np.ndarray]:
        """One simulated replicate's histograms, in the order :meth:`add_counts` takes them (reads the
        accumulator only: replicates may be histogrammed in parallel threads)."""
        got = group_counts(sim, self.fixed, self.scales, self.edges)
        out = []
        for fam, (hists, _n) in self.fams.items():
            for _w, _edges, _nc, _mcs, gi in hists:
                out.append(got[fam][gi] if gi is not None else got[fam])
        return out

    def add_counts(self, counts: list[np.ndarray]) -> None:
        """Append the histograms :meth:`counts` gave for one replicate."""
        it = iter(counts)
        for hists, _n in self.fams.values():
            for _w, _e, _nc, mcs, _g in hists:
                mcs.append(next(it))

    def add(self, sim: list[np.ndarray]) -> None:
        self.add_counts(self.counts(sim))

    def result(self) -> dict:
        fams = {fam: _family([(w, nc, mcs) for w, _e, nc, mcs, _g in hists], ntot)
                for fam, (hists, ntot) in self.fams.items()}
        return {"kl": float(sum(f["excess"] for f in fams.values() if f["significant"])), "families": fams}


def structured_kl(real: list[np.ndarray], fixed: list[bool], sims: list[list[np.ndarray]]) -> dict:
    """Structured marginal KL of held-out noise (module docstring).

    ``real``: per sequence, the data's signed noise (n, H, W); ``fixed``: per sequence, whether its
    reference is a temporal mean (scene without clean); ``sims``: per replicate (>= 2), the same list for
    the model. Returns ``{"kl": sum of the significant excesses, "families": {name: {"kl", "floor",
    "floor_iid", "sd", "excess", "z", "significant", "n"}}}``.
    """
    acc = StructuredKL(real, fixed)
    for s in sims:
        acc.add(s)
    return acc.result()


def _family(hists: list, n: int) -> dict:
    """KL of one family and its floor. The floor and SD are those of a perfect model, taken from the
    model's own replicates (leave one out: replicate r against the pool of the others, same estimator):
    this keeps the dependence between values that shared fixed patterns give (the 6 frames of a hot
    pixel, the pixels of an FPN column), which the i.i.d. floor :func:`kl_floor` (also reported,
    ``floor_iid``) ignores. SD: the larger of the replicates' spread and the i.i.d. chi-square one."""
    kl = floor_iid = var_iid = 0.0
    loo = np.zeros(len(hists[0][2]))
    for w, nc, mcs in hists:
        tot = np.sum(mcs, axis=0)
        k, f = kl_with_floor(nc, tot)
        kl += w * k
        floor_iid += w * f
        var_iid += (w * kl_sd(f, nc)) ** 2
        for r, mc in enumerate(mcs):
            loo[r] += w * kl_counts(mc, tot - mc)
    floor = float(loo.mean()) if loo.size >= 2 else floor_iid
    sd = max(float(loo.std(ddof=1)) if loo.size >= 2 else 0.0, float(np.sqrt(var_iid)))
    z = (kl - floor) / sd if sd > 0 else 0.0
    return {"kl": float(kl), "floor": floor, "floor_iid": float(floor_iid), "sd": sd,
            "excess": float(max(kl - floor, 0.0)), "z": float(z), "significant": bool(z > GATE_Z), "n": int(n)}


def marginal_kl(real: np.ndarray, model: np.ndarray) -> float:
    """Forward KL D(real || model) with the Noise Flow binning (:data:`KL_EDGES`), the model's histogram
    smoothed by half a count per bin (:func:`kl_counts`), so data in bins the
    simulation leaves empty (a hot-pixel tail) count."""
    return kl_counts(np.histogram(real, KL_EDGES)[0], np.histogram(model, KL_EDGES)[0])


def kl_sampling_floor(real: np.ndarray, model: np.ndarray) -> float:
    """Expected :func:`marginal_kl` between two samples of the same law with these sizes (exact binomial
    expectation of the estimator, :func:`kl_floor`, on the pooled histogram;
    Miller-Madow (B - 1) / 2N + (B - 1) / 2M to second order): differences below it are noise."""
    n = np.histogram(real, KL_EDGES)[0]
    m = np.histogram(model, KL_EDGES)[0]
    return kl_floor(n + m, real.size, model.size)
