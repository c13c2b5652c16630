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
    input: Path = typer.Argument(..., metavar="INPUT", help="Input DNG file."),
    output: Path = typer.Option(..., "-o", "--output", help="Output image (.png, .tif/.tiff, .exr)."),
    pipeline: str = typer.Option("srgb", "--pipeline", "-p", help="Pipeline YAML file or built-in name."),
    set_: Optional[list[str]] = typer.Option(None, "--set", help="Override STAGE.PARAM=VALUE (YAML value); repeatable."),
    depth: Optional[str] = typer.Option(None, "--depth", help="8, 16, 32 (float) or half; default by format."),
    seed: int = typer.Option(0, "--seed", help="Seed for random stages (noise)."),
) -> None:
    """Render a raw DNG through a pipeline to PNG / TIFF / EXR."""
    from ..io.images import resolve_depth, write_image
    from ..pipeline import Pipeline

    from ..io.outputs import check_output_file

    overrides = parse_set_options(set_)
    check_output_file(output, option="-o", inputs=(input,))
    resolve_depth(output, depth)  # fail on a bad format before any work
    pipe = Pipeline.from_yaml(pipeline)
    from ..io.dng import read_dng

    if overrides:
        pipe = pipe.with_overrides(overrides)
    frame = read_dng(input)
    from tqdm import tqdm

    # a bar for large frames on a terminal only (disable=None: silent when stderr is not a TTY)
    with tqdm(total=len(pipe.stages), desc=f"render {input.name}", unit="stage", leave=False,
              disable=None if frame.width * frame.height >= 4_000_000 else True) as bar:
        out = pipe(frame, seed=seed, progress=lambda name: (bar.set_postfix_str(name), bar.update(1)))
    write_image(output, out.data, depth=depth, protect=(input,))
    typer.echo(f"wrote {output} ({out.width}x{out.height}, {out.kind}, pipeline {pipe.name or pipe.source})")


def validate(pipeline: Path = typer.Argument(..., metavar="PIPELINE", help="Pipeline YAML file.")) -> None:
    """Check a pipeline file: stage types, parameters and order."""
    from ..pipeline import Pipeline

    pipe = Pipeline.from_yaml(pipeline)
    typer.echo(f"{pipeline}: ok ({len(pipe.stages)} stages, {pipe.input_kind} -> {pipe.output_kind})")


def register(app: typer.Typer) -> None:
    app.command("render")(render)
    app.command("validate")(validate)
