"""``simcam bench``: score a denoiser on SIDD-format blocks (raw and sRGB PSNR/SSIM, s/MP)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer


def bench(
    noisy: Optional[Path] = typer.Option(None, "--noisy", help="Noisy blocks .mat ([N,M,H,W] raw or [N,M,H,W,3] sRGB; MATLAB v5 or v7.3)."),
    gt: Optional[Path] = typer.Option(None, "--gt", help="Ground-truth blocks .mat (same shape)."),
    pairs: Optional[Path] = typer.Option(None, "--pairs", help="Folder of *NOISY*/*GT* files (or noisy/ and gt/) instead of --noisy/--gt."),
    noisy_key: Optional[str] = typer.Option(None, "--noisy-key", help="Variable name in --noisy (default: the only block array)."),
    gt_key: Optional[str] = typer.Option(None, "--gt-key", help="Variable name in --gt."),
    metadata: Optional[Path] = typer.Option(None, "--metadata", help="Folder of per-image SIDD *METADATA*.MAT or DNG files (sorted order = image order): NLF for the denoiser and colour for sRGB scores."),
    pipeline: str = typer.Option("sidd-srgb", "--pipeline", "-p", help="Rendering pipeline for sRGB scores (with --metadata)."),
    denoiser: str = typer.Option("none", "--denoiser", "-d", help="none | bm3d[:vst|:mean] | nlm | dncnn:CKPT | cmd:'PROG {input} {output}' | python:MODULE:FUNC"),
    cfa: str = typer.Option("RGGB", "--cfa", help="CFA pattern of the blocks when no --metadata is given."),
    images: Optional[int] = typer.Option(None, "--images", help="Use only the first N images."),
    blocks: Optional[int] = typer.Option(None, "--blocks", help="Use only the first M blocks of each image."),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write the result as JSON."),
    csv_out: Optional[Path] = typer.Option(None, "--csv", help="Write per-block scores as CSV."),
    leaderboard: Optional[Path] = typer.Option(None, "--leaderboard", help="Add the result to a Markdown leaderboard file."),
) -> None:
    """Denoise SIDD-format blocks and report PSNR/SSIM (raw, sRGB) and seconds per megapixel."""
    from ..denoise.benchmark import load_metadata_dir, pipeline_renderer, run_benchmark
    from ..errors import DatasetError
    from ..io.sidd_blocks import read_blocks, read_pair_folder

    if pairs is not None:
        if noisy or gt:
            raise DatasetError("--pairs: give either --pairs DIR or --noisy/--gt files, not both")
        ps = read_pair_folder(pairs)
        noisy_b, gt_b = [p.noisy for p in ps], [p.gt for p in ps]
    else:
        if noisy is None or gt is None:
            raise DatasetError("--noisy/--gt: expected both block files (or --pairs DIR)")
        noisy_b, gt_b = read_blocks(noisy, noisy_key), read_blocks(gt, gt_key)
        if noisy_b.shape != gt_b.shape:
            raise DatasetError(f"{gt}: shape {gt_b.shape}, expected the shape of {noisy} {noisy_b.shape}")
    noisy_b, gt_b = list(noisy_b)[:images], list(gt_b)[:images]
    if blocks is not None:
        noisy_b, gt_b = [b[:blocks] for b in noisy_b], [b[:blocks] for b in gt_b]
    metas = load_metadata_dir(metadata, len(noisy_b)) if metadata is not None else None
    renderer = pipeline_renderer(pipeline) if metas is not None else None
    total = sum(len(b) for b in noisy_b)
    from tqdm import tqdm

    with tqdm(total=total, desc=f"bench {denoiser}", unit="block", disable=None) as bar:
        result = run_benchmark(noisy_b, gt_b, denoiser, metas=metas, renderer=renderer,
                               cfa=None if metas else cfa, progress=lambda d, t: bar.update(1))
    r, s = result.raw, result.srgb
    line = f"{result.denoiser}: "
    if r:
        line += f"raw PSNR {r['psnr']:.2f} dB SSIM {r['ssim']:.4f}; "
    if s:
        line += f"sRGB PSNR {s['psnr']:.2f} dB SSIM {s['ssim']:.4f}; "
    line += f"{result.seconds_per_mp:.3g} s/MP over {len(result.per_block)} blocks"
    typer.echo(line)
    if json_out:
        result.write_json(json_out)
    if csv_out:
        result.write_csv(csv_out)
    if leaderboard:
        from ..denoise.benchmark import update_leaderboard

        update_leaderboard(leaderboard, result)


def register(app: typer.Typer) -> None:
    app.command("bench")(bench)
