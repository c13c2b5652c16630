"""``simcam info FILE``: print the parsed camera metadata of a DNG or a SIDD .MAT file."""

from __future__ import annotations

from pathlib import Path

import typer


def read_any_meta(path: Path):
    """CameraMeta of a DNG (``read_dng_meta``) or a SIDD metadata .MAT (``read_sidd_meta``)."""
    if path.suffix.lower() == ".mat":
        from ..io.sidd import read_sidd_meta

        return read_sidd_meta(path)
    from ..io.dng import read_dng_meta

    return read_dng_meta(path)


def _fmt(value) -> str:
    import json

    return json.dumps(value, default=str)


def format_meta(d: dict) -> list[str]:
    """Human-readable lines of ``CameraMeta.to_dict()`` (opcodes one per line, GainMaps summarised)."""
    lines = []
    for key, value in d.items():
        if key.startswith("opcode_list"):
            lines.append(f"{key}: {len(value)} opcode(s)")
            for k, op in enumerate(value):
                desc = f"  [{k}] {op['name']} (id {op['id']}, flags {op['flags']}, {op['bytes']} bytes)"
                gm = op.get("gain_map")
                if gm:
                    desc += (f" rect {gm['rect']} plane {gm['plane']}/{gm['planes']} pitch {gm['pitch']} "
                             f"points {gm['map_points']} spacing [{gm['spacing'][0]:.6g}, {gm['spacing'][1]:.6g}] "
                             f"origin {gm['origin']} gain {gm['gain_min']:.4f}..{gm['gain_max']:.4f}")
                lines.append(desc)
        elif key == "extra":
            for k, v in value.items():
                lines.append(f"extra.{k}: {_fmt(v)}")
        elif isinstance(value, list) and len(value) > 16 and all(isinstance(v, (int, float)) for v in value):
            lines.append(f"{key}: [{len(value)} values, {min(value):.6g}..{max(value):.6g}]")
        else:
            lines.append(f"{key}: {_fmt(value)}")
    return lines


def info(
    file: Path = typer.Argument(..., metavar="FILE", help="A DNG file or a SIDD *_METADATA_RAW_*.MAT file."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON instead of text."),
) -> None:
    """Print every parsed metadata field of a DNG (or SIDD .MAT) file."""
    import json

    meta = read_any_meta(file)
    d = meta.to_dict()
    if as_json:
        typer.echo(json.dumps(d, indent=2, default=str))
    else:
        typer.echo("\n".join(format_meta(d)))


def register(app: typer.Typer) -> None:
    app.command("info")(info)
