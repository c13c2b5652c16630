"""Noise Flow (Abdelhamed 2020, ch. 6; Abdelhamed et al., ICCV 2019, doi:10.1109/ICCV.2019.00326).

A normalising flow p(noise | clean, ISO, camera) on packed raw patches
(NCHW, channels in :data:`simcam.cfa.PACK_OFFSETS` order). Needs the ``torch``
extra; importing this package is cheap, the submodules import torch.

Submodules
----------
layers     signal-dependent, gain, LU 1x1 convolution, affine coupling
model      :class:`NoiseFlow` composite and :class:`FlowConfig`
published  loader for the authors' released weights (tests only: CC BY-NC-SA)
export     ONNX export of the sampler and the likelihood graphs
data       patch sets (.npz, SIDD .MAT pairs) and NLF synthesis (numpy only)
metrics    marginal KL with the Noise Flow binning (numpy only)
train      training loop with checkpoints, resume, CSV and plot
"""

from __future__ import annotations

__all__ = ["NoiseFlow", "FlowConfig", "load_published", "export_onnx"]


def __getattr__(name):  # lazy: torch is imported only when a flow object is asked for
    if name in ("NoiseFlow", "FlowConfig"):
        from . import model

        return getattr(model, name)
    if name == "load_published":
        from .published import load_published

        return load_published
    if name == "export_onnx":
        from .export import export_onnx

        return export_onnx
    raise AttributeError(name)
