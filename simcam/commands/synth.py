"""``simcam synth``: noisy raw DNG frames from a clean image, or a training set from many."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer


def synth_cmd(
    clean: list[Path] = typer.Argument(..., metavar="CLEAN...",
                                       help="Clean input: DNG, or 16-bit / float32 TIFF or PNG. With -o SET.zarr: "
                                            "files, folders or glob patterns of clean raws."),
    output: Path = typer.Option(..., "-o", "--output",
                                help="Output folder (clean.dng, frame_000.dng, ...), or SET.zarr for a training "
                                     "set of packed noisy/clean patches (Zarr v3)."),
    profile: Path = typer.Option(..., "--profile", help="Calibration profile YAML."),
    iso: Optional[float] = typer.Option(None, "--iso", help="ISO (interpolated in log-ISO between calibrated ISOs)."),
    exposure: Optional[float] = typer.Option(None, "--exposure", min=0.0,
                                             help="Exposure time in seconds (exposure-dependent effects such as "
                                                  "dark_current; default: the clean DNG's ExposureTime)."),
    isos: Optional[str] = typer.Option(None, "--isos",
                                       help="Training set: comma-separated ISOs, one drawn per source (e.g. 100,800,3200)."),
    camera: Optional[str] = typer.Option(None, "--camera", help="Camera id in the profile (needed if it holds several)."),
    frames: int = typer.Option(1, "--frames", min=1, help="Number of noisy frames."),
    seed: int = typer.Option(0, "--seed", help="Seed: frame i uses SeedSequence([seed, 0, i]); training-set source i "
                                               "uses SeedSequence([seed, i])."),
    as_: str = typer.Option("raw", "--as", help="TIFF/PNG meaning: 'raw' (normalised raw mosaic) or 'linear-srgb'."),
    cfa: Optional[str] = typer.Option(None, "--cfa", help="Bayer pattern for TIFF/PNG input (default: profile's, else RGGB)."),
    sensor_seed: Optional[int] = typer.Option(None, "--sensor-seed", help="Seed of fixed-pattern effects (composite models)."),
    extrapolate: bool = typer.Option(False, "--extrapolate", help="Allow an ISO outside the calibrated range (warns)."),
    patches: int = typer.Option(64, "--patches-per-source", min=1, help="Training set: patches cropped per source."),
    patch_size: int = typer.Option(256, "--patch-size", min=2,
                                   help="Training set: patch side in mosaic pixels (even; stored packed 4 x P/2 x P/2)."),
    workers: Optional[int] = typer.Option(None, "--workers", min=0,
                                          help="Training set: dask worker processes (default: one per core; 0: serial)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Training set: dask scheduler address."),
    resume: bool = typer.Option(False, "--resume", help="Training set: keep the sources already written."),
) -> None:
    """Write OUT/clean.dng and OUT/frame_000.dng ... with noise from PROFILE at ISO, or a training set."""
    from ..errors import SimcamError

    if str(output).rstrip("/").endswith(".zarr"):
        iso_list = _iso_list(iso, isos)
        raise typer.Exit(_training_set(clean, output, profile=profile, isos=iso_list, exposure=exposure,
                                       camera=camera, seed=seed,
                                       as_=as_, cfa=cfa, sensor_seed=sensor_seed, extrapolate=extrapolate,
                                       patches=patches, patch_size=patch_size, workers=workers,
                                       scheduler=scheduler, resume=resume))
    if len(clean) != 1:
        raise SimcamError(f"CLEAN: {len(clean)} inputs; expected one clean image (or -o SET.zarr for a training set)")
    if iso is None:
        raise SimcamError("--iso: missing; expected the ISO to synthesise")
    from tqdm import tqdm

    from ..io.outputs import check_output_dir
    from ..profiles.schema import load_profile
    from ..synth import load_clean, synth
    from ..stages.noise import Noise

    clean_path = clean[0]
    check_output_dir(output, option="-o", inputs=(clean_path, profile))
    prof = load_profile(profile)
    cam = prof.camera(camera)
    stage = Noise(profile=str(profile), iso=float(iso), camera=cam.id, extrapolate=extrapolate,
                  sensor_seed=sensor_seed)
    notes: list[str] = []
    frame = load_clean(clean_path, as_=as_, profile=prof, camera=cam.id, iso=iso, cfa=cfa, notes=notes)
    if exposure is not None:
        frame = frame.evolve(meta=frame.meta.replace(exposure_time_s=float(exposure)))
    for note in notes:
        typer.echo(f"note: {note}", err=True)
    paths = synth(frame, output, stage=stage, frames=frames, seed=seed, protect=(clean_path, profile),
                  progress=lambda it: tqdm(it, desc="synth", unit="frame", disable=None))
    typer.echo(f"wrote {len(paths)} DNGs to {output} ({frame.width}x{frame.height}, {cam.id} ISO {iso:g}, "
               f"model {stage.model.type}, seed {seed})")


def _iso_list(iso: Optional[float], isos: Optional[str]) -> list[float]:
    from ..errors import SimcamError

    if (iso is None) == (isos is None):
        raise SimcamError("--iso / --isos: give exactly one (a training set draws one of --isos per source)")
    if iso is not None:
        return [float(iso)]
    try:
        out = [float(v) for v in isos.split(",") if v.strip()]
    except ValueError:
        raise SimcamError(f"--isos {isos!r}: expected comma-separated numbers") from None
    if not out or any(not v > 0 for v in out):
        raise SimcamError(f"--isos {isos!r}: expected positive ISOs")
    return out


def _training_set(inputs, output: Path, *, profile: Path, isos, exposure, camera, seed, as_, cfa, sensor_seed, extrapolate,
                  patches, patch_size, workers, scheduler, resume) -> int:
    from ..batch import BatchConfig, Task, report, run_batch, start_workers_early
    from ..errors import SimcamError
    from ..io.inputs import expand_inputs
    from ..io.outputs import check_output_dir
    from ..jobs import synth_patches_job
    from ..profiles.schema import load_profile
    from ..trainingset import create_store, write_manifest

    if patch_size % 2:
        raise SimcamError(f"--patch-size {patch_size}: expected an even number of mosaic pixels")
    config = BatchConfig(workers=workers, scheduler=scheduler, resume=resume)
    start_workers_early(synth_patches_job, config)
    sources = expand_inputs(inputs, suffixes=(".dng", ".tif", ".tiff", ".png"), what="clean image")
    check_output_dir(output, option="-o", inputs=[*sources, profile])
    if output.exists() and any(output.iterdir()) and not resume:
        raise SimcamError(f"{output}: -o: exists and is not empty; expected a new training set (or --resume)")
    prof = load_profile(profile)
    cam = prof.camera(camera)
    for v in isos:  # every ISO resolvable before any work
        prof.entry_for(v, cam.id, extrapolate=extrapolate)
    group = create_store(str(output), sources=[str(s) for s in sources], patches=patches, patch_size=patch_size,
                         overwrite=not resume)
    base = {"seed": seed, "profile": str(profile), "isos": isos, "exposure": exposure, "camera": cam.id, "extrapolate": extrapolate,
            "sensor_seed": sensor_seed, "as_": as_, "cfa": cfa, "patch_size": patch_size, "patches": patches,
            "store": str(output)}
    tasks = [Task(str(s), {**base, "source": str(s), "index": i},
                  outputs=(str(output / "noisy" / "c" / str(i) / "0" / "0" / "0"),))
             for i, s in enumerate(sources)]
    outcomes = run_batch(synth_patches_job, tasks, config, label="synth")
    items = []
    for i, (s, o) in enumerate(zip(sources, outcomes)):
        item = {"source": str(s), "rows": [i * patches, (i + 1) * patches], "ok": o.ok}
        if not o.ok:
            item["error"] = o.error
        items.append(item)
    write_manifest(group, {"seed": seed, "profile": str(profile), "camera": cam.id, "isos": isos,
                           "patch_size": patch_size, "patches_per_source": patches,
                           "packed_channels": "(0,0),(0,1),(1,0),(1,1) of an RGGB cell", "items": items})
    ok = sum(o.ok for o in outcomes)
    typer.echo(f"wrote {ok * patches} patches from {ok} of {len(sources)} sources to {output} "
               f"(4x{patch_size // 2}x{patch_size // 2} packed, ISOs {', '.join(f'{v:g}' for v in isos)})")
    return report(outcomes, command="simcam synth")


def register(app: typer.Typer) -> None:
    app.command("synth")(synth_cmd)
