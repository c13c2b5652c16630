"""``simcam flow ...``: Noise Flow training and ONNX export (needs the torch extra)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

flow_app = typer.Typer(help="Noise Flow: train on noisy/clean pairs, export to ONNX.", no_args_is_help=True)


@flow_app.command("export")
def export(
    ckpt: Optional[Path] = typer.Argument(None, help="Checkpoint written by `simcam flow train` (.pt)."),
    out: Path = typer.Option(..., "--out", "-o", help="Sampler path (.onnx); the likelihood goes to <stem>.loglik.onnx."),
    published_npz: Optional[Path] = typer.Option(
        None, "--published-npz", help="Export the authors' released weights (CC BY-NC-SA 4.0: never redistribute)."
    ),
    temperature: Optional[float] = typer.Option(None, "--temperature", help="Default sampling temperature stored in the metadata."),
) -> None:
    """Export a Noise Flow to ONNX: model.onnx (sampler) and model.loglik.onnx."""
    from ..errors import NoiseModelError
    from ..noise.flow.export import export_onnx
    from ..noise.flow.model import NoiseFlow

    if (ckpt is None) == (published_npz is None):
        raise NoiseModelError("flow export: give exactly one of CKPT or --published-npz PATH")
    if published_npz is not None:
        from ..noise.flow.published import load_published

        flow = load_published(published_npz)
        source = "BorealisAI/noise_flow released weights, CC BY-NC-SA 4.0 (non-commercial; do not redistribute)"
    else:
        flow, _ = NoiseFlow.load(ckpt)
        source = f"simcam checkpoint {ckpt.name}"
    if temperature is not None:
        if not temperature > 0:
            raise NoiseModelError(f"--temperature: expected a positive number, got {temperature}")
        flow.config.default_temperature = float(temperature)
    for p in (ckpt, published_npz):
        if p is not None and Path(out).resolve() == Path(p).resolve():
            raise NoiseModelError(f"--out {out}: would overwrite the input {p}")
    sampler, loglik = export_onnx(flow, out, source=source)
    typer.echo(f"wrote {sampler} and {loglik} (cameras {flow.config.cameras}, ISO {flow.config.iso_range[0]:g}..{flow.config.iso_range[1]:g})")


def register(app: typer.Typer) -> None:
    app.add_typer(flow_app, name="flow")
