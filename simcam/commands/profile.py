"""``simcam profile``: build calibration profiles (``import-darktable``, ``from-dng``) and ``show`` one."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

profile_app = typer.Typer(help="Noise calibration profiles: import, inspect.", no_args_is_help=True,
                          rich_markup_mode=None)


def _check(output: Optional[Path], inputs: tuple[Path, ...]) -> None:
    from ..io.outputs import check_output_file

    if output is not None:
        check_output_file(output, option="-o", inputs=inputs, suffixes=(".yaml", ".yml"))


def _emit(prof, output: Optional[Path]) -> None:
    notes = getattr(prof.provenance, "notes", "") or ""
    for note in notes.split("; "):
        if " skipped: " in note:
            typer.echo(f"note: {note}", err=True)
    if output is None:
        typer.echo(prof.to_yaml(), nl=False)
        return
    prof.save(output)
    cam = prof.cameras[0]
    typer.echo(f"wrote {output} (camera {cam.id!r}, {len(cam.entries)} ISO entries "
               f"{cam.iso_range[0]:g}..{cam.iso_range[1]:g})")


@profile_app.command("import-darktable")
def import_darktable_cmd(
    file: Path = typer.Argument(..., metavar="FILE", help="darktable noiseprofiles.json"),
    camera: str = typer.Option(..., "--camera", help='Camera as darktable names it: "MAKE MODEL", e.g. "Sony ILCE-7M3".'),
    cfa: str = typer.Option("RGGB", "--cfa", help="Bayer pattern that maps the per-colour values to CFA sites."),
    camera_id: Optional[str] = typer.Option(None, "--id", help="Camera id in the profile (default: MAKE MODEL)."),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="Profile YAML to write (default: stdout)."),
) -> None:
    """Convert a darktable noise profile (a, b per RGB) to a simcam profile (nlf per ISO)."""
    from ..noise.importers import import_darktable

    _check(output, (file,))
    _emit(import_darktable(file, camera, cfa=cfa, camera_id=camera_id), output)


@profile_app.command("from-dng")
def from_dng_cmd(
    file: Path = typer.Argument(..., metavar="FILE", help="DNG with a NoiseProfile tag."),
    camera_id: Optional[str] = typer.Option(None, "--id", help="Camera id in the profile (default: MAKE MODEL)."),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="Profile YAML to write (default: stdout)."),
) -> None:
    """Build a one-ISO profile from a DNG's NoiseProfile tag."""
    from ..noise.importers import profile_from_dng

    _check(output, (file,))
    _emit(profile_from_dng(file, camera_id=camera_id), output)


@profile_app.command("show")
def show_cmd(
    file: Path = typer.Argument(..., metavar="FILE", help="Profile YAML."),
    iso: Optional[float] = typer.Option(None, "--iso", help="Print the (interpolated) model at this ISO."),
    camera: Optional[str] = typer.Option(None, "--camera", help="Camera id."),
    extrapolate: bool = typer.Option(False, "--extrapolate", help="Allow ISOs outside the calibrated range."),
) -> None:
    """Validate a profile and list its cameras, or print the model at one ISO."""
    import yaml

    from ..profiles import load_profile

    prof = load_profile(file)
    if iso is None:
        for cam in prof.cameras:
            types = sorted({e.model["type"] for e in cam.entries})
            typer.echo(f"{cam.id}: {cam.make} {cam.model}, cfa {cam.cfa}, ISO {cam.iso_range[0]:g}..{cam.iso_range[1]:g} "
                       f"({len(cam.entries)} entries, {', '.join(types)})")
        return
    model = prof.model_for(iso, camera, extrapolate=extrapolate)
    typer.echo(yaml.safe_dump(model.to_entry(), sort_keys=False), nl=False)


def register(app: typer.Typer) -> None:
    app.add_typer(profile_app, name="profile")
