"""The calibration loop: base fit, residual battery, attribution, refit, held-out before/after.

Per ISO group of a capture set:

1. Frames of each sequence are split in time: the first half fits, the second
   half is held out (sequences of < 4 frames only fit).
2. Base fit (:func:`simcam.calibration.effects.base_fit`).
3. Every diagnostic of :mod:`simcam.calibration.diagnostics` is computed on the
   fit frames and on ``replicates`` captures simulated from the current model
   (parametric bootstrap, same shapes and frame counts); standardised
   discrepancies get Student-t p-values; significance by Holm's step-down
   procedure at family-wise ``alpha`` (default 0.01) over the applicable
   diagnostics.
4. The most significant diagnostic (with the precedence rules of
   ``diagnostics.PRECEDENCE``) names an effect; its parameters are fitted; the
   candidate model is simulated again. On held-out frames: the pixel marginal
   KL (Noise Flow binning, Jeffreys-smoothed model histogram) with its
   sampling floor and excess, the structured marginal KL of aggregated noise
   (:mod:`simcam.calibration.heldout`), NLL/dim of the model's Gaussian marginal
   where it has one, and the diagnostic's own standardised discrepancy,
   before and after. The structured KL is reported, not used in decisions.
5. The effect is kept if the held-out discrepancy of its diagnostic shrinks and
   the held-out KL does not grow (beyond ``kl_tolerance`` relative plus twice
   the KL's sampling floor, :func:`kl_sampling_floor`); otherwise the
   diagnostic is left out of the choice until another effect is accepted (an
   effect can hurt the marginal while a bigger one is still missing), and is
   reported ``unexplained`` if it is still significant at the end. A
   significant diagnostic that names no effect, or whose effect is already in
   the model, is ``unexplained`` too. The loop stops when nothing significant
   is left (or after ``max_iterations``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import DatasetError
from . import diagnostics as dg
from .capture import CaptureSet, Sequence
from .effects import base_fit, ctx_like, fit_effect
from .heldout import KL_BINNING, KL_EDGES, STRUCTURED_BINNING, kl_sampling_floor, marginal_kl, structured_kl  # noqa: F401
from .model import LoopModel, SimSpec, marginal_variance, site_map
from .simulate import simulate_capture

@dataclass
class LoopConfig:
    replicates: int = 16
    heldout_replicates: int = 8
    alpha: float = 0.01
    max_iterations: int = 10
    seed: int = 0
    max_size: int = 128  # centre crop (pixels per side) used by the loop
    kl_tolerance: float = 0.10  # relative growth of held-out KL still accepted (plus twice its sampling floor)


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


def _crop(frames: np.ndarray, size: int) -> np.ndarray:
    h, w = frames.shape[-2:]
    ch, cw = min(h, size), min(w, size)
    ch, cw = ch - ch % 2, cw - cw % 2
    y0 = ((h - ch) // 2) // 2 * 2
    x0 = ((w - cw) // 2) // 2 * 2
    return frames[..., y0:y0 + ch, x0:x0 + cw]


class Group:
    """Fit / held-out views of one ISO group of a capture set."""

    def __init__(self, seqs: list[Sequence], cfg: LoopConfig, notes: list):
        self.seqs = []
        for s in seqs:
            if s.kind == "flat" and s.saturated_fraction() > 0.01:
                notes.append(f"{s.name}: saturated flat ({100 * s.saturated_fraction():.0f}% at white) left out of the loop")
                continue
            self.seqs.append(s)
        if not self.seqs:
            raise DatasetError(f"ISO {seqs[0].iso}: no usable sequence left (all saturated)")
        r0 = self.seqs[0]
        self.cfa, self.white = r0.cfa, r0.white_dn
        self.black = r0.black_dn
        self.fit, self.held = [], []
        for s in self.seqs:
            f = _crop(s.frames, cfg.max_size)
            clean = None if s.clean is None else _crop(s.clean, cfg.max_size)
            if s.n >= 4:
                k = (s.n + 1) // 2
                self.fit.append((s, f[:k], clean))
                self.held.append((s, f[k:], clean))
            else:
                self.fit.append((s, f, clean))
        if not self.held:
            notes.append("no sequence has >= 4 frames: held-out errors are computed on the fit frames")
            self.held = list(self.fit)
        self.fit_data = self._data(self.fit)
        self.held_data = self._data(self.held)

    def _data(self, part) -> dg.CaptureData:
        darks = [f for s, f, _ in part if s.kind == "dark"]
        flats = [f for s, f, _ in part if s.kind == "flat"]
        scenes = [(f, c) for s, f, c in part if s.kind == "scene"]
        return dg.CaptureData(darks, flats, scenes, self.black, self.white, self.cfa)

    def specs(self, model: LoopModel, part) -> list[SimSpec]:
        out = []
        offs = np.asarray(model.effects.get("black_level_offset", {}).get("offset_dn", [0.0] * 4))
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
            out.append(SimSpec(s.kind, f.shape[0], sig, fixed_in_clean=(s.kind == "scene" and clean is None)))
        return out


def _capture(group: Group, part, sims, specs) -> dg.CaptureData:
    return ctx_like(group.fit_data if part is group.fit else group.held_data, sims, specs)


def noise_frames(part, frames_list, specs, model: LoopModel) -> list[np.ndarray]:
    """Signed noise on normalised raw, per sequence (n, H, W): frame minus the sequence's clean level
    under the model (black + black offset + signal of its :class:`SimSpec`), the same reference for data
    and simulations (so discrete ADC codes fall on the same lattice in both)."""
    fs = model.full_scale_dn
    offs = np.asarray(model.effects.get("black_level_offset", {}).get("offset_dn", [0.0] * 4))
    out = []
    for fr, sp in zip(frames_list, specs):
        ref = sp.signal_dn + site_map(model.black_dn.ravel() + offs, sp.signal_dn.shape)
        out.append((fr.astype(np.float64) - ref) / fs)
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
        tot += float(np.sum(0.5 * np.log(2 * np.pi * vn) + x * x / (2 * vn)))
        n += x.size
    return tot / n


HELDOUT_KEYS = ("kl", "nll", "kl_floor", "kl_excess", "kl_structured", "structured")


def _summary(held: dict) -> dict:
    """The held-out numbers kept in a :class:`GroupResult` (no sample arrays)."""
    return {k: held[k] for k in HELDOUT_KEYS}


def _null_parameters(effect: str, p: dict) -> bool:
    """True when the fitted effect is the identity (nothing to add)."""
    keys = {"row_noise": "sigma_dn", "column_fpn": "sigma_dn", "dsnu": "sigma_dn", "prnu": "sigma",
            "frame_flicker": "sigma", "periodic_pattern": "amplitude_dn", "spatial_correlation": "a",
            "nonlinearity": "c", "hot_pixels": "fraction"}
    if effect in keys:
        return abs(float(p[keys[effect]])) < 1e-9
    if effect == "quantization":
        return float(p["step_dn"]) <= 1.0
    if effect == "black_level_offset":
        return max(abs(float(x)) for x in p["offset_dn"]) < 1e-9
    if effect == "channel_gain":
        return max(abs(float(g) - 1) for g in p["gains"]) < 1e-9
    return False


class Loop:
    """Runs the loop on one ISO group."""

    def __init__(self, group: Group, cfg: LoopConfig, iso: int):
        self.g, self.cfg, self.iso = group, cfg, iso
        self.data_stats = dg.compute_all(group.fit_data)
        self.held_stats = dg.compute_all(group.held_data)
        self.applicable = [k for k, v in self.data_stats.items() if v is not None]
        self._eval_counter = 0

    def _rng(self, *tag):
        return np.random.default_rng([self.cfg.seed, self.iso, *tag])

    def evaluate(self, model: LoopModel, tag: int) -> tuple[list, list]:
        """Discrepancies on the fit frames (Holm-marked) and the simulated statistics."""
        specs = self.g.specs(model, self.g.fit)
        sim_stats = []
        for r in range(self.cfg.replicates):
            sims = simulate_capture(model, specs, self._rng(1, tag, r))
            sim_stats.append(dg.compute_all(_capture(self.g, self.g.fit, sims, specs), self.applicable))
        discs = []
        for name in self.applicable:
            vals = [s[name] for s in sim_stats]
            discs.append(dg.discrepancy(name, self.data_stats[name], vals, dg.resolution(name, self.g.fit_data)))
        return dg.holm(discs, self.cfg.alpha), sim_stats

    def heldout(self, model: LoopModel, tag: int, diagnostics=()) -> dict:
        specs = self.g.specs(model, self.g.held)
        real_f = noise_frames(self.g.held, [f for _, f, _ in self.g.held], specs, model)
        real = np.concatenate([x.ravel() for x in real_f])
        sim_noise, sim_frames, sim_stats = [], [], []
        for r in range(self.cfg.heldout_replicates):
            sims = simulate_capture(model, specs, self._rng(2, tag, r))
            nf = noise_frames(self.g.held, sims, specs, model)
            sim_frames.append(nf)
            sim_noise.append(np.concatenate([x.ravel() for x in nf]))
            if diagnostics:
                sim_stats.append(dg.compute_all(_capture(self.g, self.g.held, sims, specs), diagnostics))
        model_noise = np.concatenate(sim_noise)
        kl = marginal_kl(real, model_noise)
        floor = kl_sampling_floor(real, model_noise)
        st = structured_kl(real_f, [sp.fixed_in_clean for sp in specs], sim_frames)
        out = {"kl": kl, "nll": nll_per_dim(self.g.held, specs, model), "kl_floor": floor,
               "kl_excess": max(kl - floor, 0.0), "kl_structured": st["kl"], "structured": st["families"],
               "real_noise": real, "model_noise": model_noise[: real.size * 2]}
        for name in diagnostics:
            vals = [s[name] for s in sim_stats]
            if self.held_stats.get(name) is None or any(v is None for v in vals):
                continue
            out[name] = dg.discrepancy(name, self.held_stats[name], vals, dg.resolution(name, self.g.held_data))
        return out

    def run(self, start: LoopModel | None = None) -> GroupResult:
        cfg = self.cfg
        base = base_fit(self.g.fit_data)
        model = start if start is not None else base
        res = GroupResult(self.iso, base, model)
        tag = 0
        discs, sims = self.evaluate(model, tag)
        res.base_disc = discs
        excluded: set[str] = set()  # unexplained for good
        rejected: set[str] = set()  # effect did not help; retried once the model changes
        unmodelled: set[str] = set()  # significant, and no effect of the vocabulary explains them
        held_before = self.heldout(model, tag, tuple(self.applicable))
        res.heldout_base = _summary(held_before)
        res.plots["hist_base"] = (held_before["real_noise"], held_before["model_noise"])
        for _it in range(cfg.max_iterations):
            sig = [d for d in discs if d.significant and d.name not in excluded | rejected]
            if not sig:
                break
            chosen = max(sig, key=lambda d: (-np.log10(max(d.p, 1e-300)), abs(d.z)))
            sig_names = {d.name for d in sig}
            for pre in dg.PRECEDENCE.get(chosen.name, ()):
                if pre in sig_names:
                    chosen = next(d for d in sig if d.name == pre)
                    break
            effect = dg.DIAGNOSTIC_EFFECT[chosen.name]
            outside = [b for b in dg.NULL_NEEDS.get(chosen.name, ()) if b in unmodelled]
            if outside:
                excluded.add(chosen.name)
                res.unexplained.append({"diagnostic": chosen.name, "discrepancy": chosen.z,
                                        "reason": f"not attributed: {outside[0]} (significant, no effect of the "
                                                  "vocabulary) inflates its spread beyond the simulated one"})
                continue
            if effect is None or effect in model.effects:
                if effect is None:
                    unmodelled.add(chosen.name)
                excluded.add(chosen.name)
                why = "no effect of the vocabulary explains it" if effect is None else \
                    f"{effect} is already in the model and does not explain it"
                res.unexplained.append({"diagnostic": chosen.name, "discrepancy": chosen.z, "reason": why})
                continue
            tag += 1
            ctx = {"value": chosen.value, "sim_mean": chosen.sim_mean, "seed": cfg.seed * 1000 + tag,
                   "dark_specs": [sp for sp in self.g.specs(model, self.g.fit) if sp.kind == "dark"]}
            if effect in ("heavy_tail_read", "spatial_correlation") and not ctx["dark_specs"]:
                excluded.add(chosen.name)
                res.unexplained.append({"diagnostic": chosen.name, "discrepancy": chosen.z,
                                        "reason": "needs a dark sequence to fit"})
                continue
            cand = fit_effect(effect, chosen.name, self.g.fit_data, model, ctx)
            new_discs, new_sims = self.evaluate(cand, tag)
            after = next(d for d in new_discs if d.name == chosen.name)
            held_after = self.heldout(cand, tag, (chosen.name,))
            hb = held_before.get(chosen.name)
            ha = held_after.get(chosen.name)
            diag_better = (hb is None or ha is None) or abs(ha.z) < abs(hb.z)
            kl_ok = held_after["kl"] <= held_before["kl"] * (1 + cfg.kl_tolerance) + 2 * held_before["kl_floor"]
            null_fit = _null_parameters(effect, cand.effects[effect])
            accepted = bool(diag_better and kl_ok and not null_fit)
            rec = {
                "effect": effect, "parameters": {k: v for k, v in cand.effects[effect].items()},
                "diagnostic": chosen.name, "discrepancy_before": chosen.z, "discrepancy_after": after.z,
                "p_before": chosen.p, "p_after": after.p,
                "heldout": {"kl_before": held_before["kl"], "kl_after": held_after["kl"],
                            "kl_excess_before": held_before["kl_excess"], "kl_excess_after": held_after["kl_excess"],
                            "kl_structured_before": held_before["kl_structured"],
                            "kl_structured_after": held_after["kl_structured"],
                            "structured_before": held_before["structured"],
                            "structured_after": held_after["structured"],
                            "nll_before": held_before["nll"], "nll_after": held_after["nll"],
                            "discrepancy_before": None if hb is None else hb.z,
                            "discrepancy_after": None if ha is None else ha.z},
                "accepted": accepted,
            }
            res.plots.setdefault("hists", []).append(
                (effect, held_before["real_noise"], held_before["model_noise"], held_after["model_noise"]))
            res.iterations.append(rec)
            if accepted:
                model, discs, sims = cand, new_discs, new_sims
                held_before = self.heldout(model, tag, tuple(self.applicable))
                rejected.clear()
            else:
                rejected.add(chosen.name)
                why = (f"the fitted {effect} has zero magnitude" if null_fit else
                       f"adding {effect} did not reduce the held-out error")
                res.unexplained.append({"diagnostic": chosen.name, "discrepancy": chosen.z, "reason": why})
        res.model = model
        res.final = discs
        res.heldout_final = _summary(held_before)
        listed = {u["diagnostic"] for u in res.unexplained}
        for d in discs:
            if d.significant and d.name not in listed:
                res.unexplained.append({"diagnostic": d.name, "discrepancy": d.z,
                                        "reason": "still significant when the loop stopped"})
        # keep only those still significant under the final model
        final_sig = {d.name: d for d in discs if d.significant}
        last = {u["diagnostic"]: u for u in res.unexplained}  # latest reason per diagnostic
        res.unexplained = [dict(u, discrepancy=final_sig[name].z) for name, u in last.items() if name in final_sig]
        res.plots["final_sims"] = sims
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
        res = Loop(group, cfg, iso).run(start)
        res.notes = [n for n in capture.notes if n.startswith(f"ISO {iso}:") or not n.startswith("ISO ")] + notes
        res.plots["group"] = group
        out.append(res)
    return out
