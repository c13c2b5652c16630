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
    denoiser: list[str] = typer.Option(["none"], "--denoiser", "-d",
                                       help="none | bm3d[:vst|:mean] | nlm | dncnn:CKPT | cmd:'PROG {input} {output}' | "
                                            "python:MODULE:FUNC; repeatable (several: one result each)."),
    cfa: str = typer.Option("RGGB", "--cfa", help="CFA pattern of the blocks when no --metadata is given."),
    images: Optional[int] = typer.Option(None, "--images", help="Use only the first N images."),
    blocks: Optional[int] = typer.Option(None, "--blocks", help="Use only the first M blocks of each image."),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write the result as JSON."),
    csv_out: Optional[Path] = typer.Option(None, "--csv", help="Write per-block scores as CSV."),
    leaderboard: Optional[Path] = typer.Option(None, "--leaderboard", help="Add the result to a Markdown leaderboard file."),
    workers: Optional[int] = typer.Option(None, "--workers", min=0,
                                          help="Run images x denoisers as a dask batch with N worker processes "
                                               "(0: serial items; default: one process, no batch)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Batch: dask scheduler address."),
) -> None:
    """Denoise SIDD-format blocks and report PSNR/SSIM (raw, sRGB) and seconds per megapixel."""
    from ..dataset.benchmark import load_metadata_dir, pipeline_renderer, run_benchmark
    from ..errors import DatasetError
    from ..io.sidd_blocks import read_blocks, read_pair_folder

    from ..io.outputs import check_output_file

    for o, opt in ((json_out, "--json"), (csv_out, "--csv")):
        if o is not None:
            check_output_file(o, option=opt, inputs=(noisy, gt))
    if leaderboard is not None:
        check_output_file(leaderboard, option="--leaderboard", inputs=(noisy, gt))
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
    if workers is None and scheduler is None:
        from tqdm import tqdm

        total = sum(len(b) for b in noisy_b)
        results = []
        for d in denoiser:
            with tqdm(total=total, desc=f"bench {d}", unit="block", disable=None) as bar:
                results.append(run_benchmark(noisy_b, gt_b, d, metas=metas, renderer=renderer,
                                             cfa=None if metas else cfa, progress=lambda done, t: bar.update(1)))
        failed = 0
    else:
        results, failed = _bench_batch(noisy_b, gt_b, denoiser, metas, pipeline, cfa, workers, scheduler)
    for result in results:
        r, s = result.raw, result.srgb
        line = f"{result.denoiser}: "
        if r:
            line += f"raw PSNR {r['psnr']:.2f} dB SSIM {r['ssim']:.4f}; "
        if s:
            line += f"sRGB PSNR {s['psnr']:.2f} dB SSIM {s['ssim']:.4f}; "
        line += f"{result.seconds_per_mp:.3g} s/MP over {len(result.per_block)} blocks"
        typer.echo(line)
    if json_out:
        if len(results) == 1:
            results[0].write_json(json_out)
        else:
            import json

            json_out.write_text(json.dumps({"results": [r.to_dict() for r in results]}, indent=1) + "\n")
    if csv_out:
        _write_csv(csv_out, results)
    if leaderboard:
        from ..dataset.benchmark import update_leaderboard

        for result in results:
            update_leaderboard(leaderboard, result)
    if failed:
        raise typer.Exit(1)


def _write_csv(path: Path, results) -> None:
    if len(results) == 1:
        results[0].write_csv(path)
        return
    import csv

    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["denoiser", "image", "block", "psnr_raw", "ssim_raw", "psnr_srgb", "ssim_srgb", "seconds"])
        for res in results:
            for b in res.per_block:
                w.writerow([res.denoiser, b.image, b.block] + ["" if v is None else f"{v:.6g}" for v in
                                                               (b.psnr_raw, b.ssim_raw, b.psnr_srgb, b.ssim_srgb,
                                                                b.seconds)])


def _bench_batch(noisy_b, gt_b, denoisers, metas, pipeline, cfa, workers, scheduler):
    """Images x denoisers as a dask batch; returns the merged result per denoiser that fully ran and
    the number of failed items (each reported in one line)."""
    from ..batch import BatchConfig, Task, report, run_batch
    from ..dataset.benchmark import merge_results
    from ..jobs import bench_job

    tasks = [Task(f"{d} on image {i}", {"noisy": nb, "gt": gb, "denoiser": d,
                                        "meta": None if metas is None else metas[i], "pipeline": pipeline,
                                        "cfa": cfa})
             for d in denoisers for i, (nb, gb) in enumerate(zip(noisy_b, gt_b))]
    outcomes = run_batch(bench_job, tasks, BatchConfig(workers=workers, scheduler=scheduler), label="bench")
    n_img = len(noisy_b)
    results = []
    for k, d in enumerate(denoisers):
        mine = outcomes[k * n_img:(k + 1) * n_img]
        if all(o.ok for o in mine):
            results.append(merge_results([o.info["result"] for o in mine], list(range(n_img))))
    return results, report(outcomes, command="simcam bench")


def register(app: typer.Typer) -> None:
    app.command("bench")(bench)
