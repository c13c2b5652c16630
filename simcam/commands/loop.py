"""``simcam loop``: close the loop on measured data (fit, diagnose, attribute, refit, report)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer


def loop(
    capture_dir: Path = typer.Argument(..., metavar="CAPTURE_DIR", help="Capture set: directory of dark*/flat*/scene sequences, or an EMVA 1288 descriptor."),
    out: Path = typer.Option(..., "--out", help="Output directory (profile.yaml, loop_model.yaml, report.json, report.html)."),
    start_profile: Optional[Path] = typer.Option(None, "--start-profile", help="Start from this profile's models (a profile.yaml or loop_model.yaml written by simcam loop) instead of the base fit."),
    seed: int = typer.Option(0, "--seed", help="Seed of the parametric bootstrap."),
    replicates: int = typer.Option(16, "--replicates", help="Bootstrap replicates per diagnostic evaluation (>= 4)."),
    alpha: float = typer.Option(0.01, "--alpha", help="Family-wise significance level (Holm)."),
    max_size: int = typer.Option(128, "--max-size", help="Centre crop (pixels per side) the loop works on."),
) -> None:
    """Fit a noise model to measured frames, find and attribute its residuals, refit, report before/after."""
    from ..calibration.loop import LoopConfig
    from ..calibration.report import run_and_write
    from ..errors import DatasetError

    from ..io.outputs import check_output_dir

    check_output_dir(out, option="--out", inputs=(capture_dir, start_profile))
    if replicates < 4:
        raise DatasetError(f"--replicates {replicates}: expected >= 4")
    if not 0 < alpha < 1:
        raise DatasetError(f"--alpha {alpha}: expected a level in (0, 1)")
    if max_size < 16:
        raise DatasetError(f"--max-size {max_size}: expected >= 16 pixels")
    cfg = LoopConfig(replicates=replicates, alpha=alpha, seed=seed, max_size=max_size)
    doc = run_and_write(capture_dir, out, start_profile=start_profile, cfg=cfg)
    for g in doc["isos"]:
        un = ", ".join(u["diagnostic"] for u in g["unexplained"]) or "none"
        typer.echo(f"ISO {g['iso']}: effects {', '.join(g['effects']) or 'none'}; unexplained {un}; "
                   f"held-out KL {g['heldout']['kl_base']:.3g} -> {g['heldout']['kl_final']:.3g}, "
                   f"structured KL {g['heldout']['kl_structured_base']:.3g} -> {g['heldout']['kl_structured_final']:.3g}")
    if doc.get("emva"):
        e = doc["emva"]
        typer.echo(f"EMVA 1288: K = {e['K_dn_per_e']:.4f} DN/e-, sigma_d = {e['sigma_dark_e']:.2f} e-")
    typer.echo(f"wrote {out / 'profile.yaml'}, {out / 'loop_model.yaml'}, {out / 'report.json'}, {out / 'report.html'}")


def register(app: typer.Typer) -> None:
    app.command("loop")(loop)
