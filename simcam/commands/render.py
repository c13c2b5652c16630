"""``simcam render`` and ``simcam validate``."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer


def parse_set_options(items: list[str] | None) -> dict:
    """``["white_balance.neutral=[0.66,1.0,0.44]", ...]`` -> ``{"white_balance.neutral": [...]}``.

    Values are parsed as YAML (so lists, numbers, booleans and strings work).
    """
    import yaml

    from ..errors import PipelineError

    out = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise PipelineError(f"--set {item!r}: expected STAGE.PARAM=VALUE")
        try:
            out[key.strip()] = yaml.safe_load(value)
        except yaml.YAMLError:
            raise PipelineError(f"--set {item!r}: VALUE is not valid YAML") from None
    return out


def render(
    input: Path = typer.Argument(..., help="Input DNG file."),
    output: Path = typer.Option(..., "-o", "--output", help="Output image (.png, .tif/.tiff, .exr)."),
    pipeline: str = typer.Option("srgb", "--pipeline", "-p", help="Pipeline YAML file or built-in name."),
    set_: Optional[list[str]] = typer.Option(None, "--set", help="Override STAGE.PARAM=VALUE (YAML value); repeatable."),
    depth: Optional[str] = typer.Option(None, "--depth", help="8, 16, 32 (float) or half; default by format."),
    seed: int = typer.Option(0, "--seed", help="Seed for random stages (noise)."),
    quality: int = typer.Option(95, "--quality", help="JPEG quality 1..100."),
    compression: Optional[str] = typer.Option(
        None, "--compression", help="TIFF: none (default), zip[:N], lzw; PNG: zip:N (default zip:1); EXR: none (default), zips, piz, ..."),
    thumbnail: Optional[Path] = typer.Option(None, "--thumbnail", help="Also write a small 8-bit preview (.jpg or .png)."),
) -> None:
    """Render a raw DNG through a pipeline to PNG / JPEG / TIFF / EXR (colour-tagged, with the camera's EXIF)."""
    from ..io.images import resolve_compression, resolve_depth, write_image
    from ..pipeline import Pipeline
    from ..render import render_samples

    overrides = parse_set_options(set_)
    dtype = resolve_depth(output, depth)  # fail on a bad format before any work
    resolve_compression(output, compression)
    pipe = Pipeline.from_yaml(pipeline)
    from ..io.dng import read_dng

    if overrides:
        pipe = pipe.with_overrides(overrides)
    frame = read_dng(input)
    out = render_samples(pipe, frame, dtype, seed=seed)
    write_image(output, out, depth=dtype, protect=(input,), compression=compression, quality=quality,
                thumbnail=thumbnail)
    h, w = out.samples.shape[:2]
    typer.echo(f"wrote {output} ({w}x{h}, {out.kind}, pipeline {pipe.name or pipe.source})")


def validate(pipeline: Path = typer.Argument(..., help="Pipeline YAML file.")) -> None:
    """Check a pipeline file: stage types, parameters and order."""
    from ..pipeline import Pipeline

    pipe = Pipeline.from_yaml(pipeline)
    typer.echo(f"{pipeline}: ok ({len(pipe.stages)} stages, {pipe.input_kind} -> {pipe.output_kind})")


def register(app: typer.Typer) -> None:
    app.command("render")(render)
    app.command("validate")(validate)
