"""``simcam gt``: ground truth from a burst (Abdelhamed 2020, section 5.3)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer


def _outputs(outputs: list[Path]) -> tuple[Optional[Path], Optional[Path]]:
    from ..errors import DatasetError

    npz = dng = None
    for o in outputs:
        ext = o.suffix.lower()
        if ext == ".npz" and npz is None:
            npz = o
        elif ext == ".dng" and dng is None:
            dng = o
        else:
            raise DatasetError(f"{o}: output: expected one .npz and/or one .dng file, got {o.suffix or '(no extension)'!r}")
    return npz, dng


def gt(
    burst_dir: list[Path] = typer.Argument(..., metavar="BURST_DIR...",
                                           help="Folder of the burst's frames (DNG, or PNG/TIFF for a mono sensor); "
                                                "several folders, or one folder of burst folders, for a batch."),
    output: list[Path] = typer.Option(..., "-o", "--output",
                                      help="OUT.npz (gt, sigma, defects, valid) and/or OUT.dng; repeatable. "
                                           "Batch: the output folder."),
    dark: Optional[Path] = typer.Option(None, "--dark", help="Directory of a dark sequence: defective pixels from its mean."),
    flat: Optional[Path] = typer.Option(None, "--flat", help="Directory of a flat sequence: more defective pixels."),
    defects: Optional[Path] = typer.Option(None, "--defects", help="Known defect map (.npz from --save-defects, or SIDD .mat)."),
    save_defects: Optional[Path] = typer.Option(None, "--save-defects", help="Write the defect map used to this .npz."),
    report: Optional[Path] = typer.Option(None, "--report", help="JSON report path (default: beside the first output)."),
    method: str = typer.Option("wls", "--method", help="Robust mean: wls (Abdelhamed 2020), mle (censored MLE) or mean."),
    alignment: str = typer.Option("local", "--alignment", help="local (TPS from patch shifts), global or none."),
    intensity: str = typer.Option("additive", "--intensity", help="Intensity alignment: additive (eq. 5.4), multiplicative, none."),
    patch: int = typer.Option(512, "--patch", help="Alignment patch size in mosaic pixels (Abdelhamed 2020: 512)."),
    interp_order: int = typer.Option(3, "--interp-order", help="Warp interpolation: 3 cubic, 1 linear."),
    pattern: Optional[str] = typer.Option(None, "--pattern", help="Glob selecting the burst's files (e.g. 'b_s_*.png')."),
    dark_pattern: Optional[str] = typer.Option(None, "--dark-pattern", help="Glob selecting the dark frames."),
    black_level: Optional[float] = typer.Option(None, "--black-level", help="Override the black level (DN)."),
    white_level: Optional[float] = typer.Option(None, "--white-level", help="Override the white level (DN); PNG/TIFF default: the sample type's maximum."),
    nan_policy: str = typer.Option("raise", "--nan-policy", help="NaN samples: raise, or omit (treat as missing)."),
    scratch_dir: Optional[Path] = typer.Option(None, "--scratch-dir", help="Where large bursts spill their working frames."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Progress bars on stderr."),
    workers: Optional[int] = typer.Option(None, "--workers", min=0,
                                          help="Batch: dask worker processes (default: one per core; 0: serial)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Batch: dask scheduler address."),
    resume: bool = typer.Option(False, "--resume", help="Batch: skip bursts whose outputs exist."),
) -> None:
    """Estimate the noise-free image of a burst: defects, intensity and dense alignment, robust mean."""
    """Estimate the noise-free image of a burst (or of every burst of a folder, on dask):
    defects, intensity and dense alignment, robust mean."""
    from ..groundtruth.burst import IMAGE_EXTS, RAW_EXTS, is_sidd_frame
    from ..errors import DatasetError
    from ..io.outputs import check_output_file
    from ..jobs import ground_truth_job

    settings = dict(dark=_str(dark), flat=_str(flat), defects=_str(defects), method=method, alignment=alignment,
                    intensity=intensity, patch=patch, interp_order=interp_order, pattern=pattern,
                    dark_pattern=dark_pattern, black_level=black_level, white_level=white_level,
                    nan_policy=nan_policy, scratch_dir=_str(scratch_dir))
    frame_exts = RAW_EXTS + IMAGE_EXTS
    single = len(burst_dir) == 1 and (not burst_dir[0].is_dir() or pattern is not None or any(
        (p.is_file() and p.suffix.lower() in frame_exts) or is_sidd_frame(p) for p in burst_dir[0].iterdir()))
    if not single:
        if len(output) != 1 or output[0].suffix:
            raise DatasetError(f"-o {' '.join(map(str, output))}: several bursts; expected one output folder "
                               "(OUT/<burst>.npz and OUT/<burst>.json are written)")
        if save_defects is not None or report is not None:
            raise DatasetError("--save-defects / --report: one burst only; a batch writes OUT/<burst>.json reports")
        raise typer.Exit(_gt_batch(burst_dir, output[0], settings, workers=workers, scheduler=scheduler,
                                   resume=resume))
    npz, dng = _outputs(output)
    for o, opt in [(o, "-o") for o in output] + [(save_defects, "--save-defects"), (report, "--report")]:
        if o is not None:
            check_output_file(o, option=opt, inputs=(defects,))
    if save_defects is not None and save_defects.suffix.lower() != ".npz":
        raise DatasetError(f"{save_defects}: --save-defects: expected a .npz path")
    info = ground_truth_job({**settings, "burst": str(burst_dir[0]), "npz": _str(npz), "dng": _str(dng),
                             "save_defects": _str(save_defects),
                             "report": str(report or Path(output[0]).with_suffix(".json")), "progress": progress})
    typer.echo(info["summary"])


def _str(p) -> Optional[str]:
    return None if p is None else str(p)


def _gt_batch(inputs: list[Path], out_dir: Path, settings: dict, *, workers, scheduler, resume) -> int:
    from ..batch import BatchConfig, Task, report, run_batch, start_workers_early
    from ..errors import DatasetError
    from ..io.outputs import check_output_dir
    from ..jobs import ground_truth_job

    config = BatchConfig(workers=workers, scheduler=scheduler, resume=resume)
    start_workers_early(ground_truth_job, config)
    bursts: list[Path] = []
    for item in inputs:
        if not item.is_dir():
            raise DatasetError(f"{item}: burst folder not found")
        subs = sorted(p for p in item.iterdir() if p.is_dir())
        bursts.extend(subs if subs and len(inputs) == 1 else [item])
    if not bursts:
        raise DatasetError(f"{inputs[0]}: no burst sub-folders; expected one folder of frames per burst")
    names = [b.name for b in bursts]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise DatasetError(f"bursts: several folders named {dup}; expected distinct burst names")
    check_output_dir(out_dir, option="-o", inputs=bursts)
    out_dir.mkdir(parents=True, exist_ok=True)
    tasks = [Task(str(b), {**settings, "burst": str(b), "npz": str(out_dir / f"{b.name}.npz"), "dng": None,
                           "save_defects": None, "report": str(out_dir / f"{b.name}.json"), "progress": False},
                  outputs=(str(out_dir / f"{b.name}.npz"), str(out_dir / f"{b.name}.json")))
             for b in bursts]
    outcomes = run_batch(ground_truth_job, tasks, config, label="gt")
    for o in outcomes:
        if o.ok and not o.skipped:
            typer.echo(o.info["summary"])
    typer.echo(f"ground truth of {sum(o.ok for o in outcomes)} of {len(tasks)} bursts in {out_dir}")
    return report(outcomes, command="simcam gt")


def register(app: typer.Typer) -> None:
    app.command("gt")(gt)
