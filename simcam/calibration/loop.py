"""The calibration loop: base fit, residual battery, attribution, refit, held-out before/after.

Per ISO group of a capture set:

1. Frames of each sequence are split by parity: the even frames fit, the odd
   frames are held out (sequences of < 4 frames only fit). The model is
   stationary (it has no frame index), so the halves are interleaved: a level or
   gain that drifts over a sequence spreads the frame means of both halves alike,
   which a per-frame component can describe, where a split in time would put the
   held-out half at another level than any fit half can reach.
2. Base fit (:func:`simcam.calibration.fit.base_fit`).
3. Every diagnostic of :mod:`simcam.calibration.diagnostics` is computed on the
   fit frames and on ``replicates`` captures simulated from the current model
   (parametric bootstrap, same shapes and frame counts); standardised
   discrepancies get Student-t p-values; significance by Holm's step-down
   procedure at family-wise ``alpha`` (default 0.01) over the applicable
   diagnostics.
4. Attribution by held-out model comparison (:mod:`simcam.calibration.attribution`): every
   significant diagnostic proposes the effect whose card lists it
   (:mod:`simcam.calibration.effects`; a diagnostic no card lists, or whose effect is already in the
   model, is ``unexplained``); *every* proposed effect is fitted by its card, the current model and
   each candidate are simulated on the held-out sequences with the same random streams, and each
   candidate is scored by the held-out synthetic log-likelihood of all applicable diagnostics
   (gain over the current model, with its jackknife standard error). Candidates race: each gets
   the first of :data:`RACE_STAGES` held-out replicates, and only those still within reach of the leader
   (or of the minimum gain) after each stage get the next, so a clear loser costs a third of a full
   scoring.
5. The best candidate is added when its gain exceeds its sampling noise
   (:meth:`simcam.calibration.attribution.Comparison.beats`), it does not make the held-out error
   grow (:func:`error_grew`: the structured marginal KL of aggregated noise,
   :mod:`simcam.calibration.heldout`, or its per-plane one-pixel family, beyond ``kl_tolerance`` and
   twice their sampling SD), and it breaks no diagnostic the current model reproduces on the held-out
   frames (:meth:`Loop._broken`). A refused or refuted candidate is passed over for the best of the
   others. The structured KL, the pooled one-pixel marginal KL (Noise Flow binning, Jeffreys-smoothed
   model histogram) and the NLL/dim of the model's Gaussian marginal are reported before and after,
   with every candidate's score.
   Candidates whose gains differ by less than twice their combined standard errors cannot be told
   apart by the held-out frames; of those, one the sensor's previous ISO groups added is taken (a hot
   pixel saturated at a high ISO reads as a stuck one there), else the one the strongest residual
   proposed (:meth:`Loop._break_tie`).
   Two or more candidates that gain beyond their sampling noise but are refuted (the held-out error
   grows, or a statistic breaks) may each explain part of one residual: a black offset beside a dark
   level that rises with the exposure time, where the offset alone moves the long darks away and the
   rise alone the short ones. When no candidate beats the current model, or a refuted one gained more
   than the chosen one by twice their combined SEs, each pair of them (the :data:`JOINT_CANDIDATES`
   best) is fitted jointly (the second effect's fit sees the first in the model) and raced like a
   single candidate; the best of the pairs that beat the current model and the chosen single one is
   taken, and a pair adds both effects (:meth:`Loop._joint`).
   When nothing beats the current model, the proposing diagnostics are ``unexplained`` with the
   candidates' scores as the reason, and the loop stops (also when nothing significant is left, or
   after ``max_iterations``).
6. Backward step (:meth:`Loop._backward`; stepwise selection with a backward step, M. A. Efroymson,
   "Multiple regression analysis", in *Mathematical Methods for Digital Computers*, Wiley, 1960): an
   effect added early can be superseded by one added later that explains the same residual better.
   Each effect the loop added is left out of the final model in turn, and the model without it is
   scored against the model with it as a candidate is (same held-out replicates, same statistics);
   the one whose keeping gains least is taken out when that gain does not beat its sampling noise (the
   rule a candidate must pass to enter) and the model without it neither grows the held-out error nor
   breaks a statistic; repeated until every effect left earns its keep (the others keep their fitted
   parameters, the read noise takes back the variance a removed effect held). Effects whose addition
   re-measured the system gain or the dark variance, and those another effect needs (a prerequisite) or
   is refitted after, stay.

Cost. Every replicate (a simulated capture reduced to its statistics) is drawn from its own stream,
``(seed, iso, purpose, ..., r)``, and replicates run on ``threads`` threads (numpy and the noise
kernels release the GIL) with their results merged in replicate order: the same bytes for any thread
count. Where the fit and held-out halves have the same layout (every sequence an even number of >= 4
frames) the model's held-out replicates are also its bootstrap null on the fit frames (step 3), so
no separate bootstrap is simulated.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import hashlib
import os

import numpy as np

from ..errors import DatasetError
from . import diagnostics as dg
from .attribution import MIN_GAIN, compare, gain_beats
from .binning import hist_uniform
from .capture import CaptureSet, Sequence
from .effects import FitContext, card_for, effect_for, excluded_by
from .fit import base_fit, fit_effect
from .heldout import KL_EDGES, StructuredKL, kl_counts, kl_floor
from .model import LoopModel, SimSpec, marginal_variance, shot_factors, site_map
from .region import DEFAULT_MAX_PIXELS, DEFAULT_TILE, Region
from .simulate import simulate_capture

@dataclass
class LoopConfig:
    replicates: int = 16
    heldout_replicates: int = 12  # held-out simulations per model scored (attribution by model comparison)
    alpha: float = 0.01
    max_iterations: int = 10
    seed: int = 0
    max_size: int | None = None  # centre crop (pixels per side) instead of the whole frame / tile mosaic
    max_pixels: int = DEFAULT_MAX_PIXELS  # pixels analysed per frame (whole frame up to this, else a tile mosaic)
    tile: int = DEFAULT_TILE
    progress: bool | None = None  # progress bars (None: when the output is a terminal)
    kl_tolerance: float = 0.10  # relative growth of the held-out structured KL (and its pixel family) still accepted, plus 2 SDs
    threads: int | None = None  # replicates simulated at once (None: $SIMCAM_LOOP_THREADS, else the cores this process may use)
    maps: bool = False  # keep the measured fixed patterns in maps.npz beside profile.yaml (simcam.calibration.maps)

    def region(self) -> Region:
        """The pixels the residual battery and the bootstrap analyse (:mod:`simcam.calibration.region`)."""
        return Region(max_pixels=self.max_pixels, tile=self.tile, max_size=self.max_size)


@dataclass
class GroupResult:
    iso: int
    base: LoopModel
    model: LoopModel
    iterations: list = field(default_factory=list)
    unexplained: list = field(default_factory=list)
    final: list = field(default_factory=list)  # Discrepancy of the final model
    base_disc: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    plots: dict = field(default_factory=dict)
    heldout_base: dict = field(default_factory=dict)
    heldout_final: dict = field(default_factory=dict)
    not_applicable: dict = field(default_factory=dict)  # diagnostic -> reason
    backward: list = field(default_factory=list)  # the backward step's tests (Loop._backward), in order
    bootstrap_null: str = ""  # what the residual battery's null was drawn from


def _t(s: Sequence) -> float:
    return float(s.exposure_s) if s.exposure_s is not None else -1.0


def _fmt_s(t: float) -> str:
    return "exposure time not given" if t < 0 else f"{t:.4g} s"


def dark_exposure(darks: list[Sequence]) -> float | None:
    """The exposure time (s; -1 when not given) of the darks the dark diagnostics, the black level, the
    read noise and the DSNU are measured on: the shortest given one (EMVA 1288 Release 4.0 measures
    the temporal dark noise at the shortest exposure time, where the dark current adds least); -1
    when no dark sequence gives its exposure time; None without darks."""
    if not darks:
        return None
    given = sorted(_t(s) for s in darks if _t(s) >= 0)
    return given[0] if given else -1.0


class Group:
    """Fit / held-out views of one ISO group of a capture set."""

    def __init__(self, seqs: list[Sequence], cfg: LoopConfig, notes: list):
        self.seqs = []
        saturated = []
        for s in seqs:
            if s.kind == "flat" and s.saturated_fraction() > 0.01:
                saturated.append(f"{s.name} ({100 * s.saturated_fraction():.0f}% at white)")
                continue
            self.seqs.append(s)
        if saturated:
            notes.append(f"saturated flat{'s' if len(saturated) > 1 else ''} left out of the loop: "
                         + ", ".join(saturated))
        if not self.seqs:
            raise DatasetError(f"ISO {seqs[0].iso}: no usable sequence left (all saturated)")
        self.dark_exposure_s = None
        self.series = False  # darks at >= 2 given exposure times: the dark-current series
        darks = [s for s in self.seqs if s.kind == "dark"]
        t_dark = dark_exposure(darks)
        if t_dark is not None:
            self.dark_exposure_s = t_dark
            other = sorted({_t(s) for s in darks} - {t_dark})
            if other:
                self.series = t_dark >= 0
                if not self.series or any(t < 0 for t in other):  # darks without an exposure time: left out
                    self.seqs = [s for s in self.seqs if s.kind != "dark" or _t(s) == t_dark
                                 or (self.series and _t(s) >= 0)]
                listed = ", ".join(_fmt_s(t) for t in other) if len(other) <= 4 else \
                    f"{len(other)} other exposure times ({_fmt_s(other[0])} to {_fmt_s(other[-1])})"
                notes.append(f"darks at {_fmt_s(t_dark)} used for the dark diagnostics, black level, read noise "
                             f"and DSNU (the shortest exposure time); darks at {listed} only in the dark-current "
                             "diagnostic and fit and in the held-out error (dark sequences of different "
                             "exposure times are not pooled)")
        r0 = self.seqs[0]
        self.cfa, self.white = r0.cfa, r0.white_dn
        self.black = r0.black_dn
        self.fit, self.held = [], []
        region = cfg.region()
        h, w = r0.shape
        self.region = region.describe(h, w)
        for s in self.seqs:
            f = s.frames if s.region_applied else region.extract(s.frames)
            clean = None if s.clean is None or s.region_applied else region.extract(s.clean)
            if s.n >= 4:
                self.fit.append((s, f[0::2], clean))
                self.held.append((s, f[1::2], clean))
            else:
                self.fit.append((s, f, clean))
        if not self.held:
            notes.append("no sequence has >= 4 frames: held-out errors are computed on the fit frames")
            self.held = list(self.fit)
        #: the fit and held-out halves hold the same sequences with the same frame counts (even frame counts,
        #: every sequence >= 4 frames; or no held-out half): a model's held-out replicates are then also its
        #: bootstrap null on the fit frames
        self.same_layout = len(self.fit) == len(self.held) and all(
            a[1].shape == b[1].shape for a, b in zip(self.fit, self.held))
        self.fit_data = self._data(self.fit)
        self.held_data = self._data(self.held)

    def series_only(self, s: Sequence) -> bool:
        """A dark at another exposure time than the dark diagnostics' (dark-current series only)."""
        return s.kind == "dark" and _t(s) != self.dark_exposure_s

    def _data(self, part) -> dg.CaptureData:
        darks = [f for s, f, _ in part if s.kind == "dark" and not self.series_only(s)]
        flats = [f for s, f, _ in part if s.kind == "flat"]
        scenes = [(f, c) for s, f, c in part if s.kind == "scene"]
        series = [(max(_t(s), 0.0), f) for s, f, _ in part if s.kind == "dark"] if self.series else None
        return dg.CaptureData(darks, flats, scenes, self.black, self.white, self.cfa, dark_series=series)

    def specs(self, model: LoopModel, part) -> list[SimSpec]:
        out = []
        offs = model.black_offset_dn()
        for s, f, clean in part:
            shape = f.shape[1:]
            base = site_map(model.black_dn.ravel() + offs, shape)
            if s.kind == "dark":
                sig = np.zeros(shape)
            elif s.kind == "flat":
                pm = [float(f[:, dy::2, dx::2].mean()) for dy, dx in dg.PLANE_OFFSETS]
                sig = site_map(pm, shape) - base
            else:
                ref = clean if clean is not None else f.astype(np.float64).mean(0)
                sig = ref - base
            out.append(SimSpec(s.kind, f.shape[0], sig, fixed_in_clean=(s.kind == "scene" and clean is None),
                               exposure_s=max(_t(s), 0.0), series_only=self.series_only(s)))
        return out


#: values of held-out noise kept per histogram of the report's figures
PLOT_VALUES = 200_000


def _thin(x: np.ndarray, n: int = PLOT_VALUES) -> np.ndarray:
    """Every k-th value of ``x`` so that at most ``n`` remain (for the report's histograms)."""
    return x[:: max(1, -(-x.size // n))].copy()


def _capture(group: Group, part, sims, specs) -> dg.CaptureData:
    return (group.fit_data if part is group.fit else group.held_data).like(sims, specs)


def noise_frames(part, frames_list, specs, model: LoopModel) -> list[np.ndarray]:
    """Signed noise on normalised raw, per sequence (n, H, W): frame minus the sequence's clean level
    under the model (black + black offset + signal of its :class:`SimSpec`), the same reference for data
    and simulations (so discrete ADC codes fall on the same lattice in both).

    A scene without a clean reference (``fixed_in_clean``) has the per-pixel mean of its own frames as
    the data's reference, which takes one frame's worth of noise out of the residual (variance
    ``(n - 1) / n`` of the noise's); the simulated frames, drawn about that mean, are taken about their
    own per-pixel mean too, so both sides of the comparison have the same shrinkage (taken about the
    data's mean instead, a simulation's residual has the full variance: 7 % more spread than the data's
    with 8 held-out frames, whatever the model)."""
    fs = model.full_scale_dn
    offs = model.black_offset_dn()
    out = []
    for fr, sp in zip(frames_list, specs):
        x = fr.astype(np.float64)
        if sp.fixed_in_clean:
            x -= x.mean(axis=0)
        else:
            x -= sp.signal_dn + site_map(model.black_dn.ravel() + offs, sp.signal_dn.shape)
        out.append(x / fs)
    return out


def noise_values(part, frames_list, specs, model: LoopModel) -> np.ndarray:
    """:func:`noise_frames` of all sequences, flattened into one array."""
    return np.concatenate([x.ravel() for x in noise_frames(part, frames_list, specs, model)])


def nll_per_dim(part, specs, model: LoopModel) -> float | None:
    """Mean negative log-likelihood (nats per value) of held-out noise under the model's Gaussian
    marginal (about the plane mean / clean), or None when the model has no such density."""
    fs = model.full_scale_dn
    tot, n = 0.0, 0
    for (s, f, clean), sp in zip(part, specs):
        v = marginal_variance(model, sp.signal_dn, fixed_in_clean=sp.fixed_in_clean)
        if v is None:
            return None
        x = noise_values([(s, f, clean)], [f], [sp], model).reshape(f.shape)
        vn = v / fs ** 2
        if sp.fixed_in_clean:  # about the frames' own mean (noise_frames): variance (n - 1) / n
            vn = vn * max(f.shape[0] - 1, 1) / f.shape[0]
        tot += float(np.sum(0.5 * np.log(2 * np.pi * vn) + x * x / (2 * vn)))
        n += x.size
    return tot / n


HELDOUT_KEYS = ("kl", "nll", "kl_floor", "kl_excess", "kl_structured", "structured")


def candidate_label(rec: dict) -> str:
    """A candidate's name in the report: its effect, ``first + second`` for a pair fitted jointly."""
    joint = rec.get("joint_with")
    return f"{joint['effect']} + {rec['effect']}" if joint else rec["effect"]


def _summary(held: dict) -> dict:
    """The held-out numbers kept in a :class:`GroupResult` (no sample arrays)."""
    return {k: held[k] for k in HELDOUT_KEYS}


#: held-out replicates after which the race drops the candidates that cannot be chosen (then the full count):
#: every candidate gets the first stage's; dropping at 8 too saves a third of the replicates of a candidate
#: that 4 replicates left within reach (their SE is wide) and 8 do not
RACE_STAGES = (4, 8)
#: a candidate leaves the race when its gain is this many combined SEs behind the leader's, or this many of
#: its own SEs below :data:`attribution.MIN_GAIN`
RACE_Z = 5.0
#: the least standard error (nats) the race takes a stage-one gain to have
RACE_SE_FLOOR = 1.0


def race_stages(replicates: int) -> list[int]:
    """The replicate counts a race scores at: those of :data:`RACE_STAGES` below ``replicates``, then all."""
    return sorted({min(s, replicates) for s in RACE_STAGES} | {replicates})


def race_margin(sd: float) -> float:
    """:data:`RACE_Z` standard errors of a gain, the SE taken at least :data:`RACE_SE_FLOOR` nats (an SE from a
    few replicate pairs can come out near 0 by chance)."""
    return RACE_Z * max(sd, RACE_SE_FLOOR)


#: a candidate whose gain is above this many SEs (and MIN_GAIN) but not GAIN_Z gets twice the replicates
UNCERTAIN_Z = 1.5
#: a diagnostic the current model reproduces with a held-out p-value at least this can refute a candidate
#: that fails it (:meth:`Loop._broken`)
REFUTE_PASS_P = 0.1


#: refuted candidates (gain beyond its noise, refuted by the held-out error or a broken statistic) of which
#: the pairs are fitted jointly (the best by gain; :meth:`Loop._joint` says when)
JOINT_CANDIDATES = 3


#: environment variable that sets the loop's default thread count (e.g. 1 where processes already share the cores)
THREADS_ENV = "SIMCAM_LOOP_THREADS"


def loop_threads(cfg: LoopConfig) -> int:
    """Threads of the loop's replicates (and of reading the capture set): ``cfg.threads``, else
    :data:`THREADS_ENV`, else the cores this process may run on."""
    if cfg.threads is not None:
        return max(1, int(cfg.threads))
    env = os.environ.get(THREADS_ENV, "").strip()
    if env:
        try:
            return max(1, int(env))
        except ValueError:
            raise DatasetError(f"environment {THREADS_ENV}={env!r}: expected a whole number of threads") from None
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def error_grew(held: dict, cur: dict, tolerance: float) -> str | None:
    """Why the held-out error of a candidate (``held``) counts as grown against the current model's
    (``cur``), or None: the structured KL of aggregated noise (:func:`simcam.calibration.heldout.structured_kl`),
    or its ``pixel`` family alone (the one-pixel marginal of each sequence and CFA plane), exceeds the
    current model's by ``tolerance`` relative plus twice the combined sampling SD (each model's SD from
    its own replicates). The pixel family is judged on its own because the sum counts only significant
    families: a heavy-tailed read noise added where hot pixels are already modelled lowered the sum
    (another family's excess fell) while the per-plane marginals moved 10 SDs away from the data. The
    pooled one-pixel KL of all sequences (``kl``, reported) is not a criterion: with a black offset not
    yet modelled, a right DSNU widened the shifted pooled marginal (0.044 -> 0.051 on the loop
    benchmark's 12 MP set) while every per-plane marginal came closer (pixel family 0.54 -> 0.45)."""
    out = []
    pa, pb = held["structured"].get("pixel"), cur["structured"].get("pixel")
    if pa is not None and pb is not None and pa["kl"] > pb["kl"] * (1 + tolerance) + 2 * float(np.hypot(pa["sd"], pb["sd"])):
        out.append(f"pixel family KL {pb['kl']:.3g} -> {pa['kl']:.3g}")
    sa, sb = held["kl_structured"], cur["kl_structured"]
    if sa > sb * (1 + tolerance) + 2 * float(np.hypot(held["kl_structured_sd"], cur["kl_structured_sd"])):
        out.append(f"structured KL {sb:.3g} -> {sa:.3g}")
    return "; ".join(out) or None


class HeldOut:
    """The held-out simulations of one model, replicate by replicate (a candidate can leave the race
    after a stage of :data:`RACE_STAGES` and the others go on): pixel-marginal counts, the structured KL's
    histograms, the diagnostics of every replicate and the first replicates' values for the figures.
    Replicate ``r`` is drawn from the stream ``(seed, iso, 2, 0, r)`` whatever the model (common random
    numbers), so the result is the same bytes whatever the thread count."""

    def __init__(self, loop: "Loop", model: LoopModel, diagnostics=(), label: str = "current model"):
        g = loop.g
        self.loop, self.model, self.diagnostics, self.label = loop, model, tuple(diagnostics), label
        self.specs = g.specs(model, g.held)
        self.n_real, self.real_thin, self.n_counts, st = loop.data_side(model, self.specs)
        self.m_counts = np.zeros_like(self.n_counts)
        self.m_size = 0
        self.plot: list[np.ndarray] = []  # the first replicates' values, up to twice the data's count
        self.plot_size = 0
        self.model_thin = None
        self.st = st.fresh()
        self.sims: dict[str, list] = {name: [] for name in self.diagnostics}
        self.done = 0

    def _one(self, r: int):
        """Replicate ``r`` reduced to what the result needs (runs in a worker thread)."""
        g, model, specs = self.loop.g, self.model, self.specs
        sims = simulate_capture(model, specs, self.loop._rng(2, 0, r))
        nf = noise_frames(g.held, sims, specs, model)
        counts = np.zeros(KL_EDGES.size - 1, np.int64)
        for x in nf:
            hist_uniform(x, KL_EDGES, out=counts)
        size = sum(x.size for x in nf)
        # each replicate holds as many values as the data: the first two fill the figures' sample
        plot = np.concatenate([x.ravel() for x in nf]) if r < 2 else None
        st = self.st.counts(nf)
        stats = dg.compute_all(_capture(g, g.held, sims, specs), self.diagnostics) if self.diagnostics else {}
        return counts, size, plot, st, stats

    def extend(self, upto: int) -> "HeldOut":
        """Simulate replicates ``done .. upto - 1``."""
        rs = range(self.done, upto)
        for counts, size, plot, st, stats in self.loop.map(self._one, rs, f"held-out, {self.label}"):
            self.m_counts += counts
            self.m_size += size
            if plot is not None and self.plot_size < 2 * self.n_real:
                take = plot[: 2 * self.n_real - self.plot_size]
                self.plot.append(take)
                self.plot_size += take.size
            self.st.add_counts(st)
            for name in self.diagnostics:
                self.sims[name].append(stats[name])
        self.done = max(self.done, upto)
        return self

    def result(self) -> dict:
        loop, g = self.loop, self.loop.g
        kl = kl_counts(self.n_counts, self.m_counts)
        floor = kl_floor(self.n_counts + self.m_counts, self.n_real, self.m_size)
        st = self.st.result()
        if self.plot:  # thinned once; the full values are dropped (the first replicates fill the plot)
            self.model_thin = _thin(np.concatenate(self.plot), 2 * PLOT_VALUES)
            self.plot = []
        out = {"kl": kl, "nll": nll_per_dim(g.held, self.specs, self.model), "kl_floor": floor,
               "kl_excess": max(kl - floor, 0.0), "kl_structured": st["kl"], "structured": st["families"],
               "kl_structured_sd": float(np.sqrt(sum(f["sd"] ** 2 for f in st["families"].values()
                                                     if f["significant"]))),
               "real_noise": self.real_thin, "model_noise": self.model_thin,
               "sims": dict(self.sims), "replicates": self.done, "_run": self}
        for name in self.diagnostics:
            vals = self.sims[name]
            if loop.held_stats.get(name) is None or any(v is None for v in vals):
                continue
            out[name] = dg.discrepancy(name, loop.held_stats[name], vals, loop.held_floor(name), loop.held_null(name))
        return out


class Loop:
    """Runs the loop on one ISO group."""

    def __init__(self, group: Group, cfg: LoopConfig, iso: int, preferred=()):
        self.g, self.cfg, self.iso = group, cfg, iso
        #: effects added at the sensor's other ISOs: taken where the held-out frames cannot tell candidates apart
        self.preferred = set(preferred)
        self.discs: list = []  # the current model's battery, set each iteration (Loop.run)
        #: diagnostic -> why it is not applicable (on the data, or on the simulated captures)
        self.not_applicable: dict[str, str] = {}
        self.data_stats = dg.compute_all(group.fit_data, reasons=self.not_applicable)
        self.held_stats = dg.compute_all(group.held_data)
        self.applicable = [k for k, v in self.data_stats.items() if v is not None]
        self._floors: dict[str, float] = {}
        self._nulls: dict[str, float | None] = {}  # diagnostic -> closed-form count (held_null)
        self._data_sides: dict[bytes, tuple] = {}  # digest of the held-out clean levels -> HeldOut's data side
        self.threads = loop_threads(cfg)

    def data_side(self, model: LoopModel, specs) -> tuple:
        """The held-out data's side of :class:`HeldOut` under ``model`` (value count, thinned values, pooled
        histogram, :class:`StructuredKL` of the residuals), computed once per distinct set of residuals:
        they depend on the model only through each sequence's clean level (``dsnu``, ``prnu``, ``column_fpn``
        and most other candidates leave it as it is), and building them is serial work (about a second per
        candidate on the 12 MP benchmark set) while the replicates run on every core."""
        h = hashlib.blake2b(digest_size=16)
        h.update(np.asarray([model.full_scale_dn], np.float64).tobytes())
        h.update(np.ascontiguousarray(model.black_dn, np.float64).tobytes())
        h.update(np.ascontiguousarray(model.black_offset_dn(), np.float64).tobytes())
        for sp in specs:
            h.update(b"F" if sp.fixed_in_clean else np.ascontiguousarray(sp.signal_dn, np.float64).tobytes())
        key = h.digest()
        if key not in self._data_sides:
            g = self.g
            real_f = noise_frames(g.held, [f for _, f, _ in g.held], specs, model)
            real = np.concatenate([x.ravel() for x in real_f])
            # (the thinned values stay alive with the current model: no full copies kept)
            self._data_sides[key] = (real.size, _thin(real), hist_uniform(real, KL_EDGES),
                                     StructuredKL(real_f, [sp.fixed_in_clean for sp in specs]))
        return self._data_sides[key]

    def held_floor(self, name: str) -> float:
        """The resolution of diagnostic ``name`` on the held-out data (:func:`diagnostics.resolution`)."""
        if name not in self._floors:
            self._floors[name] = dg.resolution(name, self.g.held_data)
        return self._floors[name]

    def held_null(self, name: str) -> float | None:
        """The closed-form count of a pixel-count statistic on the held-out data under a model without its
        effect (:func:`diagnostics.count_null`), or None."""
        if name not in self._nulls:
            self._nulls[name] = dg.count_null(name, self.g.held_data)
        return self._nulls[name]

    def map(self, fn, items, what: str):
        """``fn`` over ``items`` on :attr:`threads` threads (numpy and the noise kernels release the GIL),
        results in the order of ``items``, with a progress bar."""
        from tqdm.auto import tqdm

        items = list(items)
        label = f"ISO {self.iso}" if self.iso > 0 else "ISO not given"
        bar = tqdm(total=len(items), desc=f"{label}: {what}", unit="capture", leave=False,
                   disable=None if self.cfg.progress is None else not self.cfg.progress)
        try:
            if self.threads <= 1 or len(items) <= 1:
                for x in items:
                    yield fn(x)
                    bar.update(1)
                return
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(min(self.threads, len(items))) as ex:
                for out in ex.map(fn, items):
                    yield out
                    bar.update(1)
        finally:
            bar.close()

    def _rng(self, *tag):
        return np.random.default_rng([self.cfg.seed, self.iso, *tag])

    def evaluate(self, model: LoopModel, tag: int, held: dict | None = None) -> list:
        """Discrepancies of the fit frames' statistics from the model's bootstrap null (Holm-marked).

        The null is ``replicates`` captures simulated on the fit frames' layout; where the fit and held-out
        halves have the same layout (:attr:`Group.same_layout`) the model's held-out replicates ``held``
        (already simulated to score it, every applicable diagnostic on each) are draws of the same null
        and are used instead."""
        if held is not None and self.g.same_layout:
            return self._discrepancies(held["sims"])
        specs = self.g.specs(model, self.g.fit)

        def one(r):
            sims = simulate_capture(model, specs, self._rng(1, tag, r))
            return dg.compute_all(_capture(self.g, self.g.fit, sims, specs), self.applicable)

        sim_stats = list(self.map(one, range(self.cfg.replicates), f"bootstrap {tag}"))
        return self._discrepancies({name: [s[name] for s in sim_stats] for name in self.applicable})

    def _discrepancies(self, sims: dict) -> list:
        discs = []
        for name in self.applicable:
            vals = sims[name]
            undefined = sum(v is None for v in vals)
            if undefined:  # defined on the data, not on (some) simulated captures: no null to compare with
                self.not_applicable[name] = (f"undefined on {undefined} of {len(vals)} simulated captures of the "
                                             "current model (no bootstrap null)")
                continue
            discs.append(dg.discrepancy(name, self.data_stats[name], vals, dg.resolution(name, self.g.fit_data),
                                        dg.count_null(name, self.g.fit_data)))
        return dg.holm(discs, self.cfg.alpha)

    def heldout(self, model: LoopModel, diagnostics=()) -> dict:
        """All :attr:`LoopConfig.heldout_replicates` held-out replicates of ``model`` (:class:`HeldOut`)."""
        return HeldOut(self, model, diagnostics).extend(self.cfg.heldout_replicates).result()

    def _fit_candidate(self, effect: str, proposed_by: list, model: LoopModel, tag: int, via=None):
        """Fit ``effect`` on the fit frames from the proposing diagnostic ``via`` (default: the strongest):
        (candidate record for the report, fitted model or None)."""
        card = card_for(effect)
        chosen, form = via if isinstance(via, tuple) else (via or proposed_by[0], "")
        rec = {"effect": effect, "proposed_by": [d.name for d in proposed_by], "fitted_from": chosen.name}
        if form:
            rec["form"] = form
        ctx = FitContext(diagnostic=chosen.name, value=chosen.value, sim_mean=chosen.sim_mean, form=form,
                         seed=self.cfg.seed * 1000 + tag, simulate=simulate_capture, shot_factors=shot_factors,
                         dark_specs=[sp for sp in self.g.specs(model, self.g.fit)
                                     if sp.kind == "dark" and not sp.series_only])
        if card.needs_darks and not ctx.dark_specs:
            return dict(rec, skipped="needs a dark sequence to fit"), None
        pre = card.prerequisite(self.g.fit_data, model)
        if pre is not None:  # fitted first, from its own diagnostic where the battery has it; the candidate adds both
            pre_from = next((d for d in self.discs if d.name in card_for(pre).diagnostics), chosen)
            first = fit_effect(pre, self.g.fit_data, model, dataclasses.replace(
                ctx, diagnostic=pre_from.name, value=pre_from.value, sim_mean=pre_from.sim_mean))
            if card_for(pre).is_null(first.effects[pre]):
                return dict(rec, skipped=f"needs {pre} first, whose fit has zero magnitude"), None
            rec["joint_with"] = {"effect": pre, "fitted_from": pre_from.name,
                                 "parameters": first.effects[pre].to_dict(), "prerequisite": True}
            model = first
        cand = fit_effect(effect, self.g.fit_data, model, ctx)
        rec["parameters"] = cand.effects[effect].to_dict()
        if card.is_null(cand.effects[effect]):
            why = card.null_reason(cand.effects[effect])
            return dict(rec, skipped=f"the fitted {effect} has zero magnitude" + (
                f" (nothing for the form {form!r} to model here)" if form else "") + (f": {why}" if why else "")), None
        return rec, cand

    def _score(self, rec: dict, run: HeldOut, held_cur: dict) -> None:
        """``rec`` gets the held-out comparison of ``run``'s replicates with the current model's same ones."""
        n = run.done
        cur = {k: v[:n] for k, v in held_cur["sims"].items()}
        cmp = compare(self.held_stats, self._floor_map(), cur, run.sims, held_cur.setdefault("_scores", {}),
                      self._null_map())
        rec.update({"heldout_gain": cmp.gain, "heldout_gain_sd": cmp.sd, "statistics_compared": cmp.diagnostics,
                    "moved_most": [{"diagnostic": k, "gain": g} for k, g in cmp.top()], "replicates": n,
                    "_beats": cmp.beats()})

    def _race(self, fitted: list, held_cur: dict) -> list:
        """Score every fitted candidate (record, model) on the held-out frames in stages of
        :data:`RACE_STAGES` replicates, then the full count: after each stage a candidate leaves when its
        gain is :data:`RACE_Z` combined SEs behind the leader's (beyond the window in which candidates count
        as tied), or :data:`RACE_Z` SEs below :data:`attribution.MIN_GAIN`; those still in get the next
        stage's replicates. Within a stage every candidate is scored on the same replicates (the leader's
        gain is that of the stage, not of more replicates: a gain from fewer replicates, with a wider
        predictive law, falls short of a full-replicate one, and a tied hot-pixel candidate once left
        "71 nats behind"). Returns (record, model, held-out dict) per candidate."""
        R = self.cfg.heldout_replicates
        stages = race_stages(R)
        runs = []
        for rec, cand in fitted:
            run = HeldOut(self, cand, tuple(self.applicable), f"+ {rec['effect']}").extend(stages[0])
            self._score(rec, run, held_cur)
            runs.append((rec, cand, run))
        behind = set()  # ids of the records that left the race behind a leader (not for a low gain)
        for k, n in enumerate(stages):
            racing = [t for t in runs if "left_race" not in t[0]]
            if k:
                for rec, _cand, run in racing:
                    self._score(rec, run.extend(n), held_cur)
            if n == R or not racing:
                break
            lead = max(racing, key=lambda t: t[0]["heldout_gain"])[0]
            for rec, _cand, _run in racing:
                gap = lead["heldout_gain"] - rec["heldout_gain"]
                if gap > race_margin(np.hypot(lead["heldout_gain_sd"], rec["heldout_gain_sd"])):
                    rec["left_race"] = f"{gap:.3g} nats behind {lead['effect']} after {n} replicates"
                    behind.add(id(rec))
                elif rec["heldout_gain"] + race_margin(rec["heldout_gain_sd"]) < MIN_GAIN:
                    rec["left_race"] = f"gain below {MIN_GAIN:g} nats by > {RACE_Z:g} SE after {n} replicates"
        for rec, _cand, run in runs:
            # a gain short of GAIN_Z SEs but beyond UNCERTAIN_Z: the replicates are doubled for it and for the
            # current model, and the comparison is made again (the jackknife SE of 12 pairs is itself noisy)
            if "left_race" in rec or rec["_beats"] or run.done < R:
                continue
            if rec["heldout_gain"] > MIN_GAIN and rec["heldout_gain"] > UNCERTAIN_Z * rec["heldout_gain_sd"]:
                cur = held_cur["_run"]
                if cur.done < 2 * R:
                    held_cur.update(cur.extend(2 * R).result())
                self._score(rec, run.extend(2 * R), held_cur)

        def judged(items):
            out = []
            for rec, cand, run in items:
                held = run.result()
                worse = error_grew(held, held_cur, self.cfg.kl_tolerance)
                kl_ok = worse is None
                beats = rec.pop("_beats") and "left_race" not in rec
                broken = self._broken(held, held_cur)
                if broken:
                    rec["breaks"] = broken
                if worse:
                    rec["error_grew"] = worse
                rec.update({"kl_before": held_cur["kl"], "kl_after": held["kl"], "kl_ok": kl_ok,
                            "kl_structured_after": held["kl_structured"],
                            "beats_current": bool(beats and kl_ok and not broken)})
                out.append((rec, cand, held))
            return out

        out = judged(runs)
        # a leader refuted on the held-out frames (it breaks a statistic the current model reproduces, or the
        # held-out error grows) must not have sent the others out of the race: where none of those that
        # stayed beats the current model and one of them is refuted, those that left behind a candidate get
        # the full replicates and are judged again
        stayed = [rec for rec, _c, _h in out if "left_race" not in rec]
        if stayed and not any(r["beats_current"] for r in stayed) and any(r.get("breaks") or not r["kl_ok"]
                                                                           for r in stayed):
            again = [t for t in runs if id(t[0]) in behind]
            for rec, _cand, run in again:
                rec["raced_again"] = rec.pop("left_race") + "; raced again: the candidates ahead were refuted"
                self._score(rec, run.extend(R), held_cur)
            redo = {id(t[0]) for t in again}
            out = [t for t in out if id(t[0]) not in redo] + judged(again)
        return out

    def _broken(self, held: dict, held_cur: dict) -> list[dict]:
        """The diagnostics a candidate breaks on the held-out frames: those the current model reproduces
        (p >= :data:`REFUTE_PASS_P`: the held-out value unremarkable under it) and the candidate fails
        beyond the family-wise level (p < ``alpha`` / the number of diagnostics compared, Bonferroni),
        further from the data than the current model. (A diagnostic already near the edge under the
        current model, p 0.01-0.1, can cross the family-wise level by chance when any effect is added:
        a right PRNU candidate moved a column spectrum peak from z 2.9 to 5.3.) A candidate
        that explains one statistic by breaking another is refuted whatever its summed gain (a
        posterior predictive check, A. Gelman et al., *Bayesian Data Analysis*, 3rd ed., ch. 6): a dark
        level that rises between exposures, fitted as dark current, predicts a dark variance that rises
        with it, which a drifting black level does not have."""
        names = [n for n in self.applicable if held.get(n) is not None and held_cur.get(n) is not None]
        level = self.cfg.alpha / max(len(names), 1)
        out = []
        for n in names:
            a, b = held[n], held_cur[n]
            if a.p < level and b.p >= REFUTE_PASS_P and abs(a.z) > abs(b.z):
                out.append({"diagnostic": n, "z": float(a.z), "p": float(a.p), "z_before": float(b.z)})
        return out

    def _break_tie(self, best: tuple, scored: list, sig: list) -> tuple:
        """Of the candidates the held-out frames cannot tell apart from ``best`` (gains within twice their
        combined SEs): one the sensor's other ISOs added (a hot pixel saturated at a high ISO reads as a
        stuck one there); else the one proposed by the strongest residual (``sig``, strongest first: the
        residual that stands out most is traced first; random telegraph pixels at p 1e-32 and the dark
        tail they make at p 1e-15 propose rtn and a heavy-tailed read noise, whose gains 134 +- 2 and
        146 +- 37 nats do not tell them apart)."""
        def tied(t):
            a, b = best[0], t[0]
            return a["heldout_gain"] - b["heldout_gain"] <= 2 * np.hypot(a["heldout_gain_sd"], b["heldout_gain_sd"])

        ties = [t for t in scored if tied(t)]
        if len(ties) < 2:
            return best
        pref = [t for t in ties if t[0]["effect"] in self.preferred]
        if pref:
            if best[0]["effect"] in self.preferred:
                return best
            best = max(pref, key=lambda t: t[0]["heldout_gain"])
            best[0]["tie_broken_by"] = "added at another ISO of this sensor"
            return best
        rank = {d.name: i for i, d in enumerate(sig)}

        def first(t):
            return min(rank.get(n, len(sig)) for n in t[0]["proposed_by"])

        top = min(ties, key=lambda t: (first(t), -t[0]["heldout_gain"]))
        if top is not best:
            top[0]["tie_broken_by"] = f"proposed by the strongest residual ({sig[first(top)].name})"
        return top

    def _joint(self, tried: list, proposals: dict, tag: int, held_cur: dict, best: tuple) -> list:
        """Pairs of refuted candidates fitted jointly (module docstring, step 5): of the candidates whose
        held-out gain beats the current model's beyond its noise but which were refuted, the
        :data:`JOINT_CANDIDATES` best by gain, each pair in order of gain (the second fitted with the first
        in the model), raced as :meth:`_race` does. Only when ``best`` (the single candidate chosen) does
        not beat the current model, or a refuted one gained more than it by twice their combined SEs (a
        small gain beside a large refuted one is what is left when two effects share one residual).
        Returns ``(record, model, held-out dict)`` per pair; a pair's record is the second effect's,
        with ``joint_with`` the first's record."""
        refuted = [(rec, cand) for rec, cand, _h in tried if cand is not None and "left_race" not in rec
                   and "joint_with" not in rec
                   and (rec.get("error_grew") or rec.get("breaks"))
                   and gain_beats(rec["heldout_gain"], rec["heldout_gain_sd"])]
        refuted = sorted(refuted, key=lambda t: -t[0]["heldout_gain"])[:JOINT_CANDIDATES]
        b = best[0]
        if len(refuted) < 2 or (b["beats_current"] and refuted[0][0]["heldout_gain"] <= b["heldout_gain"] + 2 * np.hypot(
                b["heldout_gain_sd"], refuted[0][0]["heldout_gain_sd"])):
            return []
        fits = []
        for i, (ra, ca) in enumerate(refuted):
            for rb, _cb in refuted[i + 1:]:
                eb = rb["effect"]
                if eb in ca.effects or excluded_by(eb, ca.effects):
                    continue
                via = next(d for d in proposals[eb] if d.name == rb["fitted_from"])
                rec, cand = self._fit_candidate(eb, proposals[eb], ca, tag, (via, rb.get("form", "")))
                rec["joint_with"] = {k: ra[k] for k in ("effect", "form", "fitted_from", "parameters") if k in ra}
                rec["proposed_by"] = ra["proposed_by"] + [n for n in rec["proposed_by"] if n not in ra["proposed_by"]]
                if cand is not None:
                    fits.append((rec, cand))
        return self._race(fits, held_cur) if fits else []

    def removable(self, model: LoopModel, effect: str, added: dict) -> bool:
        """Whether the backward step may test ``model`` without ``effect``: the loop added it, its addition
        left the system gain and the measured dark variance as they were (deleting it undoes it), no effect
        left in the model is refitted after it (``refit_after``) or needs it first (``prerequisite``)."""
        if not added.get(effect):
            return False
        rest = model.without_effect(effect)
        return not any(effect in card_for(n).refit_after or card_for(n).prerequisite(self.g.fit_data, rest) == effect
                       for n in rest.effects)

    def _backward(self, model: LoopModel, held_cur: dict, added: dict, last: set, res: GroupResult) -> tuple:
        """The backward step (module docstring, step 6): each effect the loop added (:meth:`removable`) is
        held out of the final model in turn and the model without it scored on the held-out replicates
        against the model with it (common random numbers, as a candidate is); the one whose keeping gains
        least is taken out when that gain does not beat its sampling noise
        (:func:`attribution.gain_beats`), the held-out error does not grow without it (:func:`error_grew`)
        and it breaks no statistic (:meth:`_broken`); repeated until every effect left earns its keep.
        An effect added early can be superseded by a later one that explains the same residual better: a
        heavy-tailed read noise taken for the dark tail that random telegraph pixels make, while the
        telegraph pixels' own candidate was refuted by a dark level the model did not yet have. The effects
        of the last addition are not tested in the first round (they have just been scored against the
        model without them). Each test runs in the race's stages (:data:`RACE_STAGES` replicates, then
        all): one whose keeping gain is :data:`RACE_Z` SEs beyond :data:`attribution.MIN_GAIN` after a
        stage stops there (it stays). Returns (model, its held-out dict, whether anything was taken out); every
        test is appended to ``res.backward``."""
        R = self.cfg.heldout_replicates
        stages = race_stages(R)
        changed, skip, rnd = False, set(last), 0
        while len(model.effects) >= 2:
            trials, rnd = [], rnd + 1
            for name in model.effects:
                if name in skip or not self.removable(model, name, added):
                    continue
                rest = model.without_effect(name)
                run = HeldOut(self, rest, tuple(self.applicable), f"- {name}")
                rec = {"effect": name, "round": rnd, "parameters": model.effects[name].to_dict()}
                for n in stages:  # in the race's stages: one that clearly earns its keep stops early
                    self._score(rec, run.extend(n), held_cur)
                    clear = -rec["heldout_gain"] > MIN_GAIN + race_margin(rec["heldout_gain_sd"])
                    if clear:
                        break
                rec.pop("_beats")
                held = run.result()
                keep, sd = -rec.pop("heldout_gain"), rec.pop("heldout_gain_sd")
                rec.update({"keep_gain": keep, "keep_gain_sd": sd, "kl_structured_with": held_cur["kl_structured"],
                            "kl_structured_without": held["kl_structured"]})
                rec["moved_most"] = [{"diagnostic": m["diagnostic"], "gain": -m["gain"]} for m in rec["moved_most"]]
                if clear:
                    rec.update(removed=False, earns_keep=True)
                    trials.append((rec, rest, held, False))
                    continue
                worse, broken = error_grew(held, held_cur, self.cfg.kl_tolerance), self._broken(held, held_cur)
                if worse:
                    rec["error_grew_without"] = worse
                if broken:
                    rec["breaks_without"] = broken
                rec["removed"], rec["earns_keep"] = False, gain_beats(keep, sd)
                trials.append((rec, rest, held, not rec["earns_keep"] and not worse and not broken))
            skip = set()
            if not trials:
                break
            res.backward.extend(t[0] for t in trials)
            out = [t for t in trials if t[3]]
            if not out:
                break
            rec, model, held_cur, _ = min(out, key=lambda t: t[0]["keep_gain"])
            rec["removed"] = True
            changed = True
        return model, held_cur, changed

    def _floor_map(self) -> dict:
        return {n: self.held_floor(n) for n in self.applicable}

    def _null_map(self) -> dict:
        return {n: self.held_null(n) for n in self.applicable}

    def run(self, start: LoopModel | None = None) -> GroupResult:
        cfg = self.cfg
        base = base_fit(self.g.fit_data)
        model = start if start is not None else base
        res = GroupResult(self.iso, base, model)
        res.bootstrap_null = (f"the current model's {cfg.heldout_replicates} held-out replicates (the fit and held-out "
                              "halves share a layout: every sequence an even number of >= 4 frames)"
                              if self.g.same_layout else
                              f"{cfg.replicates} captures simulated on the fit frames' layout per model")
        tag = 0
        held_cur = self.heldout(model, tuple(self.applicable))
        discs = self.evaluate(model, tag, held_cur)
        res.base_disc = discs
        excluded: set[str] = set()  # unexplained for good
        added: dict[str, bool] = {}  # effect the loop added -> whether the backward step may take it out
        last_added: set[str] = set()  # the effects of the last addition
        unmodelled: set[str] = set()  # significant, and no effect of the vocabulary explains them
        res.heldout_base = _summary(held_cur)
        res.plots["hist_base"] = (held_cur["real_noise"], held_cur["model_noise"])

        def strength(d):
            return (-np.log10(max(d.p, 1e-300)), abs(d.z))

        def unexplained(d, reason):
            excluded.add(d.name)
            res.unexplained.append({"diagnostic": d.name, "discrepancy": d.z, "reason": reason})

        for _it in range(cfg.max_iterations):
            self.discs = discs  # the current model's battery (a prerequisite's fit reads its diagnostic)
            sig = sorted((d for d in discs if d.significant and d.name not in excluded), key=strength, reverse=True)
            if not sig:
                break
            proposals: dict[str, list] = {}  # effect -> the significant diagnostics proposing it, strongest first
            for d in sig:
                effect = effect_for(d.name)
                if effect is None:
                    unmodelled.add(d.name)
            for d in sig:
                effect = effect_for(d.name)
                outside = [b for b in dg.NULL_NEEDS.get(d.name, ()) if b in unmodelled]
                if effect is None:
                    unexplained(d, "no effect of the vocabulary explains it")
                elif outside:
                    unexplained(d, f"not attributed: {outside[0]} (significant, no effect of the vocabulary) "
                                   "inflates its spread beyond the simulated one")
                elif effect in model.effects:
                    unexplained(d, f"{effect} is already in the model and does not explain it")
                elif excluded_by(effect, model.effects):
                    unexplained(d, f"{effect} cannot sit beside {excluded_by(effect, model.effects)}, which is "
                                   "in the model")
                else:
                    proposals.setdefault(effect, []).append(d)
            if not proposals:
                continue
            tag += 1
            # a card with several forms (spatial_correlation's two kernels) gives one candidate per form its
            # proposing diagnostics point to
            fits = [self._fit_candidate(effect, ds, model, tag, via) for effect, ds in proposals.items()
                    for via in card_for(effect).variants(ds)]
            scored = self._race([f for f in fits if f[1] is not None], held_cur)
            by_rec = {id(t[0]): t for t in scored}
            tried = [by_rec.get(id(rec), (rec, None, None)) for rec, _c in fits]
            scored = [t for t in scored if "left_race" not in t[0]] or scored  # all left: none beats
            # a candidate that breaks a diagnostic the current model passes, or makes the held-out error grow,
            # is refuted: the best of the others
            scored = [t for t in scored if not t[0].get("breaks") and t[0]["kl_ok"]] or scored
            best = max(scored, key=lambda t: t[0]["heldout_gain"]) if scored else None
            if best is not None:
                best = self._break_tie(best, scored, sig)
            for rec, _c, _h in tried:
                rec["chosen"] = best is not None and rec is best[0]
            if best is None:  # no candidate could be fitted: each proposing diagnostic says why
                for rec, _c, _h in tried:
                    for d in proposals[rec["effect"]]:
                        unexplained(d, rec["skipped"])
                continue
            pairs = self._joint(tried, proposals, tag, held_cur, best)
            if pairs:
                tried = tried + pairs
                good = [t for t in pairs + [best] if t[0]["beats_current"]]
                if good:
                    for rec, _c, _h in tried:
                        rec["chosen"] = False
                    best = self._break_tie(max(good, key=lambda t: t[0]["heldout_gain"]), good, sig)
                    best[0]["chosen"] = True
            brec, cand, held = best
            effect = brec["effect"]
            accepted = brec["beats_current"]
            new_discs = self.evaluate(cand, tag, held) if accepted else None
            joint = brec.get("joint_with") if accepted else None

            def record(eff: str, fitted_from: str, parameters: dict) -> dict:
                chosen = next(d for d in discs if d.name == fitted_from)
                after = next((d for d in new_discs if d.name == chosen.name), None) if accepted else None
                hb, ha = held_cur.get(chosen.name), held.get(chosen.name)
                rec = {
                    "effect": eff, "parameters": parameters,
                    "diagnostic": chosen.name, "discrepancy_before": chosen.z,
                    "discrepancy_after": None if after is None else after.z,
                    "p_before": chosen.p, "p_after": None if after is None else after.p,
                    "heldout": {"kl_before": held_cur["kl"], "kl_after": held["kl"],
                                "kl_excess_before": held_cur["kl_excess"], "kl_excess_after": held["kl_excess"],
                                "kl_structured_before": held_cur["kl_structured"],
                                "kl_structured_after": held["kl_structured"],
                                "structured_before": held_cur["structured"],
                                "structured_after": held["structured"],
                                "nll_before": held_cur["nll"], "nll_after": held["nll"],
                                "discrepancy_before": None if hb is None else hb.z,
                                "discrepancy_after": None if ha is None else ha.z,
                                "gain": brec["heldout_gain"], "gain_sd": brec["heldout_gain_sd"]},
                    "accepted": accepted,
                    "candidates": [],
                }
                family = card_for(eff).family_of(cand.effects[eff])
                if family is not None:  # an empirical component: its residual family
                    rec["not_in_vocabulary"] = family
                return rec

            # a pair fitted jointly (Loop._joint) adds both effects: one record each, the first listing the candidates
            recs = ([dict(record(joint["effect"], joint["fitted_from"], cand.effects[joint["effect"]].to_dict()),
                          joint_with=effect)] if joint else [])
            recs.append(record(effect, brec["fitted_from"], brec["parameters"]))
            if joint:
                recs[-1]["joint_with"] = joint["effect"]
                why = (f"{effect} is fitted beside {joint['effect']}, which the model lacked" if joint.get("prerequisite")
                       else "each alone was refuted on the held-out frames")
                for r in recs:
                    r["joint_why"] = why
            recs[0]["candidates"] = [t[0] for t in tried]
            gone = [n for n in model.effects if n not in cand.effects]
            if gone:  # refitted to the identity beside the new effect (simcam.calibration.fit.fit_effect)
                recs[-1]["removed"] = {n: f"refitted to zero magnitude with {effect} in the model" for n in gone}
            res.plots.setdefault("hists", []).append(
                (" + ".join(r["effect"] for r in recs), held_cur["real_noise"], held_cur["model_noise"],
                 held["model_noise"]))
            res.iterations.extend(recs)
            if accepted:
                # effects whose addition left the system gain and the measured dark variance as they were can
                # be taken out again by deleting them (the backward step); the others re-measured those
                same = cand.K == model.K and cand.var_dark_dn2 == model.var_dark_dn2
                for n in cand.effects:
                    if n not in model.effects:
                        added[n] = same
                last_added = {n for n in cand.effects if n not in model.effects}
                model, discs, held_cur = cand, new_discs, held
                continue
            # no candidate beats the current model: every proposing diagnostic stays unexplained
            listed = "; ".join(
                f"{candidate_label(r)}: {r['skipped']}" if "skipped" in r else
                f"{candidate_label(r)}: held-out gain {r['heldout_gain']:.3g} ± {r['heldout_gain_sd']:.2g} nats"
                + (f", held-out error grew ({r['error_grew']})" if r.get("error_grew") else "")
                + "".join(f", breaks {b['diagnostic']} (held-out z {b['z_before']:.2g} -> {b['z']:.2g})"
                          for b in r.get("breaks", ()))
                + (f" (left the race: {r['left_race']})" if "left_race" in r else "")
                for r, _c, _h in tried)
            for ds in proposals.values():
                for d in ds:
                    unexplained(d, f"no candidate beat the current model on held-out frames ({listed})")
        if added:
            model, held_cur, changed = self._backward(model, held_cur, added, last_added, res)
            if changed:
                discs = self.evaluate(model, tag + 1, held_cur)
        res.model = model
        res.final = discs
        res.heldout_final = _summary(held_cur)
        listed = {u["diagnostic"] for u in res.unexplained}
        taken = {b["effect"]: b for b in res.backward if b["removed"]}
        for d in discs:
            b = taken.get(effect_for(d.name))
            if d.significant and b is not None:  # its effect was added, then taken out
                unexplained(d, f"{b['effect']} was taken out by the backward step: keeping it beside the others "
                               f"gained {b['keep_gain']:.3g} ± {b['keep_gain_sd']:.2g} nats on held-out frames")
            elif d.significant and d.name not in listed:
                res.unexplained.append({"diagnostic": d.name, "discrepancy": d.z,
                                        "reason": "still significant when the loop stopped"})
        # keep only those still significant under the final model
        final_sig = {d.name: d for d in discs if d.significant}
        last = {u["diagnostic"]: u for u in res.unexplained}  # latest reason per diagnostic
        res.unexplained = [dict(u, discrepancy=final_sig[name].z) for name, u in last.items() if name in final_sig]
        res.not_applicable = {k: self.not_applicable[k] for k in dg.DIAGNOSTICS if k in self.not_applicable}
        return res


def run_loop(capture: CaptureSet, cfg: LoopConfig | None = None,
             start_models: dict | None = None) -> list[GroupResult]:
    """Run the loop on every ISO group of ``capture``."""
    cfg = cfg or LoopConfig()
    out = []
    for iso in capture.isos():
        notes: list[str] = []
        group = Group(capture.group(iso), cfg, notes)
        start = (start_models or {}).get(iso)
        if start_models and start is None:
            notes.append(f"start profile has no entry for ISO {iso}: started from the base fit")
        if start is not None and (start.cfa != group.cfa or abs(start.white_dn - group.white) > 0.5):
            from ..errors import ProfileError

            raise ProfileError(f"--start-profile: ISO {iso}: cfa {start.cfa!r} / white level {start.white_dn:g} DN "
                               f"do not match the capture set ({group.cfa!r} / {group.white:g} DN)")
        res = Loop(group, cfg, iso, preferred={e for r in out for e in r.model.effects}).run(start)
        res.notes = [n for n in capture.notes if n.startswith(f"ISO {iso}:") or not n.startswith("ISO ")] + notes
        res.plots["group"] = group
        out.append(res)
    return out
