"""``simcam loop``: close the loop on measured data (fit, diagnose, attribute, refit, report)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer


def loop(
    capture_dir: Path = typer.Argument(..., help="Capture set: directory of dark*/flat*/scene sequences, or an EMVA 1288 descriptor."),
    out: Path = typer.Option(..., "--out", help="Output directory (profile.yaml, loop_model.yaml, report.json, report.html)."),
    start_profile: Optional[Path] = typer.Option(None, "--start-profile", help="Start from this profile's models (a profile.yaml or loop_model.yaml written by simcam loop) instead of the base fit."),
    seed: int = typer.Option(0, "--seed", help="Seed of the parametric bootstrap."),
    replicates: int = typer.Option(16, "--replicates", help="Bootstrap replicates per diagnostic evaluation (>= 4)."),
    alpha: float = typer.Option(0.01, "--alpha", help="Family-wise significance level (Holm)."),
    max_size: Optional[int] = typer.Option(None, "--max-size", help="Analyse a centre crop of this many pixels per side instead of the whole frame."),
    max_pixels: int = typer.Option(512 * 512, "--max-pixels", help="Pixels per frame the residual battery and bootstrap analyse: the whole frame up to this, else tiles spread over the frame."),
) -> None:
    """Fit a noise model to measured frames, find and attribute its residuals, refit, report before/after."""
    from ..calibration.loop import LoopConfig
    from ..calibration.report import run_and_write
    from ..errors import DatasetError

    if replicates < 4:
        raise DatasetError(f"--replicates {replicates}: expected >= 4")
    if not 0 < alpha < 1:
        raise DatasetError(f"--alpha {alpha}: expected a level in (0, 1)")
    if max_size is not None and max_size < 16:
        raise DatasetError(f"--max-size {max_size}: expected >= 16 pixels")
    if max_pixels < 64 * 64:
        raise DatasetError(f"--max-pixels {max_pixels}: expected >= 4096 pixels")
    cfg = LoopConfig(replicates=replicates, alpha=alpha, seed=seed, max_size=max_size, max_pixels=max_pixels)
    doc = run_and_write(capture_dir, out, start_profile=start_profile, cfg=cfg)
    for g in doc["isos"]:
        un = ", ".join(u["diagnostic"] for u in g["unexplained"]) or "none"
        typer.echo(f"{g['iso_label']}: effects {', '.join(g['effects']) or 'none'}; unexplained {un}; "
                   f"held-out KL {g['heldout']['kl_base']:.3g} -> {g['heldout']['kl_final']:.3g}, "
                   f"structured KL {g['heldout']['kl_structured_base']:.3g} -> {g['heldout']['kl_structured_final']:.3g}")
    if doc.get("emva"):
        e = doc["emva"]
        typer.echo(f"EMVA 1288: K = {e['K_dn_per_e']:.4f} DN/e-, sigma_d = {e['sigma_dark_e']:.2f} e-")
    typer.echo(f"wrote {out / 'profile.yaml'}, {out / 'loop_model.yaml'}, {out / 'report.json'}, {out / 'report.html'}")


def register(app: typer.Typer) -> None:
    app.command("loop")(loop)
