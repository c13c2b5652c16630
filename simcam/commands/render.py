"""``simcam render`` and ``simcam validate``."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer


def parse_set_options(items: list[str] | None) -> dict:
    """``["white_balance.neutral=[0.66,1.0,0.44]", ...]`` -> ``{"white_balance.neutral": [...]}``.

    Values are parsed as YAML (so lists, numbers, booleans and strings work).
    """
    from ..errors import PipelineError
    from ..yamlio import load_yaml

    out = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise PipelineError(f"--set {item!r}: expected STAGE.PARAM=VALUE")
        out[key.strip()] = load_yaml(value, source=f"--set {item!r}: VALUE", error=PipelineError)
    return out


def render(
    inputs: list[Path] = typer.Argument(..., metavar="INPUT...",
                                        help="DNG files, folders of DNGs or glob patterns ('raw/*.dng')."),
    output: Path = typer.Option(..., "-o", "--output",
                                help="Output image (.png, .tif/.tiff, .exr, .jpg) for one input; the output folder "
                                     "when there are several inputs, a folder or a pattern."),
    pipeline: str = typer.Option("srgb", "--pipeline", "-p", help="Pipeline YAML file or built-in name."),
    set_: Optional[list[str]] = typer.Option(None, "--set", help="Override STAGE.PARAM=VALUE (YAML value); repeatable."),
    depth: Optional[str] = typer.Option(None, "--depth", help="8, 16, 32 (float) or half; default by format."),
    seed: int = typer.Option(0, "--seed", help="Seed for random stages (noise); item i uses SeedSequence([seed, 0, i])."),
    fmt: str = typer.Option("png", "--format", help="Batch: output format (png, tif, exr, jpg)."),
    workers: Optional[int] = typer.Option(None, "--workers", min=0,
                                          help="Batch: dask worker processes (default: one per core; 0: serial)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler",
                                            help="Batch: dask scheduler address (default $DASK_SCHEDULER_ADDRESS, "
                                                 "else a local cluster)."),
    resume: bool = typer.Option(False, "--resume", help="Batch: skip inputs whose output exists."),
    quality: int = typer.Option(95, "--quality", help="JPEG quality 1..100."),
    compression: Optional[str] = typer.Option(
        None, "--compression",
        help="TIFF: none (default), zip[:N], lzw; PNG: zip:N (zlib level, default 1); EXR: none (default), zips, piz, ..."),
    thumbnail: Optional[Path] = typer.Option(None, "--thumbnail",
                                             help="Also write a small 8-bit preview (.jpg or .png); one input only."),
) -> None:
    """Render raw DNGs through a pipeline to PNG / TIFF / EXR / JPEG (one file, or a batch on dask)."""
    from ..io.inputs import is_pattern

    batch = (len(inputs) > 1 or any(is_pattern(i) or Path(i).is_dir() for i in inputs)
             or output.is_dir() or not output.suffix)
    reading = warming = None
    if batch:  # the workers' fork server imports while this process reads the pipeline and lists the inputs
        from ..batch import BatchConfig, start_workers_early
        from ..jobs import render_job

        start_workers_early(render_job, BatchConfig(workers=workers, scheduler=scheduler))
    else:  # LibRaw decodes the DNG (C code, the GIL released) while this process imports and builds
        from concurrent.futures import ThreadPoolExecutor

        from ..io.dng import read_dng

        reading = ThreadPoolExecutor(1, thread_name_prefix="simcam-read")
        frame_read = reading.submit(read_dng, inputs[0])
    try:
        from ..io.outputs import check_output_file
        from ..jobs import render_file
        from ..pipeline import Pipeline

        overrides = parse_set_options(set_)
        if not batch:
            from ..io.images import resolve_compression, resolve_depth

            check_output_file(output, option="-o", inputs=inputs)
            resolve_depth(output, depth)  # fail on a bad format before any work
            resolve_compression(output, compression)
        pipe = Pipeline.from_yaml(pipeline)
        if overrides:
            pipe = pipe.with_overrides(overrides)
        if batch:
            if thumbnail is not None:
                from ..errors import SimcamError

                raise SimcamError(f"--thumbnail {thumbnail}: expected one input and one output file, not a batch")
            raise typer.Exit(_render_batch(inputs, output, pipe, depth=depth, seed=seed, fmt=fmt, workers=workers,
                                           scheduler=scheduler, resume=resume,
                                           write={"quality": quality, "compression": compression}))
        from tqdm import tqdm

        warming = pipe.warm_in_background()  # e.g. numba's set-up for Menon 2007, while the DNG is decoded
        frame = frame_read.result()  # the reader's errors, after those of the options and the pipeline
        # a bar for large frames on a terminal only (disable=None: silent when stderr is not a TTY)
        with tqdm(total=len(pipe.stages), desc=f"render {inputs[0].name}", unit="stage", leave=False,
                  disable=None if frame.width * frame.height >= 4_000_000 else True) as bar:
            info = render_file(inputs[0], output, pipeline=pipe, depth=depth, seed=seed, frame=frame,
                               progress=lambda name: (bar.set_postfix_str(name), bar.update(1)),
                               quality=quality, compression=compression, thumbnail=thumbnail)
    finally:  # the reader done (its capture of fd 2 over) before an error line is printed
        if reading is not None:
            reading.shutdown(wait=True)
        if warming is not None:
            warming.join()
    typer.echo(f"wrote {output} ({info['width']}x{info['height']}, {info['kind']}, pipeline {pipe.name or pipe.source})")


def _render_batch(inputs, out_dir: Path, pipe, *, depth, seed, fmt, workers, scheduler, resume,
                  write: dict | None = None) -> int:
    from ..batch import BatchConfig, Task, report, run_batch
    from ..errors import SimcamError
    from ..io.images import resolve_compression, resolve_depth
    from ..io.inputs import expand_inputs
    from ..io.outputs import check_output_dir
    from ..jobs import render_job

    config = BatchConfig(workers=workers, scheduler=scheduler, resume=resume)
    files = expand_inputs(inputs, suffixes=(".dng",), what="DNG")
    check_output_dir(out_dir, option="-o", inputs=files)
    ext = "." + fmt.lower().lstrip(".")
    resolve_depth(out_dir / f"x{ext}", depth)  # fail on a bad format before any work
    resolve_compression(out_dir / f"x{ext}", (write or {}).get("compression"))
    stems: dict[str, Path] = {}
    for f in files:
        if f.stem in stems:
            raise SimcamError(f"{f}: same name as {stems[f.stem]}; both would write {out_dir / (f.stem + ext)}")
        stems[f.stem] = f
    out_dir.mkdir(parents=True, exist_ok=True)
    doc = pipe.to_dict()
    tasks = [Task(str(f), {"input": str(f), "output": str(out_dir / f"{f.stem}{ext}"), "pipeline": doc,
                           "depth": depth, "seed": seed, "index": i, **(write or {})}, outputs=(str(out_dir / f"{f.stem}{ext}"),))
             for i, f in enumerate(files)]
    outcomes = run_batch(render_job, tasks, config, label="render")
    done = sum(o.ok and not o.skipped for o in outcomes)
    skipped = sum(o.skipped for o in outcomes)
    typer.echo(f"rendered {done} of {len(tasks)} DNGs into {out_dir}" + (f" ({skipped} already there)" if skipped else ""))
    return report(outcomes, command="simcam render")


def validate(pipeline: Path = typer.Argument(..., metavar="PIPELINE", help="Pipeline YAML file.")) -> None:
    """Check a pipeline file: stage types, parameters and order."""
    from ..pipeline import Pipeline

    pipe = Pipeline.from_yaml(pipeline)
    typer.echo(f"{pipeline}: ok ({len(pipe.stages)} stages, {pipe.input_kind} -> {pipe.output_kind})")


def register(app: typer.Typer) -> None:
    app.command("render")(render)
    app.command("validate")(validate)
