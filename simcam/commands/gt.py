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
    burst_dir: Path = typer.Argument(..., help="Directory of the burst's frames (DNG, or PNG/TIFF for a mono sensor)."),
    output: list[Path] = typer.Option(..., "-o", "--output", help="OUT.npz (gt, sigma, defects, valid) and/or OUT.dng; repeatable."),
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
) -> None:
    """Estimate the noise-free image of a burst: defects, intensity and dense alignment, robust mean."""
    import json

    from ..groundtruth import Burst, GroundTruthConfig, estimate_ground_truth, load_defect_map, save_defect_map
    from ..errors import DatasetError

    npz, dng = _outputs(output)
    kw = dict(black_level=black_level, white_level=white_level, nan_policy=nan_policy)
    burst = Burst.from_directory(burst_dir, pattern=pattern, **kw)
    inputs = {p.resolve() for p in map(Path, burst.names)}
    for o in output:
        if o.resolve() in inputs:
            raise DatasetError(f"{o}: refusing to overwrite an input frame")
    dark_b = Burst.from_directory(dark, pattern=dark_pattern, **kw) if dark is not None else None
    flat_b = Burst.from_directory(flat, **kw) if flat is not None else None
    known = load_defect_map(defects) if defects is not None else None
    cfg = GroundTruthConfig(method=method, alignment=alignment, intensity=intensity, patch=patch,
                            interp_order=interp_order, scratch_dir=str(scratch_dir) if scratch_dir else None)
    res = estimate_ground_truth(burst, dark=dark_b, flat=flat_b, defects=known, config=cfg, progress=progress)
    written = []
    if npz is not None:
        res.save_npz(npz)
        written.append(str(npz))
    if dng is not None:
        from ..groundtruth.dngout import write_ground_truth_dng

        write_ground_truth_dng(dng, res, burst)
        written.append(str(dng))
    if save_defects is not None:
        from ..groundtruth import DefectMap

        save_defect_map(save_defects, DefectMap(res.defects, "simcam gt", res.report["defects"].get("planes", [])))
        written.append(str(save_defects))
    rep_path = report or Path(output[0]).with_suffix(".json")
    rep = dict(res.report, inputs={"burst": str(burst_dir), "dark": str(dark) if dark else None,
                                   "flat": str(flat) if flat else None, "defects": str(defects) if defects else None},
               outputs=written)
    rep_path.write_text(json.dumps(rep, indent=2))
    a = res.report["alignment"]
    typer.echo(
        f"ground truth of {burst_dir}: {res.report['frames_used']}/{res.report['frames']} frames "
        f"(dropped {[d['index'] for d in res.report['dropped']]}), reference {res.reference}, "
        f"{res.report['defects']['count']} defective pixels, alignment {a['mode']} max shift {a['max_shift_px']:.2f} px, "
        f"{res.report['robust_mean']['fallback_pixels']} fallback pixels; wrote {', '.join(written)} and {rep_path}")


def register(app: typer.Typer) -> None:
    app.command("gt")(gt)
