"""ONNX export of a Noise Flow: a sampler graph and a likelihood graph.

``model.onnx`` (sampler): inputs ``clean`` f32 [B,4,H,W], ``z`` f32 [B,4,H,W],
``iso`` f32 [B], ``camera`` int64 [B]; output ``noise`` f32 [B,4,H,W].
``model.loglik.onnx`` (likelihood, same stem): inputs ``noise``, ``clean``, ``iso``,
``camera``; output ``loglik`` f32 [B] (nats per patch). Opset 17, dynamic B/H/W,
1x1-convolution inverses precomputed (no Inverse op), no random op (the latent is
an input), no boolean-mask indexing. ``metadata_props`` carry the keys read by
:mod:`simcam.noise.onnx_sampler` (:data:`~simcam.noise.onnx_sampler.META_KEYS`).
"""

from __future__ import annotations

import copy
import json
import warnings
from pathlib import Path

from ...errors import NoiseModelError, require_extra
from ..onnx_sampler import FORMAT, PACKING, loglik_path
from . import layers as L
from .model import NoiseFlow, log_normal


def _simcam_version() -> str:
    """The installed simcam version (written into the ONNX metadata)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("simcam")
    except PackageNotFoundError:  # a source tree that is not installed
        return "0+unknown"

torch = require_extra("torch", "torch")

OPSET = 17


class _Graph(torch.nn.Module):
    def __init__(self, flow: NoiseFlow):
        super().__init__()
        self.flow = flow

    def cond(self, clean, iso, camera):
        knots = self.flow.iso_knots.to(clean.dtype)
        return L.Cond(clean, iso, L.iso_weights(iso, knots, legacy=self.flow.config.legacy_iso), camera)


class SamplerGraph(_Graph):
    """``(clean, z, iso, camera) -> noise`` (latent -> noise direction)."""

    def forward(self, clean, z, iso, camera):
        return self.flow._from_latent(z, self.cond(clean, iso, camera))


class LoglikGraph(_Graph):
    """``(noise, clean, iso, camera) -> loglik`` (nats per patch)."""

    def forward(self, noise, clean, iso, camera):
        z, logdet = self.flow._to_latent(noise, self.cond(clean, iso, camera))
        return logdet + log_normal(z)


def metadata(flow: NoiseFlow, *, role: str, source: str) -> dict[str, str]:
    """The simcam metadata_props of an exported graph (all values are strings)."""
    cfg = flow.config
    return {
        "simcam_format": FORMAT,
        "simcam_version": _simcam_version(),
        "simcam_role": role,
        "packing_order": PACKING,
        "iso_min": repr(float(cfg.iso_range[0])),
        "iso_max": repr(float(cfg.iso_range[1])),
        "iso_knots": json.dumps([float(k) for k in cfg.iso_knots]),
        "cameras": json.dumps(list(cfg.cameras)),
        "default_temperature": repr(float(cfg.default_temperature)),
        "arch": cfg.arch,
        "iso_mode": "legacy-released" if cfg.legacy_iso else "log-interpolated",
        "source": source,
    }


def _export_one(module, args, names_in, names_out, path, meta):
    onnx = require_extra("onnx", "onnx")
    dyn = {n: {0: "B", 2: "H", 3: "W"} for n in names_in if n not in ("iso", "camera")}
    dyn.update({"iso": {0: "B"}, "camera": {0: "B"}})
    for n in names_out:
        dyn[n] = {0: "B", 2: "H", 3: "W"} if n == "noise" else {0: "B"}
    with warnings.catch_warnings():  # tracer chatter about constant shapes
        warnings.simplefilter("ignore")
        torch.onnx.export(
            module, args, str(path), input_names=names_in, output_names=names_out,
            dynamic_axes=dyn, opset_version=OPSET, dynamo=False, do_constant_folding=True,
        )
    model = onnx.load(str(path))
    del model.metadata_props[:]
    for k, v in meta.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = k, v
    model.producer_name = "simcam"
    model.producer_version = _simcam_version()
    onnx.checker.check_model(model)
    onnx.save(model, str(path))


def export_onnx(flow: NoiseFlow, out, *, source: str = "simcam", legacy_iso: bool = False) -> tuple[Path, Path]:
    """Write the sampler ``out`` and the likelihood graph beside it.

    Parameters
    ----------
    flow : NoiseFlow
        Model to export (copied; put in eval mode with frozen inverses).
    out : path-like
        Sampler path ending in ``.onnx``; the likelihood goes to ``<stem>.loglik.onnx``.
    source : str
        Provenance written to the metadata (e.g. the licence of published weights).
    legacy_iso : bool
        Reproduce the released code's ISO handling (one-hot on an exact knot, factor
        exp(0) = 1 for any other ISO; metadata ``iso_mode: legacy-released``) instead of
        log-ISO interpolation. Only for matching the authors' golden vectors.

    Returns
    -------
    (Path, Path)
        Sampler and likelihood paths.

    Examples
    --------
    >>> import tempfile
    >>> from simcam.noise.flow import FlowConfig, NoiseFlow
    >>> tiny = NoiseFlow(FlowConfig(cameras=["GP"], iso_knots=[100.0, 1600.0]))
    >>> sampler, loglik = export_onnx(tiny, tempfile.mkdtemp() + "/flow.onnx")
    >>> sampler.name, loglik.name
    ('flow.onnx', 'flow.loglik.onnx')
    """
    out = Path(out)
    if out.suffix != ".onnx":
        raise NoiseModelError(f"--out {out}: expected a path ending in .onnx")
    out.parent.mkdir(parents=True, exist_ok=True)
    flow = copy.deepcopy(flow).float().eval()
    flow.config = copy.deepcopy(flow.config)
    flow.config.legacy_iso = bool(legacy_iso)
    flow.freeze()
    b, h, w = 2, 8, 6
    g = torch.Generator().manual_seed(0)
    clean = torch.rand(b, 4, h, w, generator=g)
    x = 0.01 * torch.randn(b, 4, h, w, generator=g)
    lo, hi = flow.config.iso_range
    iso = torch.tensor([lo, hi], dtype=torch.float32)
    cam = torch.zeros(b, dtype=torch.int64)
    lpath = loglik_path(out)
    with torch.no_grad():
        _export_one(SamplerGraph(flow), (clean, x, iso, cam), ["clean", "z", "iso", "camera"], ["noise"], out,
                    metadata(flow, role="sampler", source=source))
        _export_one(LoglikGraph(flow), (x, clean, iso, cam), ["noise", "clean", "iso", "camera"], ["loglik"],
                    lpath, metadata(flow, role="loglik", source=source))
    return out, lpath
