"""``simcam flow ...``: Noise Flow training and ONNX export (needs the torch extra)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

flow_app = typer.Typer(help="Noise Flow: train on noisy/clean pairs, export to ONNX.", no_args_is_help=True,
                       rich_markup_mode=None)


@flow_app.command("export")
def export(
    ckpt: Optional[Path] = typer.Argument(None, metavar="CKPT", help="Checkpoint written by `simcam flow train` (.pt)."),
    out: Path = typer.Option(..., "--out", "-o", help="Sampler path (.onnx); the likelihood goes to <stem>.loglik.onnx."),
    published_npz: Optional[Path] = typer.Option(
        None, "--published-npz", help="Export the authors' released weights (CC BY-NC-SA 4.0: never redistribute)."
    ),
    temperature: Optional[float] = typer.Option(None, "--temperature", help="Default sampling temperature stored in the metadata."),
    legacy_iso: bool = typer.Option(
        False, "--legacy-iso",
        help="Reproduce the released code's ISO handling (factor 1 for ISOs other than its five) instead of log-ISO interpolation."),
) -> None:
    """Export a Noise Flow to ONNX: model.onnx (sampler) and model.loglik.onnx."""
    from ..errors import NoiseModelError
    from ..noise.flow.export import export_onnx
    from ..noise.flow.model import NoiseFlow

    from ..io.outputs import check_output_file

    if (ckpt is None) == (published_npz is None):
        raise NoiseModelError("flow export: give exactly one of CKPT or --published-npz PATH")
    check_output_file(out, option="--out", inputs=(ckpt, published_npz), suffixes=(".onnx",))
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
    sampler, loglik = export_onnx(flow, out, source=source, legacy_iso=legacy_iso)
    typer.echo(f"wrote {sampler} and {loglik} (cameras {flow.config.cameras}, ISO {flow.config.iso_range[0]:g}..{flow.config.iso_range[1]:g})")


@flow_app.command("train")
def train(
    data: Path = typer.Argument(..., metavar="DATA", help="Patch set .npz (clean, noise|noisy, iso, camera), a folder of SIDD .MAT pairs, or a folder of DNG bursts (frames + clean.dng or gt.npz)."),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder: last.pt, best.pt, metrics.csv, metrics.png."),
    epochs: int = typer.Option(10, "--epochs", min=1, help="Training epochs (total, also when resuming)."),
    batch_size: int = typer.Option(64, "--batch-size", min=1, help="Patches per Adam step."),
    lr: float = typer.Option(1e-3, "--lr", help="Adam learning rate (betas 0.9, 0.999)."),
    arch: str = typer.Option("paper", "--arch", help="paper (Noise Flow, ICCV 2019) or published (the released code)."),
    sdn_per_iso: bool = typer.Option(True, "--sdn-per-iso/--sdn-global", help="paper arch: beta1, beta2 per camera and ISO."),
    data_init: bool = typer.Option(True, "--data-init/--no-data-init", help="Start from a least-squares NLF fit."),
    test_fraction: float = typer.Option(0.2, "--test-fraction", help="Share of patches held out for the test NLL and KL."),
    seed: int = typer.Option(0, "--seed", help="Seed of the split, the initialisation and the batch order."),
    resume: bool = typer.Option(False, "--resume", help="Continue from OUT/last.pt."),
    threads: Optional[int] = typer.Option(None, "--threads", help="torch intra-op threads."),
    patches_per_image: int = typer.Option(64, "--patches-per-image", help="SIDD folders: 32x32 packed patches per image."),
    reference_nlf: Optional[Path] = typer.Option(None, "--reference-nlf", help="CAM_ISO,beta1,beta2 table: also report its test NLL/dim."),
) -> None:
    """Train a Noise Flow on noisy/clean pairs (Adam, NLL; per-epoch test NLL/dim and marginal KL)."""
    from ..noise.flow.data import load_data, nlf_nll_per_dim, read_nlf_table
    from ..errors import NoiseModelError
    from ..noise.flow.model import ARCHS
    from ..noise.flow.train import train as run

    if arch not in ARCHS:
        raise NoiseModelError(f"--arch {arch!r}: expected one of {list(ARCHS)}")
    if not 0 < test_fraction < 1:
        raise NoiseModelError(f"--test-fraction {test_fraction}: expected a share in (0, 1)")

    from ..io.outputs import check_output_dir

    check_output_dir(out, option="--out", inputs=(data, reference_nlf))
    ps = load_data(data, patches_per_image=patches_per_image) if data.is_dir() else load_data(data)
    ref = None
    if reference_nlf is not None:
        table = read_nlf_table(reference_nlf)
        ref = lambda te: nlf_nll_per_dim(te, table)  # noqa: E731
    row = run(ps, out, arch=arch, sdn_per_iso=sdn_per_iso, epochs=epochs, batch_size=batch_size, lr=lr, seed=seed,
              test_fraction=test_fraction, resume=resume, threads=threads, data_init=data_init, reference_nll=ref)
    if row:
        typer.echo(f"{out}: epoch {row['epoch']} test NLL/dim {row['test_nll_per_dim']:.4f} nats, "
                   f"marginal KL {row['test_marginal_kl']:.5f}")
    else:
        typer.echo(f"{out}: nothing to do (already at epoch {epochs})")


@flow_app.command("synth-nlf")
def synth_nlf(
    nlf: Path = typer.Argument(..., metavar="NLF", help="Table of CAM_ISO,beta1,beta2 rows (e.g. profiles/sidd_pixel_nlf.csv)."),
    out: Path = typer.Option(..., "--out", "-o", help="Patch set to write (.npz)."),
    n_per: int = typer.Option(1000, "--n-per", min=2, help="Patches per (camera, ISO)."),
    cameras: Optional[str] = typer.Option(None, "--cameras", help="Comma-separated, e.g. GP."),
    isos: Optional[str] = typer.Option(None, "--isos", help="Comma-separated, e.g. 100,400,800,1600."),
    size: int = typer.Option(32, "--size", help="Packed patch side."),
    seed: int = typer.Option(0, "--seed", help="Seed of the clean levels and the noise."),
) -> None:
    """Synthesise noisy/clean pairs from an NLF table: noise ~ N(0, beta1*clean + beta2)."""
    from ..errors import DatasetError
    from ..noise.flow.data import read_nlf_table, save_npz, synthesize_nlf_pairs

    from ..io.outputs import check_output_file

    check_output_file(out, option="--out", inputs=(nlf,), suffixes=(".npz",))
    table = read_nlf_table(nlf)
    cams = cameras.split(",") if cameras else None
    try:
        iso_list = [float(i) for i in isos.split(",")] if isos else None
    except ValueError:
        raise DatasetError(f"--isos {isos!r}: expected comma-separated numbers") from None
    ps = synthesize_nlf_pairs(table, n_per, size=size, seed=seed, cameras=cams, isos=iso_list)
    save_npz(out, ps)
    typer.echo(f"wrote {out} ({ps['clean'].shape[0]} patches of {size}x{size}x4)")


def register(app: typer.Typer) -> None:
    app.add_typer(flow_app, name="flow")
