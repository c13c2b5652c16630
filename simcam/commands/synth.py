"""``simcam synth``: noisy raw DNG frames from a clean image and a calibration profile."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer


def synth_cmd(
    clean: Path = typer.Argument(..., help="Clean input: DNG, or 16-bit / float32 TIFF or PNG."),
    output: Path = typer.Option(..., "-o", "--output", help="Output folder (clean.dng, frame_000.dng, ...)."),
    profile: Path = typer.Option(..., "--profile", help="Calibration profile YAML."),
    iso: float = typer.Option(..., "--iso", help="ISO (interpolated in log-ISO between calibrated ISOs)."),
    camera: Optional[str] = typer.Option(None, "--camera", help="Camera id in the profile (needed if it holds several)."),
    frames: int = typer.Option(1, "--frames", min=1, help="Number of noisy frames."),
    seed: int = typer.Option(0, "--seed", help="Seed: frame i uses SeedSequence([seed, 0, i])."),
    as_: str = typer.Option("raw", "--as", help="TIFF/PNG meaning: 'raw' (normalised raw mosaic) or 'linear-srgb'."),
    cfa: Optional[str] = typer.Option(None, "--cfa", help="Bayer pattern for TIFF/PNG input (default: profile's, else RGGB)."),
    sensor_seed: Optional[int] = typer.Option(None, "--sensor-seed", help="Seed of fixed-pattern effects (composite models)."),
    extrapolate: bool = typer.Option(False, "--extrapolate", help="Allow an ISO outside the calibrated range (warns)."),
) -> None:
    """Write OUT/clean.dng and OUT/frame_000.dng ... with noise from PROFILE at ISO."""
    from tqdm import tqdm

    from ..synth import load_clean, synth
    from ..profiles.schema import load_profile
    from ..stages.noise import Noise

    prof = load_profile(profile)
    cam = prof.camera(camera)
    stage = Noise(profile=str(profile), iso=float(iso), camera=cam.id, extrapolate=extrapolate,
                  sensor_seed=sensor_seed)
    frame = load_clean(clean, as_=as_, profile=prof, camera=cam.id, iso=iso, cfa=cfa)
    paths = synth(frame, output, stage=stage, frames=frames, seed=seed, protect=(clean, profile),
                  progress=lambda it: tqdm(it, desc="synth", unit="frame", disable=None))
    typer.echo(f"wrote {len(paths)} DNGs to {output} ({frame.width}x{frame.height}, {cam.id} ISO {iso:g}, "
               f"model {stage.model.type}, seed {seed})")


def register(app: typer.Typer) -> None:
    app.command("synth")(synth_cmd)
