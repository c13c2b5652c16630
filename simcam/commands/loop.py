"""``simcam loop``: close the loop on measured data (fit, diagnose, attribute, refit, report)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from ..calibration.region import DEFAULT_MAX_PIXELS


def loop(
    capture_dir: list[Path] = typer.Argument(..., metavar="CAPTURE_DIR...",
                                             help="Capture set: directory of dark*/flat*/scene sequences, or an EMVA "
                                                  "1288 descriptor. Several: a batch, one OUT/<name>/ each."),
    out: Path = typer.Option(..., "--out", help="Output directory (profile.yaml, loop_model.yaml, report.json, report.html)."),
    start_profile: Optional[Path] = typer.Option(None, "--start-profile", help="Start from this profile's models (a profile.yaml or loop_model.yaml written by simcam loop) instead of the base fit."),
    seed: int = typer.Option(0, "--seed", help="Seed of the parametric bootstrap."),
    replicates: int = typer.Option(16, "--replicates", help="Bootstrap replicates per diagnostic evaluation (>= 4)."),
    alpha: float = typer.Option(0.01, "--alpha", help="Family-wise significance level (Holm)."),
    max_size: Optional[int] = typer.Option(None, "--max-size", help="Analyse a centre crop of this many pixels per side instead of the whole frame."),
    max_pixels: int = typer.Option(DEFAULT_MAX_PIXELS, "--max-pixels", help="Pixels per frame the residual battery and bootstrap analyse: the whole frame up to this, else tiles spread over the frame."),
    workers: Optional[int] = typer.Option(None, "--workers", min=0,
                                          help="Batch: dask worker processes (default: one per core; 0: serial)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Batch: dask scheduler address."),
    resume: bool = typer.Option(False, "--resume", help="Batch: skip capture sets whose report exists."),
    maps: bool = typer.Option(False, "--maps", help="Keep this sensor's measured fixed patterns (dark offset map: DSNU, "
                              "column offsets, hot pixels; flat gain map: PRNU) in maps.npz beside profile.yaml, so "
                              "the noise stage reproduces them instead of drawing new ones."),
) -> None:
    """Fit a noise model to measured frames, find and attribute its residuals, refit, report before/after."""
    from ..errors import DatasetError
    from ..io.outputs import check_output_dir
    from ..jobs import loop_job

    check_output_dir(out, option="--out", inputs=(*capture_dir, start_profile))
    if replicates < 4:
        raise DatasetError(f"--replicates {replicates}: expected >= 4")
    if not 0 < alpha < 1:
        raise DatasetError(f"--alpha {alpha}: expected a level in (0, 1)")
    if max_size is not None and max_size < 16:
        raise DatasetError(f"--max-size {max_size}: expected >= 16 pixels")
    if max_pixels < 64 * 64:
        raise DatasetError(f"--max-pixels {max_pixels}: expected >= 4096 pixels")
    cfg = dict(replicates=replicates, alpha=alpha, seed=seed, max_size=max_size, max_pixels=max_pixels, maps=maps)
    start = None if start_profile is None else str(start_profile)
    if len(capture_dir) > 1:
        raise typer.Exit(_loop_batch(capture_dir, out, cfg, start, workers=workers, scheduler=scheduler,
                                     resume=resume))
    info = loop_job({"capture": str(capture_dir[0]), "out": str(out), "start_profile": start, "config": cfg})
    for line in info["lines"]:
        typer.echo(line)


def _loop_batch(sets: list[Path], out: Path, cfg: dict, start, *, workers, scheduler, resume) -> int:
    from ..batch import BatchConfig, Task, report, run_batch
    from ..errors import DatasetError
    from ..jobs import loop_job

    names = [s.stem if s.is_file() else s.name for s in sets]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise DatasetError(f"capture sets: several named {dup}; expected distinct names (OUT/<name>/ each)")
    tasks = [Task(str(s), {"capture": str(s), "out": str(out / n), "start_profile": start, "config": cfg},
                  outputs=(str(out / n / "report.json"),)) for s, n in zip(sets, names)]
    out.mkdir(parents=True, exist_ok=True)
    outcomes = run_batch(loop_job, tasks, BatchConfig(workers=workers, scheduler=scheduler, resume=resume),
                         label="loop")
    for t, o in zip(tasks, outcomes):
        if o.ok and not o.skipped:
            typer.echo(f"{t.key}:")
            for line in o.info["lines"]:
                typer.echo(f"  {line}")
    typer.echo(f"calibrated {sum(o.ok for o in outcomes)} of {len(tasks)} capture sets into {out}")
    return report(outcomes, command="simcam loop")


def register(app: typer.Typer) -> None:
    app.command("loop")(loop)
