"""Outputs of ``simcam loop``: profile.yaml (noise-stage profile), loop_model.yaml (the loop's own
model in DN), report.json and report.html (plots as base64 PNGs).

The JSON schema is documented in the README ("Calibration loop report").
"""

from __future__ import annotations

import base64
import html
import io
import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..errors import ProfileError
from ..parallel import map_threads
from . import diagnostics as dg
from .effects import DIAGNOSTIC_EFFECT, card_for
from .effects.card import format_number as _num
from .heldout import FAMILIES, GATE_Z, KL_BINNING, KL_EDGES, STRUCTURED_BINNING
from .loop import GroupResult, LoopConfig, loop_threads
from .model import LoopModel
from .simulate import simulate_capture

STRUCTURED_KL = (f"sum over the families {', '.join(FAMILIES)} of the held-out noise (per sequence and CFA plane) of "
                 f"their KL minus its sampling floor, counted where it exceeds {GATE_Z:g} sampling SDs; binning: "
                 f"{STRUCTURED_BINNING}")

REPORT_SCHEMA = "simcam-loop-report/1"
PROFILE_SCHEMA = 1


def iso_label(iso: int) -> str:
    """The ISO as the data give it: "ISO 800", or "ISO not given" (EMVA 1288 descriptors, raw arrays
    without the tag; stored as 0)."""
    return f"ISO {int(iso)}" if iso and iso > 0 else "ISO not given"


def _disc_dict(d: dg.Discrepancy) -> dict:
    return {"name": d.name, "effect": DIAGNOSTIC_EFFECT[d.name], "value": d.value, "sim_mean": d.sim_mean,
            "sim_sd": d.sim_sd, "discrepancy": d.z, "p": d.p, "significant": bool(d.significant)}


def _clean(v):
    if isinstance(v, Mapping):
        return {str(k): _clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v]
    if isinstance(v, np.ndarray):
        return _clean(v.tolist())
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if np.isfinite(f) else None
    if isinstance(v, (np.integer,)):
        return int(v)
    return v


def _plane_ptc(r: GroupResult) -> dict | None:
    from .photon_transfer import plane_ptc

    darks, flats = r.plots["group"].fit_data.ptc_points()
    return plane_ptc(darks, flats, r.base.full_scale_dn)


#: diagnostics of the battery that probe each structured-KL family
FAMILY_DIAGNOSTICS = {
    "pixel": ("dsnu_excess", "hot_pixel_tail", "dark_tail_mass", "dark_ppcc_lambda", "code_occupancy", "prnu_excess",
              "flat_spread_growth", "ptc_curvature", "plane_gain_spread", "black_offset"),
    "row": ("row_mean_excess", "row_spectrum_peak", "row_mean_lag1"),
    "column": ("col_temporal_excess", "col_fpn_excess", "col_fpn_spectrum_peak", "flat_col_spectrum_peak",
               "col_spectrum_peak"),
    "temporal": ("dsnu_excess", "prnu_excess", "flat_spread_growth", "hot_pixel_tail", "col_fpn_excess",
                 "col_fpn_spectrum_peak", "flat_col_spectrum_peak"),
    "block": ("lag1_corr", "lag2_corr", "dark_checker_jitter", "frame_spectrum_peak"),
    "frame": ("frame_mean_jitter", "frame_mean_drift", "dark_frame_jitter", "dark_checker_jitter"),
}


def remaining_families(r: GroupResult) -> list[dict]:
    """Structured-KL families still significant under the final model, each with its reason: the
    unexplained diagnostics that probe it (and why they are unexplained), or that none of the battery's
    diagnostics is significant for it (a shape outside what the battery tests)."""
    out = []
    unexpl = {u["diagnostic"]: u["reason"] for u in r.unexplained}
    for fam, f in (r.heldout_final.get("structured") or {}).items():
        if not f["significant"]:
            continue
        hits = [f"{d} ({unexpl[d]})" for d in FAMILY_DIAGNOSTICS.get(fam, ()) if d in unexpl]
        reason = ("unexplained: " + "; ".join(hits)) if hits else (
            "no diagnostic of the battery probing this family is significant: the discrepancy has a shape "
            "the battery does not test")
        out.append({"family": fam, "excess": f["excess"], "z": f["z"], "reason": reason})
    return out


def build_report(results: list[GroupResult], capture, cfg: LoopConfig, emva: dict[int, dict | None],
                 dark: dict[int, dict] | None = None, emva1288_r4: dict[int, dict] | None = None) -> dict:
    """The report.json document (see docs/loop.md for the schema).

    ``dark``: dark current per ISO (:func:`simcam.calibration.dark_current.dark_current`);
    ``emva1288_r4``: EMVA 1288 Release 4.0 results per ISO, written under each ISO's ``"emva1288"``
    key as given (the full R4.0 evaluation is computed outside the loop).
    """
    isos = []
    for r in results:
        isos.append({
            "iso": int(r.iso),
            "iso_label": iso_label(r.iso),
            "analysed": r.plots["group"].region,
            "bootstrap_null": r.bootstrap_null,
            "iterations": [{k: v for k, v in it.items()} for it in r.iterations],
            "backward": [dict(b) for b in r.backward],
            "effects": list(r.model.effects),
            "unexplained": [{"diagnostic": u["diagnostic"], "discrepancy": u["discrepancy"], "reason": u["reason"]}
                            for u in r.unexplained],
            "photon_transfer": _plane_ptc(r),
            "base_model": r.base.to_dict(),
            "model": r.model.to_dict(),
            "diagnostics_base": [_disc_dict(d) for d in r.base_disc],
            "diagnostics_final": [_disc_dict(d) for d in r.final],
            "not_applicable": [{"diagnostic": k, "reason": v} for k, v in r.not_applicable.items()],
            "remaining_families": remaining_families(r),
            "heldout": {"kl_base": r.heldout_base["kl"], "kl_final": r.heldout_final["kl"],
                        "kl_sampling_floor": r.heldout_final["kl_floor"],
                        "kl_excess_base": r.heldout_base["kl_excess"], "kl_excess_final": r.heldout_final["kl_excess"],
                        "kl_structured_base": r.heldout_base["kl_structured"],
                        "kl_structured_final": r.heldout_final["kl_structured"],
                        "structured_base": r.heldout_base["structured"],
                        "structured_final": r.heldout_final["structured"],
                        "nll_base": r.heldout_base["nll"], "nll_final": r.heldout_final["nll"]},
            "emva": emva.get(r.iso),
            "dark_current": (dark or {}).get(r.iso),
            "emva1288": (emva1288_r4 or {}).get(r.iso),
            "notes": r.notes,
        })
    top_emva = None
    for r in results:
        e = emva.get(r.iso)
        if e is not None:
            top_emva = {k: e[k] for k in ("K_dn_per_e", "sigma_dark_e", "dsnu_e", "prnu_percent")}
            break
    doc = {
        "schema": REPORT_SCHEMA,
        "capture_set": str(capture.root),
        "layout": capture.layout,
        "settings": {"replicates": cfg.replicates, "heldout_replicates": cfg.heldout_replicates,
                     "alpha": cfg.alpha, "correction": "Holm step-down over the applicable diagnostics",
                     "test": "two-sided Student t (R-1 dof) on the standardised discrepancy",
                     "max_size": cfg.max_size, "max_pixels": cfg.max_pixels, "tile": cfg.tile, "seed": cfg.seed,
                     "max_iterations": cfg.max_iterations,
                     "simulator": "simcam.noise composite (the profile.yaml entry), Composite.sample_frames"},
        "kl_binning": KL_BINNING,
        "structured_kl": STRUCTURED_KL,
        "nll_density": "per-pixel Gaussian marginal of the model about the plane mean (null when the model has "
                       "heavy-tailed read noise or hot pixels)",
        "emva": top_emva,
        "isos": isos,
        "notes": list(capture.notes),
    }
    return _clean(doc)


# ------------------------------------------------------------------ profile

def loop_model_dict(results: list[GroupResult], capture, camera_id: str | None = None) -> dict:
    """The loop's own record of its final models (DN units, exactly what it simulated; effect names
    of simcam's noise vocabulary); ``--start-profile`` reads it back losslessly.

    Base model per ISO as a Poisson-Gaussian on normalised raw (beta1 = K / (white - black),
    beta2 = read^2 / (white - black)^2, Abdelhamed, PhD dissertation, York University, 2020, eq. 3.6) plus the same in DN.
    """
    first = results[0].model
    isos = []
    for r in results:
        m = r.model
        fs = m.full_scale_dn
        isos.append({
            "iso": int(r.iso),
            "iso_label": iso_label(r.iso),
            "analysed": r.plots["group"].region,
            "model": {"type": "poisson_gaussian", "beta1": float(m.K / fs), "beta2": float(m.read_dn ** 2 / fs ** 2)},
            "K_dn_per_e": float(m.K), "read_dn": float(m.read_dn),
            "black_level": [float(x) for x in np.asarray(m.black_dn).ravel()],
            "effects": _clean({k: prm.to_dict() for k, prm in m.effects.items()}),
        })
    return {
        "schema_version": PROFILE_SCHEMA,
        "camera": camera_id or Path(capture.root).name,
        "cfa": first.cfa,
        "black_level": [float(x) for x in np.asarray(first.black_dn).ravel()],
        "white_level": float(first.white_dn),
        "provenance": {"tool": "simcam loop", "capture_set": str(capture.root)},
        "isos": isos,
    }


def write_yaml(path: Path, doc: dict) -> None:
    import yaml

    Path(path).write_text(yaml.safe_dump(_clean(doc), sort_keys=False))


def read_start_profile(path: Path) -> dict[int, LoopModel]:
    """LoopModels per ISO from ``loop_model.yaml`` or a noise-stage ``profile.yaml`` written by simcam loop."""
    from ..yamlio import load_yaml

    try:
        text = Path(path).read_text()
    except FileNotFoundError:
        raise ProfileError(f"{path}: start profile not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ProfileError(f"{path}: cannot read start profile ({exc})") from None
    doc = load_yaml(text, source=str(path), error=ProfileError)
    if isinstance(doc, dict) and "cameras" in doc:
        from .profile import models_from_noise_profile

        return models_from_noise_profile(doc, str(path))
    if not isinstance(doc, dict) or doc.get("schema_version") != PROFILE_SCHEMA or "isos" not in doc:
        raise ProfileError(f"{path}: schema_version {doc.get('schema_version') if isinstance(doc, dict) else None!r}; "
                           f"expected {PROFILE_SCHEMA} with an 'isos' list (a profile written by simcam loop)")
    out = {}
    white = float(doc["white_level"])
    for i, e in enumerate(doc["isos"]):
        try:
            black = np.asarray(e.get("black_level", doc["black_level"]), dtype=np.float64).reshape(2, 2)
            K, read = float(e["K_dn_per_e"]), float(e["read_dn"])
            effects = dict(e.get("effects") or {})
        except (KeyError, TypeError, ValueError) as exc:
            raise ProfileError(f"{path}: isos[{i}]: missing or invalid field ({exc}); expected iso, K_dn_per_e, "
                               "read_dn, black_level, effects") from None
        try:
            m = LoopModel(doc.get("cfa"), black, white, K, read, var_dark_dn2=0.0, effects=effects)
        except (KeyError, TypeError, ValueError) as exc:
            raise ProfileError(f"{path}: isos[{i}].effects: {exc.args[0] if exc.args else exc}") from None
        m.set_dark_variance_from_read()
        out[int(e["iso"])] = m
    return out


# ------------------------------------------------------------------ plots

def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _ptc_curve(model: LoopModel, y: np.ndarray, plane: int) -> np.ndarray:
    s = model.full_scale_dn
    c = model.param("nonlinearity", "c", 0.0)
    x = y if abs(c) < 1e-12 else (np.sqrt(np.maximum(1 + 4 * c * y / s, 0)) - 1) * s / (2 * c)
    v = model.K * model.gains()[plane] * x + model.var_dark_dn2
    return v * (1 + 2 * c * x / s) ** 2


def figures(r: GroupResult, seed: int = 0) -> dict[str, str]:
    """Base64 PNGs: photon transfer, spectra, temporal-mean maps, residual histograms."""
    from ..errors import require_extra

    matplotlib = require_extra("matplotlib", "plot")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    g = r.plots["group"]
    d = g.fit_data
    out = {}
    darks, flats = d.ptc_points()
    if flats:
        mu0 = np.mean([p[:, 0] for p in darks], axis=0) if darks else r.base.black_dn.ravel()
        fig, (ax, axr) = plt.subplots(2, 1, figsize=(7, 6), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
        cols = ["tab:red", "tab:green", "tab:olive", "tab:blue"] if d.cfa else ["k"] * 4
        labels = [f"site {dy}{dx}" + (f" ({d.cfa[k]})" if d.cfa else "") for k, (dy, dx) in enumerate(dg.PLANE_OFFSETS)]
        pts = np.array(darks + flats)
        ymax = float((pts[:, :, 0] - mu0).max())
        yy = np.linspace(0, ymax * 1.02, 200)
        for c in range(4 if d.cfa else 1):
            x = pts[:, c, 0] - mu0[c]
            ax.plot(x, pts[:, c, 1], "o", color=cols[c], ms=4, label=labels[c] if d.cfa else "data")
            ax.plot(yy, _ptc_curve(r.base, yy, c), "--", color=cols[c], lw=0.8)
            ax.plot(yy, _ptc_curve(r.model, yy, c), "-", color=cols[c], lw=1.2)
            axr.plot(x, pts[:, c, 1] - _ptc_curve(r.base, x, c), "x", color=cols[c], ms=4)
            axr.plot(x, pts[:, c, 1] - _ptc_curve(r.model, x, c), "o", color=cols[c], ms=3, mfc="none")
        ax.plot([], [], "k--", lw=0.8, label="base fit")
        ax.plot([], [], "k-", lw=1.2, label="final model")
        ax.set_ylabel("temporal variance (DN$^2$)")
        ax.set_title(f"{iso_label(r.iso)}: photon transfer (K = {r.base.K:.4g} → {r.model.K:.4g} DN/e$^-$)")
        ax.legend(fontsize=8)
        axr.axhline(0, color="0.5", lw=0.8)
        axr.set_xlabel("mean signal above dark (DN)")
        axr.set_ylabel("residual (DN$^2$)\nx base, o final", fontsize=8)
        fig.tight_layout()
        out["ptc"] = _png(fig)
    # spectra: data vs base vs final (mean of 4 simulated captures)
    def spectra(item):
        key, model, rep = item
        specs = g.specs(model, g.fit)
        cd = d.like(simulate_capture(model, specs, np.random.default_rng([seed, 99, rep])), specs)
        return key, {axis: dg.periodogram(cd, axis) for axis in (2, 1)}

    model_ps = {"base": {2: [], 1: []}, "final": {2: [], 1: []}}
    items = [(key, model, rep) for key, model in (("base", r.base), ("final", r.model)) for rep in range(4)]
    for key, ps in map_threads(spectra, items):  # (each capture seeded by its index: any thread count)
        for axis in (2, 1):
            model_ps[key][axis].append(ps[axis])
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    for ax, axis, title in ((axes[0], 2, "row means (vs row index)"), (axes[1], 1, "column means (vs column index)")):
        p = dg.periodogram(d, axis)
        if p is None:
            continue
        f = np.arange(p.size) / (2 * (p.size - 1))
        ax.semilogy(f[1:], p[1:], "k-", lw=1.2, label="data")
        for key, style, lab in (("base", "--", "base model"), ("final", "-", "final model")):
            ax.semilogy(f[1:], np.mean(model_ps[key][axis], axis=0)[1:], style, lw=1, label=lab)
        ax.set_xlabel("spatial frequency (cycles / pixel)")
        ax.set_ylabel("power of temporal residual (DN$^2$ · px)")
        ax.set_title(title)
        ax.legend(fontsize=8)
    fig.tight_layout()
    out["spectra"] = _png(fig)
    maps = [(n, m) for n, m in (("dark", d.dark_map()), ("flat", d.flat_map())) if m is not None]
    if maps:
        fig, axes = plt.subplots(1, len(maps), figsize=(5.2 * len(maps), 4.2), squeeze=False)
        for ax, (name, (m, _vt, n)) in zip(axes[0], maps):
            unit = "DN"
            if name != "dark":  # per-plane relative response, so the CFA colour does not dominate
                dm = d.dark_map()
                base = dm[0] if dm is not None else np.zeros_like(m)
                m = m - base
                for dy, dx in dg.PLANE_OFFSETS:
                    m[dy::2, dx::2] = 100.0 * m[dy::2, dx::2] / m[dy::2, dx::2].mean()
                unit = "% of the CFA-plane mean (dark subtracted)"
            lo, hi = np.percentile(m, [0.5, 99.5])
            im = ax.imshow(m, cmap="gray", vmin=lo, vmax=hi, interpolation="nearest")
            ax.set_title(f"temporal mean, {name} ({n} frames)")
            ax.set_xlabel("column (px)")
            ax.set_ylabel("row (px)")
            fig.colorbar(im, ax=ax, label=unit)
        fig.tight_layout()
        out["maps"] = _png(fig)
    hists = [("base fit", *r.plots["hist_base"], None)] + list(r.plots.get("hists", []))
    n = len(hists)
    ncol = min(n, 4)
    nrow = (n + ncol - 1) // ncol
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 3.6 * nrow), squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    centres = 0.5 * (KL_EDGES[1:-2] + KL_EDGES[2:-1])
    for ax, h in zip(axes.ravel(), hists):
        name, real, before, after = h
        lim = max(np.percentile(np.abs(real), 99.9) * 1.3, 1e-4)
        bins = np.linspace(-lim, lim, 81)

        def dens(x):
            return np.histogram(x, bins, density=True)[0]

        ax.stairs(dens(real), bins, fill=True, color="0.8", label="held-out data")
        ax.stairs(dens(before), bins, color="tab:blue", label="model before")
        if after is not None:
            ax.stairs(dens(after), bins, color="tab:red", label="model after")
        ax.set_yscale("log")
        ax.set_xlabel("noise (normalised raw)")
        ax.set_ylabel("density (1 / normalised raw)")
        ax.set_title(name if after is None else f"+ {name}")
        ax.legend(fontsize=7)
    del centres
    fig.tight_layout()
    out["hists"] = _png(fig)
    return out


def _fmt(v):
    if v is None:
        return "–"
    if isinstance(v, float):
        return f"{v:.4g}"
    return html.escape(str(v))


def format_parameters(effect: str, params: Mapping) -> str:
    """Parameters of ``effect`` with their units, e.g. ``sigma_dn = 2.66 DN`` (the effect's card formats them)."""
    return card_for(effect).format(params)


def _model_table(g: dict) -> str:
    """Base and final model: gain, read noise (DN and e-), black and white levels, with units."""
    rows = ["<h3>Model</h3><table><tr><th></th><th>K (DN/e⁻)</th><th>read noise (DN)</th><th>read noise (e⁻)</th>"
            "<th>black (DN)</th><th>white (DN)</th><th>effects</th></tr>"]
    for name in ("base_model", "model"):
        m = g[name]
        K = m["K_dn_per_e"]
        read_e = m["read_dn"] / K if K else None
        black = np.asarray(m["black_dn"], dtype=np.float64)
        eff = "; ".join(f"<b>{html.escape(k)}</b>: {html.escape(format_parameters(k, v))}" for k, v in m["effects"].items())
        rows.append(f"<tr><td class=l>{'base fit' if name == 'base_model' else 'final'}</td>"
                    f"<td>{_num(K, 4) if K else '– (no signal)'}</td><td>{_num(m['read_dn'], 4)}</td><td>{_num(read_e, 4)}</td>"
                    f"<td>{_num(float(black.mean()), 5)}</td><td>{_num(m['white_dn'], 5)}</td>"
                    f"<td class=l>{eff or 'none'}</td></tr>")
    rows.append("</table>")
    return "".join(rows)


def _dark_table(dc: dict | None) -> str:
    if not dc:
        return ""
    if not dc.get("applicable"):
        return f"<h3>Dark current</h3><p>Not applicable: {html.escape(dc['reason'])}.</p>"
    rows = ["<h3>Dark current (whole frames)</h3><table><tr><th>exposure (s)</th><th>frames</th>"
            "<th>dark mean (DN)</th><th>dark temporal variance (DN²)</th></tr>"]
    pts = list(zip(dc["exposure_s"], dc["frames"], dc["mean_dn"], dc["temporal_var_dn2"]))
    shown = pts if len(pts) <= 8 else pts[:3] + [None] + pts[-3:]
    for pt in shown:
        if pt is None:
            rows.append(f"<tr><td colspan=4 class=l>… {len(pts) - 6} more exposure times …</td></tr>")
            continue
        t, n, m, v = pt
        rows.append(f"<tr><td>{_num(t, 4)}</td><td>{n}</td><td>{_num(m, 5)}</td><td>{_num(v, 4)}</td></tr>")
    rows.append("</table><p>")
    rows.append(f"Slopes: {_num(dc['dn_per_s'])} DN/s (mean), {_num(dc['dn2_per_s'])} DN²/s (variance). ")
    if dc["e_per_s_from_mean"] is not None:
        rows.append(f"Dark current {_num(dc['e_per_s_from_mean'])} e⁻/s from the mean, "
                    f"{_num(dc['e_per_s_from_variance'])} e⁻/s from the variance. ")
    if dc["nonuniformity_dn_per_s"] is not None:
        nu_e = dc["nonuniformity_e_per_s"]
        rows.append(f"Non-uniformity {_num(dc['nonuniformity_dn_per_s'])} DN/s"
                    + (f" ({_num(nu_e)} e⁻/s)" if nu_e is not None else "")
                    + (f", {html.escape(dc['nonuniformity_reason'])}" if dc.get("nonuniformity_reason") else "") + ".")
    rows.append("</p>")
    return "".join(rows)


def _drop(before, after) -> str:
    if not before or before <= 0 or after is None:
        return ""
    change = 100 * (1 - after / before)
    return f" ({change:.0f} % drop)" if change >= 0 else f" (grew {-change:.0f} %)"


def _family_table(h: dict) -> str:
    """Per-family structured KL, base and final model: KL, sampling floor, z of the excess."""
    rows = ["<h3>Held-out structured marginal KL per family</h3><table><tr><th>family</th><th>values</th>"
            "<th>KL base</th><th>floor</th><th>z base</th><th>KL final</th><th>floor</th><th>z final</th>"
            "<th>counted excess base</th><th>counted excess final</th></tr>"]
    fb, ff = h.get("structured_base") or {}, h.get("structured_final") or {}
    for fam in FAMILIES:
        b, f = fb.get(fam), ff.get(fam)
        if b is None or f is None:
            continue
        cls = " class=sig" if f["significant"] else ""
        rows.append(f"<tr{cls}><td class=l>{fam}</td><td>{b['n']}</td><td>{_fmt(b['kl'])}</td><td>{_fmt(b['floor'])}</td>"
                    f"<td>{b['z']:.1f}</td><td>{_fmt(f['kl'])}</td><td>{_fmt(f['floor'])}</td><td>{f['z']:.1f}</td>"
                    f"<td>{_fmt(b['excess'] if b['significant'] else 0.0)}</td>"
                    f"<td>{_fmt(f['excess'] if f['significant'] else 0.0)}</td></tr>")
    rows.append("</table>")
    return "".join(rows)


_EMVA_ROWS = (  # (key, label, digits) of the EMVA 1288 R4.0 summary table (the standard's data sheet order)
    ("system_gain", "System gain K", 4), ("inverse_system_gain", "1/K", 4),
    ("dark_noise_e", "Temporal dark noise σ_d", 4), ("dark_noise_dn", "Temporal dark noise σ_y.dark", 4),
    ("quantum_efficiency", "Quantum efficiency η", 3), ("responsivity", "Responsivity R", 4),
    ("saturation_capacity_e", "Saturation capacity μ_e.sat", 4), ("saturation_signal_dn", "Saturation signal μ_y.sat", 4),
    ("sensitivity_threshold_e", "Absolute sensitivity threshold μ_e.min", 4),
    ("snr_max", "SNR max", 4), ("snr_max_db", "SNR max", 3), ("dynamic_range", "Dynamic range", 4),
    ("dynamic_range_db", "Dynamic range", 3), ("linearity_error_min", "Linearity error LE min", 3),
    ("linearity_error_max", "Linearity error LE max", 3),
    ("dark_current_mean_e_s", "Dark current (mean method)", 4), ("dark_current_var_e_s", "Dark current (variance method)", 4),
)
_EMVA_SPLIT = (("dsnu_e", "DSNU"), ("prnu_percent", "PRNU"))


def _emva_value(v) -> str:
    if not isinstance(v, dict):
        return "–"
    if v.get("value") is None:
        return f"n/a ({html.escape(str(v.get('reason', 'not measurable')))})"
    return f"{_num(v['value'], 4)} {html.escape(v.get('unit', ''))}"


def emva1288_r4_html(e: dict | None) -> str:
    """The EMVA 1288 R4.0 data-sheet table of one ISO (channels as columns), DSNU / PRNU split into
    total, row, column and pixel parts (EMVA 1288 R4.0, sec. 8), with the reason where a figure is not
    measurable on the data."""
    if not e:
        return ""
    if "not_applicable" in e:
        return f"<p>EMVA 1288 R4.0: not applicable ({html.escape(e['not_applicable'])}).</p>"
    chans = e["channels"]
    names = list(chans)
    head = "".join(f"<th>{html.escape(n)}</th>" for n in names)
    rows = [f"<h3>{html.escape(e.get('standard', 'EMVA 1288'))}</h3><table><tr><th>quantity</th>{head}</tr>"]
    for key, label, _ in _EMVA_ROWS:
        if any(key in chans[n] for n in names):
            rows.append(f"<tr><td class=l>{label}</td>" + "".join(
                f"<td>{_emva_value(chans[n].get(key))}</td>" for n in names) + "</tr>")
    for key, label in _EMVA_SPLIT:
        for part in ("total", "row", "column", "pixel"):
            if any(isinstance(chans[n].get(key), dict) and part in chans[n][key] for n in names):
                rows.append(f"<tr><td class=l>{label} {part}</td>" + "".join(
                    f"<td>{_emva_value((chans[n].get(key) or {}).get(part))}</td>" for n in names) + "</tr>")
    rows.append("</table>")
    notes = sorted({note for n in names for note in chans[n].get("notes", [])})
    rows += [f"<p><i>{html.escape(n)}</i></p>" for n in notes]
    return "".join(rows)


def emva1288_r4_figure(e: dict | None) -> str | None:
    """One base64 PNG of an ISO's EMVA 1288 R4.0 results: photon transfer (variance vs mean, with the
    fit range), the horizontal and vertical DSNU / PRNU spectrograms, and the logarithmic accumulated
    histograms of DSNU / PRNU (EMVA 1288 R4.0, sec. 8.2-8.3), one line per channel."""
    if not e or "channels" not in e:
        return None
    from ..errors import require_extra

    require_extra("matplotlib", "plot")
    import matplotlib.pyplot as plt

    chans = e["channels"]
    fig, ax = plt.subplots(2, 3, figsize=(13, 6.6))
    for name, c in chans.items():
        pt = c.get("photon_transfer") or {}
        if pt.get("mean_dn"):
            m = np.asarray(pt["mean_dn"]) - np.asarray(pt["dark_mean_dn"])
            v = np.asarray(pt["var_dn2"]) - np.asarray(pt["dark_var_dn2"])
            ax[0, 0].plot(m, v, ".", ms=4, label=name)
            i0, i1 = pt.get("fit_indices") or (0, len(m) - 1)
            K = (c.get("system_gain") or {}).get("value")
            if K:
                xs = np.array([0.0, m[i1]])
                ax[0, 0].plot(xs, K * xs, "-", lw=1)
        for j, key in enumerate(("dsnu_horizontal", "prnu_horizontal")):
            sp = (c.get("spectrograms") or {}).get(key)
            if sp:
                ax[0, 1 + j].semilogy(sp["frequency"][1:], np.maximum(sp["amplitude"][1:], 1e-6), lw=0.7, label=name)
                ax[0, 1 + j].set_ylabel(f"amplitude ({sp['unit']})", fontsize=8)
        for j, key in enumerate(("dsnu_vertical", "prnu_vertical")):
            sp = (c.get("spectrograms") or {}).get(key)
            if sp:
                ax[1, j].semilogy(sp["frequency"][1:], np.maximum(sp["amplitude"][1:], 1e-6), lw=0.7, label=name)
                ax[1, j].set_ylabel(f"amplitude ({sp['unit']})", fontsize=8)
        for key, style in (("dsnu", "-"), ("prnu", "--")):
            h = (c.get("histograms") or {}).get(key)
            if h and h.get("accumulated_percent"):
                ax[1, 2].semilogy(h["abs_edges"][:len(h["accumulated_percent"])],
                                  np.maximum(h["accumulated_percent"], 1e-4), style, lw=1,
                                  label=f"{name} {key.upper()} ({h['unit']})")
    titles = [["Photon transfer: σ²_y − σ²_y.dark vs μ_y − μ_y.dark (DN)", "DSNU spectrogram, horizontal",
               "PRNU spectrogram, horizontal"],
              ["DSNU spectrogram, vertical", "PRNU spectrogram, vertical", "Accumulated histograms |deviation|"]]
    for r in range(2):
        for k in range(3):
            ax[r, k].set_title(titles[r][k], fontsize=9)
            ax[r, k].tick_params(labelsize=7)
            if ax[r, k].lines:
                ax[r, k].legend(fontsize=6)
    for a in (ax[0, 1], ax[0, 2], ax[1, 0], ax[1, 1]):
        a.set_xlabel("cycles / pixel", fontsize=8)
    ax[1, 2].set_ylabel("% of pixels", fontsize=8)
    fig.tight_layout()
    return _png(fig)


def write_html(path: Path, doc: dict, figs: dict[int, dict]) -> None:
    parts = ["<!doctype html><html><head><meta charset='utf-8'><title>simcam loop report</title>",
             "<style>body{font-family:sans-serif;margin:2em;max-width:1200px} table{border-collapse:collapse;"
             "font-size:13px;display:block;overflow-x:auto;max-width:100%} "
             "td,th{border:1px solid #bbb;padding:3px 6px;text-align:right} th{background:#eee}"
             " td.l{text-align:left} .sig{background:#fdd}</style></head><body>",
             f"<h1>simcam loop report</h1><p>Capture set <code>{html.escape(doc['capture_set'])}</code> "
             f"({doc['layout']}). Significance: {doc['settings']['correction']} at alpha = {doc['settings']['alpha']}"
             f", bootstrap null: the model's {doc['settings']['heldout_replicates']} held-out replicates where the fit and "
             f"held-out halves share a layout, else {doc['settings']['replicates']} captures simulated on the fit frames. "
             f"Pixel marginal KL: {html.escape(doc['kl_binning'])}. "
             f"Structured marginal KL: {html.escape(doc['structured_kl'])}.</p>"]
    for note in doc["notes"]:
        parts.append(f"<p><b>Note:</b> {html.escape(note)}</p>")
    if doc.get("emva"):
        e = doc["emva"]
        parts.append("<h2>EMVA 1288</h2><table><tr><th>K (DN/e⁻)</th><th>σ_d (e⁻)</th><th>DSNU1288 (e⁻)</th>"
                     f"<th>PRNU1288 (%)</th></tr><tr><td>{_fmt(e['K_dn_per_e'])}</td><td>{_fmt(e['sigma_dark_e'])}</td>"
                     f"<td>{_fmt(e['dsnu_e'])}</td><td>{_fmt(e['prnu_percent'])}</td></tr></table>")
    for g in doc["isos"]:
        iso = g["iso"]
        parts.append(f"<h2>{g['iso_label']}</h2><p>Effects added: <b>{', '.join(g['effects']) or 'none'}</b>. "
                     f"Held-out pixel marginal KL {_fmt(g['heldout']['kl_base'])} (base) → {_fmt(g['heldout']['kl_final'])} "
                     f"(final; sampling floor {_fmt(g['heldout']['kl_sampling_floor'])}, excess "
                     f"{_fmt(g['heldout']['kl_excess_base'])} → {_fmt(g['heldout']['kl_excess_final'])}); structured "
                     f"marginal KL {_fmt(g['heldout']['kl_structured_base'])} → {_fmt(g['heldout']['kl_structured_final'])}"
                     f"{_drop(g['heldout']['kl_structured_base'], g['heldout']['kl_structured_final'])}; "
                     f"NLL/dim {_fmt(g['heldout']['nll_base'])} → {_fmt(g['heldout']['nll_final'])} nats.</p>")
        a = g.get("analysed")
        if a:
            parts.append(f"<p>Pixels analysed by the residual battery and the bootstrap: {a['pixels_analysed']:,} of "
                         f"{a['frame'][0]} × {a['frame'][1]} ({100 * a['fraction']:.3g} %), {html.escape(a['layout'])}. "
                         "EMVA 1288 numbers and the dark current use every pixel of every frame.</p>")
        if g.get("bootstrap_null"):
            parts.append(f"<p>Bootstrap null of the residual battery: {html.escape(g['bootstrap_null'])}.</p>")
        parts.append(_model_table(g))
        parts.append(_dark_table(g.get("dark_current")))
        parts.append(emva1288_r4_html(g.get("emva1288")))
        if figs.get(iso, {}).get("emva1288"):
            parts.append("<img alt='EMVA 1288 R4.0 plots' style='max-width:100%;height:auto' "
                         f"src='data:image/png;base64,{figs[iso]['emva1288']}'>")
        parts.append(_family_table(g["heldout"]))
        if g.get("remaining_families"):
            parts.append("<p>Families still significant under the final model:</p><ul>" + "".join(
                f"<li>{f['family']} (excess {_num(f['excess'])}, z = {f['z']:.1f}): {html.escape(f['reason'])}</li>"
                for f in g["remaining_families"]) + "</ul>")
        for note in g["notes"]:
            if note not in doc["notes"]:
                parts.append(f"<p><i>{html.escape(note)}</i></p>")
        parts.append("<h3>Iterations</h3><table><tr><th>#</th><th>effect</th><th>diagnostic</th><th>z before</th>"
                     "<th>z after</th><th>held-out z before</th><th>held-out z after</th><th>pixel KL before</th>"
                     "<th>pixel KL after</th><th>KL excess before</th><th>KL excess after</th>"
                     "<th>structured KL before</th><th>structured KL after</th><th>NLL before</th><th>NLL after</th>"
                     "<th>kept</th><th>parameters</th></tr>")
        taken_out = {b["effect"] for b in g.get("backward") or [] if b["removed"]}
        for i, it in enumerate(g["iterations"], 1):
            h = it["heldout"]
            label = it["effect"] + (f" <i>(empirical, not in the vocabulary: {html.escape(it['not_in_vocabulary'])})</i>"
                                    if it.get("not_in_vocabulary") else "")
            if it.get("joint_with"):
                label += (f" <i>(fitted jointly with {html.escape(it['joint_with'])}: "
                          f"{html.escape(it.get('joint_why', ''))})</i>")
            label += "".join(f"<br><i>{html.escape(n)} removed: {html.escape(why)}</i>"
                             for n, why in (it.get("removed") or {}).items())
            if it["accepted"] and it["effect"] in taken_out:
                label += " <i>(taken out by the backward step)</i>"
            parts.append(f"<tr><td>{i}</td><td class=l>{label}</td><td class=l>{it['diagnostic']}</td>"
                         f"<td>{_fmt(it['discrepancy_before'])}</td><td>{_fmt(it['discrepancy_after'])}</td>"
                         f"<td>{_fmt(h['discrepancy_before'])}</td><td>{_fmt(h['discrepancy_after'])}</td>"
                         f"<td>{_fmt(h['kl_before'])}</td><td>{_fmt(h['kl_after'])}</td>"
                         f"<td>{_fmt(h['kl_excess_before'])}</td><td>{_fmt(h['kl_excess_after'])}</td>"
                         f"<td>{_fmt(h['kl_structured_before'])}</td><td>{_fmt(h['kl_structured_after'])}</td>"
                         f"<td>{_fmt(h['nll_before'])}</td>"
                         f"<td>{_fmt(h['nll_after'])}</td><td>{'yes' if it['accepted'] else 'no'}</td>"
                         f"<td class=l>{html.escape(format_parameters(it['effect'], it['parameters']))}</td></tr>")
        parts.append("</table>")
        parts.append(_candidates_table(g["iterations"]))
        parts.append(_backward_table(g.get("backward") or []))
        if g["unexplained"]:
            parts.append("<h3>Unexplained</h3><ul>" + "".join(
                f"<li>{u['diagnostic']}: z = {_fmt(u['discrepancy'])} ({html.escape(u['reason'])})</li>"
                for u in g["unexplained"]) + "</ul>")
        parts.append("<h3>Diagnostics (base → final model)</h3><table><tr><th>diagnostic</th><th>effect</th>"
                     "<th>data</th><th>z base</th><th>z final</th><th>p final</th></tr>")
        fin = {d["name"]: d for d in g["diagnostics_final"]}
        na = {x["diagnostic"]: x["reason"] for x in g.get("not_applicable", [])}
        for d in g["diagnostics_base"]:
            f = fin.get(d["name"], {"significant": False, "discrepancy": None, "p": None})
            cls = " class=sig" if f["significant"] else ""
            parts.append(f"<tr{cls}><td class=l>{d['name']}</td><td class=l>{d['effect'] or '–'}</td>"
                         f"<td>{_fmt(d['value'])}</td><td>{_fmt(d['discrepancy'])}</td><td>{_fmt(f['discrepancy'])}</td>"
                         f"<td>{_fmt(f['p'])}</td></tr>")
        parts.append("</table>")
        if na:
            parts.append("<h3>Not applicable</h3><ul>" + "".join(
                f"<li>{html.escape(k)}: {html.escape(v)}</li>" for k, v in na.items()) + "</ul>")
        titles = {"ptc": "Photon-transfer curve with fit and residuals", "spectra": "Row / column spectra",
                  "maps": "Temporal-mean maps", "hists": "Residual histograms before / after each added effect"}
        for key, title in titles.items():
            if key in figs.get(iso, {}):
                parts.append(f"<h3>{title}</h3><img alt='{title}' style='max-width:100%;height:auto' "
                             f"src='data:image/png;base64,{figs[iso][key]}'>")
    parts.append("</body></html>")
    Path(path).write_text("\n".join(parts))


def _backward_table(tests: list[dict]) -> str:
    """The backward step's tests: each added effect left out of the final model in turn, the held-out gain
    of keeping it, and whether it was taken out (:meth:`simcam.calibration.loop.Loop._backward`)."""
    if not tests:
        return ""
    rows = ["<h3>Backward step (held-out synthetic log-likelihood gain of keeping each added effect)</h3>"
            "<table><tr><th>round</th><th>effect</th><th>gain of keeping it (nats)</th><th>± SD</th><th>replicates</th>"
            "<th>statistics that moved most</th><th>structured KL with</th><th>structured KL without</th>"
            "<th>taken out</th></tr>"]
    for b in tests:
        moved = ", ".join(f"{m['diagnostic']} {m['gain']:+.3g}" for m in b["moved_most"])
        why = ("yes: keeping it does not beat its noise" if b["removed"] else
               "no: keeping it beats its noise" if b.get("earns_keep") else
               f"no: without it the held-out error grows ({html.escape(b['error_grew_without'])})"
               if b.get("error_grew_without") else
               "no: without it a statistic breaks (" + html.escape(", ".join(x["diagnostic"] for x in b["breaks_without"]))
               + ")" if b.get("breaks_without") else "no: another effect kept less")
        rows.append(f"<tr><td>{b.get('round', '')}</td><td class=l>{html.escape(b['effect'])}</td><td>{b['keep_gain']:.3g}</td>"
                    f"<td>{b['keep_gain_sd']:.2g}</td><td>{b['replicates']}</td><td class=l>{html.escape(moved)}</td>"
                    f"<td>{_fmt(b['kl_structured_with'])}</td><td>{_fmt(b['kl_structured_without'])}</td>"
                    f"<td class=l>{why}</td></tr>")
    return "".join(rows) + "</table>"


def _candidates_table(iterations: list[dict]) -> str:
    """Every candidate effect of every iteration with its held-out score (attribution by model comparison,
    :mod:`simcam.calibration.attribution`)."""
    if not any(it.get("candidates") for it in iterations):
        return ""
    rows = ["<h3>Candidates per iteration (held-out synthetic log-likelihood gain over the current model)</h3>"
            "<table><tr><th>#</th><th>candidate</th><th>proposed by</th><th>gain (nats)</th><th>± SD</th>"
            "<th>replicates</th><th>statistics that moved most</th><th>pixel KL after</th><th>structured KL after</th>"
            "<th>beats current</th>"
            "<th>chosen</th></tr>"]
    for i, it in enumerate(iterations, 1):
        for c in it.get("candidates", []):
            if "skipped" in c:
                name = c["effect"] + (f" ({c['form']})" if c.get("form") else "")
                rows.append(f"<tr><td>{i}</td><td class=l>{name}</td><td class=l>{', '.join(c['proposed_by'])}</td>"
                            f"<td colspan=8 class=l>{html.escape(c['skipped'])}</td></tr>")
                continue
            moved = ", ".join(f"{m['diagnostic']} {m['gain']:+.3g}" for m in c["moved_most"])
            chosen = ("" if not c["chosen"] else
                      f"yes (tied: {html.escape(c['tie_broken_by'])})" if c.get("tie_broken_by") else "yes")
            breaks = "; ".join(f"{b['diagnostic']} held-out z {b['z_before']:.2g} → {b['z']:.2g}"
                               for b in c.get("breaks", ()))
            verdict = (f"no (left the race: {html.escape(c['left_race'])})" if c.get("left_race") else
                       f"no (breaks {html.escape(breaks)})" if breaks else
                       f"no (held-out error grew: {html.escape(c['error_grew'])})" if c.get("error_grew") else "no")
            again = (f" (raced again: it had left {html.escape(c['raced_again'].split(';')[0])})"
                     if c.get("raced_again") else "")  # behind a leader that was then refuted
            several = len(c["proposed_by"]) > 1 and c.get("fitted_from")
            joint = c.get("joint_with")
            name = (f"{joint['effect']}" + (f" ({joint['form']})" if joint.get("form") else "") + " + "
                    if joint else "") + c["effect"] + (f" ({c['form']})" if c.get("form") else "") + (
                f" (fitted from {c['fitted_from']})" if several else "")
            rows.append(f"<tr><td>{i}</td><td class=l>{name}</td><td class=l>{', '.join(c['proposed_by'])}</td>"
                        f"<td>{_fmt(c['heldout_gain'])}</td><td>{_fmt(c['heldout_gain_sd'])}</td>"
                        f"<td>{c.get('replicates', '')}</td><td class=l>{html.escape(moved)}</td><td>{_fmt(c['kl_after'])}</td>"
                        f"<td>{_fmt(c.get('kl_structured_after'))}</td>"
                        f"<td>{('yes' if c['beats_current'] else verdict) + again}</td>"
                        f"<td>{chosen}</td></tr>")
    rows.append("</table>")
    return "".join(rows)


def emva1288_r4_results(capture) -> dict[int, dict]:
    """EMVA 1288 R4.0 (Linear) results per ISO from the whole-frame point statistics the reader kept
    (:mod:`simcam.calibration.emva1288`); an ISO without dark and flat points at known exposures gets
    ``{"not_applicable": reason}``."""
    from .emva1288 import Emva1288Error, Emva1288Report, cfa_channels, characterise_stats

    out: dict[int, dict] = {}
    for iso in capture.isos():
        seqs = [s for s in capture.group(iso) if s.emva_stats]
        kinds = {s.kind for s in seqs}
        if not {"dark", "flat"} <= kinds:
            out[iso] = {"not_applicable": "EMVA 1288 needs dark and flat sequences with their exposure times; "
                                          f"this ISO has {sorted(kinds) or 'none'}"}
            continue
        cfa = seqs[0].cfa
        names = [n for n, _, _ in cfa_channels(cfa)]
        try:
            rep = Emva1288Report({n: characterise_stats([s.emva_stats[i] for s in seqs], channel=n)
                                  for i, n in enumerate(names)}, None if cfa is None else str(cfa).upper())
            out[iso] = rep.to_dict()
        except Emva1288Error as exc:
            out[iso] = {"not_applicable": str(exc)}
    return out


def run_and_write(capture_dir: str | Path, out_dir: str | Path, *, start_profile: str | Path | None = None,
                  cfg: LoopConfig | None = None) -> dict:
    """Read a capture set, run the loop, write profile.yaml, report.json, report.html; return the report."""
    from ..errors import DatasetError
    from .capture import read_capture_set
    from .loop import run_loop
    from .dark_current import dark_current
    from .photon_transfer import emva1288_numbers

    cfg = cfg or LoopConfig()
    capture_dir, out_dir = Path(capture_dir), Path(out_dir)
    if out_dir.resolve() == capture_dir.resolve():
        raise DatasetError(f"--out {out_dir}: is the capture set itself; expected another directory "
                           "(inputs are never overwritten)")
    starts = read_start_profile(Path(start_profile)) if start_profile else None
    if start_profile and Path(start_profile).resolve() == (out_dir / "profile.yaml").resolve():
        raise DatasetError(f"--start-profile {start_profile}: would be overwritten by the output profile; "
                           "expected a file outside OUT_DIR")
    capture = read_capture_set(capture_dir, region=cfg.region(), progress=cfg.progress, threads=loop_threads(cfg))
    results = run_loop(capture, cfg, starts)
    emva = {iso: emva1288_numbers(capture.group(iso)) for iso in capture.isos()}
    dark = {}
    for r in results:
        e = emva.get(r.iso) or {}
        K = e.get("K_dn_per_e") or (r.base.K if r.base.K > 0 else None)
        dark[r.iso] = dark_current([s for s in capture.group(r.iso) if s.kind == "dark"], K)
    doc = build_report(results, capture, cfg, emva, dark, emva1288_r4=emva1288_r4_results(capture))
    out_dir.mkdir(parents=True, exist_ok=True)
    from .profile import noise_profile

    maps = None
    if cfg.maps:
        from .maps import MAPS_FILE, measured_maps

        arrays, maps, map_notes = measured_maps(capture, results)
        doc["notes"] = doc["notes"] + map_notes
        if arrays:
            tmp = out_dir / (MAPS_FILE + ".part.npz")
            np.savez_compressed(tmp, **arrays)
            tmp.replace(out_dir / MAPS_FILE)
    write_yaml(out_dir / "profile.yaml", noise_profile(results, capture, maps=maps))
    write_yaml(out_dir / "loop_model.yaml", loop_model_dict(results, capture))
    (out_dir / "report.json").write_text(json.dumps(doc, indent=2))
    figs = {r.iso: figures(r, cfg.seed) for r in results}
    for g in doc["isos"]:
        emva_png = emva1288_r4_figure(g.get("emva1288"))
        if emva_png:
            figs.setdefault(g["iso"], {})["emva1288"] = emva_png
    write_html(out_dir / "report.html", doc, figs)
    return doc
