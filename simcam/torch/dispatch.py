"""Dispatch from a model ``type`` to its torch sampler, and the support table of every registered type."""

from __future__ import annotations

import torch

from ..errors import NoiseModelError
from . import samplers
from .composite import composite
from .context import Ctx
from .group import Group
from .layout import MOSAIC, PACKED, to_mosaic, to_packed

#: torch sampler of each model type.
SAMPLERS = {
    "gaussian": samplers.gaussian,
    "nlf": samplers.nlf,
    "poisson_gaussian": samplers.poisson_gaussian,
    "poisson_mixture": samplers.poisson_mixture,
    "clipped": samplers.clipped,
    "composite": composite,
}

#: registered model types with no torch sampler, and why.
NOT_SUPPORTED = {
    "noiseflow_onnx": "an ONNX graph (onnxruntime, CPU/host arrays) cannot run inside a torch graph; pass the trained "
                      "torch model instead (simcam.noise.flow.NoiseFlow, e.g. NoiseFlow.load(checkpoint)) as "
                      "profile_or_model",
}

#: model types that need the mosaic layout (their effects act on rows, columns and CFA planes).
_MOSAIC_ONLY = {"composite"}


def sample_group(group: Group, clean: torch.Tensor, ctx: Ctx) -> torch.Tensor:
    """Noisy tensor for the clean ``[G, C, h, w]`` of one group, in ``ctx.layout``."""
    t = group.models[0].type
    fn = SAMPLERS.get(t)
    if fn is None:
        why = NOT_SUPPORTED.get(t, "no torch sampler is registered for it")
        raise NoiseModelError(f"model {t!r}: not supported by simcam.torch ({why})")
    if t in _MOSAIC_ONLY and ctx.layout == PACKED:
        m = to_mosaic(clean)
        out = fn(group, m, ctx.with_layout(MOSAIC, tuple(m.shape[-2:])))
        return to_packed(out)
    return fn(group, clean, ctx)
