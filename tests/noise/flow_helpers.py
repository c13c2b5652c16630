"""Helpers shared by the Noise Flow tests (not a test module)."""

from __future__ import annotations

import numpy as np

#: released packed order (0,0),(0,1),(1,1),(1,0) -> simcam (0,0),(0,1),(1,0),(1,1)
TO_SIMCAM = [0, 1, 3, 2]


def nhwc_released_to_nchw(a):
    """Golden array [B, H, W, 4] in the released channel order -> simcam NCHW."""
    return np.ascontiguousarray(np.asarray(a)[..., TO_SIMCAM].transpose(0, 3, 1, 2))


def nhwc_latent_to_nchw(a):
    """Golden latent [B, H, W, 4] -> NCHW (the latent keeps the model's own order)."""
    return np.ascontiguousarray(np.asarray(a).transpose(0, 3, 1, 2))


def randomise(flow, seed=0, scale=0.3):
    """Give every parameter a random non-trivial value (couplings start as identity)."""
    import torch

    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for name, p in flow.named_parameters():
            p.add_(scale * torch.randn(p.shape, generator=g, dtype=p.dtype))
    return flow


# ----------------------------------------------------------------------------- fixtures
# Imported by the flow test modules (a conftest.py here would shadow tests/conftest.py for
# modules that do ``from conftest import ...``). The builders are cached, so a fixture
# imported into several modules still builds/exports once per session.
import atexit  # noqa: E402
import functools  # noqa: E402
import shutil  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402


@functools.lru_cache(maxsize=None)
def _tmpdir() -> Path:
    d = Path(tempfile.mkdtemp(prefix="simcam_flow_tests_"))
    atexit.register(shutil.rmtree, d, True)
    return d


@functools.lru_cache(maxsize=None)
def build_small_flow():
    """A randomised paper-configuration flow (2 cameras, ISO 100..1600), float32, eval."""
    import torch

    from simcam.noise.flow.model import FlowConfig, NoiseFlow

    cfg = FlowConfig(arch="paper", cameras=["A", "B"], iso_knots=[100.0, 400.0, 1600.0], sdn_per_iso=True)
    flow = randomise(NoiseFlow(cfg, seed=7), seed=2, scale=0.2).eval()
    g = torch.Generator().manual_seed(3)
    with torch.no_grad():
        flow.layers[0].b1.copy_(torch.log(torch.tensor([[2e-4, 1e-3, 4e-3], [5e-4, 2e-3, 8e-3]])))
        flow.layers[0].b2.copy_(torch.log(torch.tensor([[2e-6, 1e-5, 4e-5], [3e-6, 2e-5, 9e-5]])))
        for m in flow.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.running_mean.copy_(0.1 * torch.randn(m.running_mean.shape, generator=g))
                m.running_var.copy_(0.5 + torch.rand(m.running_var.shape, generator=g))
    return flow


@functools.lru_cache(maxsize=None)
def build_small_onnx():
    from simcam.noise.flow.export import export_onnx

    return export_onnx(build_small_flow(), _tmpdir() / "small" / "model.onnx")


@functools.lru_cache(maxsize=None)
def build_published_flow(weights: str):
    from simcam.noise.flow.published import load_published

    return load_published(weights)


@functools.lru_cache(maxsize=None)
def build_published_onnx(weights: str, legacy_iso: bool = False):
    """Published weights exported to a temporary dir only (CC BY-NC-SA: never into the repo)."""
    from simcam.noise.flow.export import export_onnx

    name = "published-legacy" if legacy_iso else "published"
    return export_onnx(build_published_flow(weights), _tmpdir() / name / "model.onnx", legacy_iso=legacy_iso)


@pytest.fixture
def small_flow():
    pytest.importorskip("torch")
    return build_small_flow()


@pytest.fixture
def small_onnx():
    pytest.importorskip("torch")
    pytest.importorskip("onnxruntime")
    return build_small_onnx()


def _weights():
    from shared_data import shared_path

    return str(shared_path("noiseflow/noiseflow_weights.npz"))


@pytest.fixture
def published_flow():
    pytest.importorskip("torch")
    return build_published_flow(_weights())


@pytest.fixture
def published_onnx():
    pytest.importorskip("torch")
    pytest.importorskip("onnxruntime")
    return build_published_onnx(_weights())


@pytest.fixture
def published_onnx_legacy():
    """The published weights exported with the released code's ISO handling (golden case 7)."""
    pytest.importorskip("torch")
    pytest.importorskip("onnxruntime")
    return build_published_onnx(_weights(), legacy_iso=True)
