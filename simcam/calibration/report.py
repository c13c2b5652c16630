"""Outputs of ``simcam loop``: profile.yaml (noise-stage profile), loop_model.yaml (the loop's own
model in DN), report.json and report.html (plots as base64 PNGs).

The JSON schema is documented in the README ("Calibration loop report").
"""

from __future__ import annotations

import base64
import html
import io
import json
from pathlib import Path

import numpy as np

from ..errors import ProfileError
from . import diagnostics as dg
from .heldout import KL_BINNING, KL_EDGES
from .effects import ctx_like
from .loop import LoopConfig, GroupResult
from .heldout import FAMILIES, GATE_Z, STRUCTURED_BINNING

STRUCTURED_KL = (f"sum over the families {', '.join(FAMILIES)} of the held-out noise (per sequence and CFA plane) of "
                 f"their KL minus its sampling floor, counted where it exceeds {GATE_Z:g} sampling SDs; binning: "
                 f"{STRUCTURED_BINNING}")
from .model import LoopModel
from .simulate import simulate_capture

REPORT_SCHEMA = "simcam-loop-report/1"
PROFILE_SCHEMA = 1


def _disc_dict(d: dg.Discrepancy) -> dict:
    return {"name": d.name, "effect": dg.DIAGNOSTIC_EFFECT[d.name], "value": d.value, "sim_mean": d.sim_mean,
            "sim_sd": d.sim_sd, "discrepancy": d.z, "p": d.p, "significant": bool(d.significant)}


def _clean(v):
    if isinstance(v, dict):
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


def build_report(results: list[GroupResult], capture, cfg: LoopConfig, emva: dict[int, dict | None]) -> dict:
    """The report.json document (see the README for the schema)."""
    isos = []
    for r in results:
        isos.append({
            "iso": int(r.iso),
            "iterations": [{k: v for k, v in it.items()} for it in r.iterations],
            "effects": list(r.model.effects),
            "unexplained": [{"diagnostic": u["diagnostic"], "discrepancy": u["discrepancy"], "reason": u["reason"]}
                            for u in r.unexplained],
            "photon_transfer": _plane_ptc(r),
            "base_model": r.base.to_dict(),
            "model": r.model.to_dict(),
            "diagnostics_base": [_disc_dict(d) for d in r.base_disc],
            "diagnostics_final": [_disc_dict(d) for d in r.final],
            "heldout": {"kl_base": r.heldout_base["kl"], "kl_final": r.heldout_final["kl"],
                        "kl_sampling_floor": r.heldout_final["kl_floor"],
                        "kl_excess_base": r.heldout_base["kl_excess"], "kl_excess_final": r.heldout_final["kl_excess"],
                        "kl_structured_base": r.heldout_base["kl_structured"],
                        "kl_structured_final": r.heldout_final["kl_structured"],
                        "structured_base": r.heldout_base["structured"],
                        "structured_final": r.heldout_final["structured"],
                        "nll_base": r.heldout_base["nll"], "nll_final": r.heldout_final["nll"]},
            "emva": emva.get(r.iso),
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
                     "max_size": cfg.max_size, "seed": cfg.seed, "max_iterations": cfg.max_iterations,
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
            "model": {"type": "poisson_gaussian", "beta1": float(m.K / fs), "beta2": float(m.read_dn ** 2 / fs ** 2)},
            "K_dn_per_e": float(m.K), "read_dn": float(m.read_dn),
            "black_level": [float(x) for x in np.asarray(m.black_dn).ravel()],
            "effects": _clean({k: {p: v for p, v in prm.items()} for k, prm in m.effects.items()}),
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
        m = LoopModel(doc.get("cfa"), black, white, K, read, var_dark_dn2=0.0, effects=effects)
        q = m.q
        m.var_dark_dn2 = read ** 2 + q ** 2 / 12 + effects.get("row_noise", {}).get("sigma_dn", 0.0) ** 2 + \
            (effects["periodic_pattern"]["amplitude_dn"] ** 2 / 2 if "periodic_pattern" in effects else 0.0)
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
    c = model.effects.get("nonlinearity", {}).get("c", 0.0)
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
        ax.set_title(f"ISO {r.iso}: photon transfer (K = {r.base.K:.4g} → {r.model.K:.4g} DN/e$^-$)")
        ax.legend(fontsize=8)
        axr.axhline(0, color="0.5", lw=0.8)
        axr.set_xlabel("mean signal above dark (DN)")
        axr.set_ylabel("residual (DN$^2$)\nx base, o final", fontsize=8)
        fig.tight_layout()
        out["ptc"] = _png(fig)
    # spectra: data vs base vs final (mean of 4 simulated captures)
    model_ps = {}
    for key, model in (("base", r.base), ("final", r.model)):
        specs = g.specs(model, g.fit)
        acc = {2: [], 1: []}
        for rep in range(4):
            sims = simulate_capture(model, specs, np.random.default_rng([seed, 99, rep]))
            cd = ctx_like(d, sims, specs)
            for axis in (2, 1):
                acc[axis].append(dg.periodogram(cd, axis))
        model_ps[key] = acc
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


def _drop(before, after) -> str:
    if not before or before <= 0 or after is None:
        return ""
    return f" ({100 * (1 - after / before):.0f} % drop)"


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


def write_html(path: Path, doc: dict, figs: dict[int, dict]) -> None:
    parts = ["<!doctype html><html><head><meta charset='utf-8'><title>simcam loop report</title>",
             "<style>body{font-family:sans-serif;margin:2em;max-width:1200px} table{border-collapse:collapse;"
             "font-size:13px} td,th{border:1px solid #bbb;padding:3px 6px;text-align:right} th{background:#eee}"
             " td.l{text-align:left} .sig{background:#fdd}</style></head><body>",
             f"<h1>simcam loop report</h1><p>Capture set <code>{html.escape(doc['capture_set'])}</code> "
             f"({doc['layout']}). Significance: {doc['settings']['correction']} at alpha = {doc['settings']['alpha']}"
             f", {doc['settings']['replicates']} bootstrap replicates. Pixel marginal KL: {html.escape(doc['kl_binning'])}. "
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
        parts.append(f"<h2>ISO {iso}</h2><p>Effects added: <b>{', '.join(g['effects']) or 'none'}</b>. "
                     f"Held-out pixel marginal KL {_fmt(g['heldout']['kl_base'])} (base) → {_fmt(g['heldout']['kl_final'])} "
                     f"(final; sampling floor {_fmt(g['heldout']['kl_sampling_floor'])}, excess "
                     f"{_fmt(g['heldout']['kl_excess_base'])} → {_fmt(g['heldout']['kl_excess_final'])}); structured "
                     f"marginal KL {_fmt(g['heldout']['kl_structured_base'])} → {_fmt(g['heldout']['kl_structured_final'])}"
                     f"{_drop(g['heldout']['kl_structured_base'], g['heldout']['kl_structured_final'])}; "
                     f"NLL/dim {_fmt(g['heldout']['nll_base'])} → {_fmt(g['heldout']['nll_final'])} nats.</p>")
        parts.append(_family_table(g["heldout"]))
        for note in g["notes"]:
            parts.append(f"<p><i>{html.escape(note)}</i></p>")
        parts.append("<h3>Iterations</h3><table><tr><th>#</th><th>effect</th><th>diagnostic</th><th>z before</th>"
                     "<th>z after</th><th>held-out z before</th><th>held-out z after</th><th>pixel KL before</th>"
                     "<th>pixel KL after</th><th>KL excess before</th><th>KL excess after</th>"
                     "<th>structured KL before</th><th>structured KL after</th><th>NLL before</th><th>NLL after</th>"
                     "<th>kept</th><th>parameters</th></tr>")
        for i, it in enumerate(g["iterations"], 1):
            h = it["heldout"]
            parts.append(f"<tr><td>{i}</td><td class=l>{it['effect']}</td><td class=l>{it['diagnostic']}</td>"
                         f"<td>{_fmt(it['discrepancy_before'])}</td><td>{_fmt(it['discrepancy_after'])}</td>"
                         f"<td>{_fmt(h['discrepancy_before'])}</td><td>{_fmt(h['discrepancy_after'])}</td>"
                         f"<td>{_fmt(h['kl_before'])}</td><td>{_fmt(h['kl_after'])}</td>"
                         f"<td>{_fmt(h['kl_excess_before'])}</td><td>{_fmt(h['kl_excess_after'])}</td>"
                         f"<td>{_fmt(h['kl_structured_before'])}</td><td>{_fmt(h['kl_structured_after'])}</td>"
                         f"<td>{_fmt(h['nll_before'])}</td>"
                         f"<td>{_fmt(h['nll_after'])}</td><td>{'yes' if it['accepted'] else 'no'}</td>"
                         f"<td class=l>{html.escape(json.dumps(it['parameters']))}</td></tr>")
        parts.append("</table>")
        if g["unexplained"]:
            parts.append("<h3>Unexplained</h3><ul>" + "".join(
                f"<li>{u['diagnostic']}: z = {_fmt(u['discrepancy'])} ({html.escape(u['reason'])})</li>"
                for u in g["unexplained"]) + "</ul>")
        parts.append("<h3>Diagnostics (base → final model)</h3><table><tr><th>diagnostic</th><th>effect</th>"
                     "<th>data</th><th>z base</th><th>z final</th><th>p final</th></tr>")
        fin = {d["name"]: d for d in g["diagnostics_final"]}
        for d in g["diagnostics_base"]:
            f = fin[d["name"]]
            cls = " class=sig" if f["significant"] else ""
            parts.append(f"<tr{cls}><td class=l>{d['name']}</td><td class=l>{d['effect'] or '–'}</td>"
                         f"<td>{_fmt(d['value'])}</td><td>{_fmt(d['discrepancy'])}</td><td>{_fmt(f['discrepancy'])}</td>"
                         f"<td>{_fmt(f['p'])}</td></tr>")
        parts.append("</table>")
        titles = {"ptc": "Photon-transfer curve with fit and residuals", "spectra": "Row / column spectra",
                  "maps": "Temporal-mean maps", "hists": "Residual histograms before / after each added effect"}
        for key, title in titles.items():
            if key in figs.get(iso, {}):
                parts.append(f"<h3>{title}</h3><img alt='{title}' src='data:image/png;base64,{figs[iso][key]}'>")
    parts.append("</body></html>")
    Path(path).write_text("\n".join(parts))


def run_and_write(capture_dir: str | Path, out_dir: str | Path, *, start_profile: str | Path | None = None,
                  cfg: LoopConfig | None = None) -> dict:
    """Read a capture set, run the loop, write profile.yaml, report.json, report.html; return the report."""
    from ..errors import DatasetError
    from .capture import read_capture_set
    from .loop import run_loop
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
    capture = read_capture_set(capture_dir)
    results = run_loop(capture, cfg, starts)
    emva = {iso: emva1288_numbers(capture.group(iso)) for iso in capture.isos()}
    doc = build_report(results, capture, cfg, emva)
    out_dir.mkdir(parents=True, exist_ok=True)
    from .profile import noise_profile

    write_yaml(out_dir / "profile.yaml", noise_profile(results, capture))
    write_yaml(out_dir / "loop_model.yaml", loop_model_dict(results, capture))
    (out_dir / "report.json").write_text(json.dumps(doc, indent=2))
    figs = {r.iso: figures(r, cfg.seed) for r in results}
    write_html(out_dir / "report.html", doc, figs)
    return doc
