"""``empirical_offset``: a measured per-frame column offset, or a per-frame offset of the whole frame, for
a residual no named effect explains.

Physics. Some sensors add an offset to each *column* of each frame, drawn anew every frame (temporal
column noise: column-parallel ADCs or amplifiers with their own 1/f noise and a shared reference,
EMVA 1288 Release 4.0, sec. 8, the column component of the temporal noise; A. Abdelhamed, *Noise
Modelling for Smartphone Cameras*, PhD dissertation, York University, 2020, ch. 3: noise components
fitted to measured statistics). None of the named effects makes it: ``column_fpn`` is the fixed part
of the column offsets, ``row_noise`` the per-frame part of the rows. ``col_temporal_excess`` (the
variance of each frame's column means of the temporal residual over its white-noise share) sees it,
and nothing else in the vocabulary proposes it, so the loop adds this *empirical* component and the
report says it is not in the vocabulary, with its family: column, temporal, additive (present in the
darks), not exposure-dependent.

Fit. From the darks (else the flats): each frame's column means of the temporal residual (the
frame's mean taken off). Their variance is the column offset's plus the white part ``pixel variance /
H``; what exceeds the white part is the offset's variance s^2. Its *law* is the measured one: the 33 quantiles (at
probabilities 0, 1/32, ..., 1) of the column means, centred and shrunk towards their median by
``s / sd(column means)`` (the Gaussian deconvolution of the white part; exact when both are
Gaussian), so a skewed or heavy-tailed column noise keeps its shape.

Frame form (``axis: frame``). A black level that wanders from frame to frame (a clamp or reference that
settles with die temperature, a supply that drifts) moves every pixel of a frame alike; none of the
named effects does (``frame_flicker`` is a gain on the light: darks do not show it).
``frame_mean_drift`` (the frame means of a sequence varying more slowly than independent frames would:
the inverse of von Neumann's ratio, J. von Neumann, *Ann. Math. Statist.* 12, 1941) proposes it, and so
does ``dark_frame_jitter`` (the dark frames' levels varying more than their own noise allows, in any
order). Fit from the darks only (an offset is present in them; a drifting *gain* shows in the flats
alone and leaves this fit null): each dark sequence's frame means of the temporal residual
(``diagnostics.dark_frame_levels``); their variance is the offset's s^2 plus what the rows, columns and
pixels put there, ``var(row means) / H + var(column means) / W - var(pixels) / (H W)`` per frame (each
line's mean of the frame's residual about the frame's mean; the pixel part is in both terms once). The
law is the measured one as above (33 quantiles of the frame means, shrunk by ``s / sd``). It is weighed
against ``frame_flicker`` on the held-out frames: flicker moves the flats' levels in proportion to their
signal and leaves the darks alone. The noise stage draws the offset independently every frame: it
reproduces the spread of the frame levels, not their order (a drift's ramp is a sequence, which a
per-frame draw does not have), so ``frame_mean_drift`` itself stays unexplained. A level that drifts
with temperature also sits higher in longer darks (self-heating): with darks at two exposure times or
more the form keeps the dark level's rise per second that the model's ``dark_current`` does not make
(its ``non_poisson_dn_per_s``, the rise the dark variance does not follow; without dark current the
whole rise; less the model's ``amp_glow``), when beyond 3 standard errors (``rate_dn_per_s``, added to
every pixel as ``rate x t``, no shot noise); it is refitted when ``dark_current`` or ``amp_glow`` joins.
Each sequence level's standard error is that of its frame means about a straight line in the frame index
(:func:`level_variance`): a level that drifts over a sequence is not noise of its mean (a 3.6-DN ramp
over 8 frames made the spread about the mean 0.3 DN/s of standard error and hid a 0.62-DN/s rise, the
independent simulator's black drift at ``--seed 2030``).
A model holds one ``empirical_offset``: column or frame.

Profile. The noise stage's ``{type: empirical_offset, axis: column | frame, temporal: true, quantiles}``
(quantiles on normalised raw; drawn by inverse transform every frame), with ``rate`` (normalised raw per
second) where the frame form has one.
"""

from __future__ import annotations

import numpy as np

from .card import EffectCard, EffectParams, quantity

#: quantiles kept of the measured law
N_QUANTILES = 33


def quantile_table_moments(q) -> tuple[float, float]:
    """(mean, variance) of the law whose quantiles at equally spaced probabilities 0..1 are ``q``:
    between consecutive quantiles the law is uniform (linear interpolation of the quantile function)."""
    q = np.asarray(q, dtype=np.float64)
    a, b = q[:-1], q[1:]
    m = float(np.mean((a + b) / 2))
    m2 = float(np.mean((a * a + a * b + b * b) / 3))
    return m, max(m2 - m * m, 0.0)


class EmpiricalOffset(EffectParams):
    quantiles_dn: list = quantity("DN", "quantiles of one column's (or the frame's) offset in one frame at "
                                  "probabilities 0, 1/32, ..., 1 (DN, mean 0)")
    axis: str = quantity("", "what the offset is shared by: each column (column) or the whole frame (frame)",
                         scale=None, default="column")
    rate_dn_per_s: float = quantity("DN/s", "rise of the whole frame's level per second of exposure, without shot "
                                    "noise (frame form)", default=0.0)


#: the card's forms (``FitContext.form``): what the offset is shared by
FORMS = ("column", "frame")
#: the residual family of each form (the report's "not in the vocabulary" line)
FAMILIES = {"column": "column, temporal, additive (present in darks), not exposure-dependent",
            "frame": "frame, temporal, additive (present in darks), not exposure-dependent",
            "frame_rate": "frame, temporal, additive (present in darks), exposure-dependent"}


class EmpiricalOffsetCard(EffectCard, name="empirical_offset", params=EmpiricalOffset,
                          diagnostics=("col_temporal_excess", "frame_mean_drift", "dark_frame_jitter"), gaussian=False,
                          family=FAMILIES["column"], refit_after=("dark_current", "amp_glow")):

    def variants(self, proposed_by):
        # one candidate per form the proposals point to: the frame form from the frame statistics
        out, forms = [], set()
        for p in proposed_by:
            form = "frame" if p.name in ("frame_mean_drift", "dark_frame_jitter") else "column"
            if form not in forms:
                forms.add(form)
                out.append((p, form))
        return out

    def family_of(self, p):
        if p.axis == "frame" and p.rate_dn_per_s:
            return FAMILIES["frame_rate"]
        return FAMILIES.get(p.axis, self.family)

    def fit(self, d, model, ctx):
        form = ctx.form
        if form not in FORMS:  # a refit beside another effect (whose form ctx carries): keep the model's
            held = model.effects.get(self.name)
            form = held.axis if held is not None else "column"
        if form == "frame":
            return _fit_frame(d, model)
        res = d.temporal_residuals("dark") or d.temporal_residuals("flat")
        means, excess = [], []
        for r in res:
            cm = r.mean(axis=1)  # (frames, W): each frame's column means
            cm = cm - cm.mean(axis=1, keepdims=True)
            means.append(cm.ravel())
            excess.append(float(np.mean(cm * cm)) - float(np.var(r)) / r.shape[1])
        m = np.concatenate(means)
        s2 = max(float(np.mean(excess)), 0.0)
        sd = float(np.std(m))
        if not (s2 > 0 and sd > 0):
            return EmpiricalOffset(quantiles_dn=[0.0] * N_QUANTILES)
        return EmpiricalOffset(quantiles_dn=_shrunk_quantiles(m, s2))

    def format(self, p):
        if not isinstance(p, EffectParams):
            p = self.params.from_dict(p)
        q = np.asarray(p.quantiles_dn, dtype=np.float64)
        sd = np.sqrt(quantile_table_moments(q)[1])
        return (f"quantiles_dn = {q.size} quantiles, sd {sd:.3g} DN, from {q[0]:.3g} to {q[-1]:.3g} DN, median "
                f"{float(np.interp(0.5, np.linspace(0, 1, q.size), q)):.3g} DN; axis = {p.axis}; "
                f"rate_dn_per_s = {p.rate_dn_per_s:.3g} DN/s")

    def is_null(self, p):
        return quantile_table_moments(p.quantiles_dn)[1] <= 0.0 and not p.rate_dn_per_s

    def dark_variance_dn2(self, p):
        # the read noise is measured with each frame's mean removed (``CaptureData.ptc_points``): a column
        # offset is in that variance, a whole frame's offset is not
        return 0.0 if p.axis == "frame" else quantile_table_moments(p.quantiles_dn)[1]

    def to_profile(self, p, model):
        from .card import ProfileTerm

        fs = model.full_scale_dn
        entry = {"type": self.name, "axis": p.axis, "temporal": True, "quantiles": [float(x) / fs for x in p.quantiles_dn]}
        if p.rate_dn_per_s:
            entry["rate"] = float(p.rate_dn_per_s) / fs
        return ProfileTerm(effect=entry)

    def from_profile(self, entry, full_scale_dn):
        axis = entry.get("axis", "pixel")
        if entry.get("map") is not None or not entry.get("temporal", False) or axis not in ("column", "frame"):
            raise ValueError("the loop reads an empirical_offset entry only as a temporal column or frame offset "
                             "given by quantiles (axis: column or frame, temporal: true)")
        return EmpiricalOffset(quantiles_dn=[float(x) * full_scale_dn * float(entry.get("scale", 1.0))
                                             for x in entry["quantiles"]], axis=axis,
                               rate_dn_per_s=float(entry.get("rate", 0.0)) * full_scale_dn)


def _shrunk_quantiles(m: np.ndarray, s2: float) -> list:
    """The :data:`N_QUANTILES` quantiles of the values ``m``, centred on their median and shrunk by
    ``sqrt(s2) / sd(m)`` (the Gaussian deconvolution of the white part), mean 0; zeros if s2 or sd is 0."""
    sd = float(np.std(m))
    if not (s2 > 0 and sd > 0):
        return [0.0] * N_QUANTILES
    q = np.quantile(m, np.linspace(0.0, 1.0, N_QUANTILES))
    q = (q - np.median(m)) * min(np.sqrt(s2) / sd, 1.0)
    q -= quantile_table_moments(q)[0]
    return [float(x) for x in q]


#: standard errors by which the dark level's unexplained rise per second must differ from 0 to be kept
RATE_Z = 3.0


def level_variance(means: np.ndarray) -> float:
    """Sampling variance of a sequence's level from its frames' means: their residual variance about a
    straight line in the frame index (n - 2 degrees of freedom) over their number, from 4 frames (else
    their variance about their mean). A level that drifts over the sequence (a clamp warming up) is then
    not taken for noise: the sequence's mean is the line's value at its middle frame, whose error is the
    residuals' alone; for frames independent from frame to frame both estimates are unbiased."""
    n = means.size
    if n < 4:
        return float(np.var(means, ddof=1)) / n
    i = np.arange(n, dtype=np.float64)
    i -= i.mean()
    r = means - means.mean() - i * (np.sum(i * means) / np.sum(i * i))
    return float(np.sum(r * r) / (n - 2)) / n


def _exposure_rate(d, model) -> float:
    """The rise of the dark level per second of exposure (DN/s) that the model's ``dark_current`` does not
    make (its ``non_poisson_dn_per_s``, a rise the dark variance does not follow; without dark current the
    whole rise): each dark sequence's level is the 1 %-trimmed mean of its temporal-mean image, as
    ``dark_signal_slope``'s; the slope is the least-squares one weighted by frame count, its standard error
    from each level's (:func:`level_variance`: a drift within a sequence is not noise of its level); 0
    unless beyond :data:`RATE_Z` of them, or with darks at fewer than 2 exposure times."""
    from scipy import stats as sst

    from .dark_current import _without_glow

    series = [(float(t), f) for t, f in _without_glow(d.dark_series or [], model) if f.shape[0] >= 2]
    if len({t for t, _ in series}) < 2:
        return 0.0
    t = np.array([ti for ti, _ in series])
    n = np.array([f.shape[0] for _, f in series], dtype=np.float64)
    level = np.array([float(sst.trim_mean(f.astype(np.float64).mean(0).ravel(), 0.01)) for _, f in series])
    var = np.array([level_variance(f.astype(np.float64).mean(axis=(1, 2))) for _, f in series])
    tc = t - np.sum(n * t) / n.sum()
    c = n * tc / np.sum(n * tc * tc)  # weighted least-squares slope weights
    slope, se = float(np.sum(c * level)), float(np.sqrt(np.sum(c * c * var)))
    dc = model.effects.get("dark_current")
    if dc is not None:
        slope = float(dc.non_poisson_dn_per_s)
    return slope if abs(slope) > RATE_Z * se else 0.0


def _fit_frame(d, model) -> EmpiricalOffset:
    """The frame form's fit from the dark sequences of >= 3 frames (module docstring); null without them."""
    from .. import diagnostics as dg

    rate = _exposure_rate(d, model)
    levels = dg.dark_frame_levels(d)
    means = [fm for fm, _white in levels]
    excess = [float(np.mean(fm * fm)) - white for fm, white in levels]
    if not means:
        return EmpiricalOffset(quantiles_dn=[0.0] * N_QUANTILES, axis="frame", rate_dn_per_s=rate)
    return EmpiricalOffset(quantiles_dn=_shrunk_quantiles(np.concatenate(means), max(float(np.mean(excess)), 0.0)),
                           axis="frame", rate_dn_per_s=rate)
