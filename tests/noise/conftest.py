"""Session fixtures of the Noise Flow tests (exports are made once, in a tmp dir)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def small_flow():
    """A randomised paper-configuration flow (2 cameras, ISO 100..1600), float32, eval."""
    torch = pytest.importorskip("torch")
    from flow_helpers import randomise

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


@pytest.fixture(scope="session")
def small_onnx(small_flow, tmp_path_factory):
    pytest.importorskip("onnxruntime")
    from simcam.noise.flow.export import export_onnx

    return export_onnx(small_flow, tmp_path_factory.mktemp("onnx") / "model.onnx")


@pytest.fixture(scope="session")
def published_flow():
    pytest.importorskip("torch")
    from tests.conftest import shared_path

    from simcam.noise.flow.published import load_published

    return load_published(shared_path("noiseflow/noiseflow_weights.npz"))


@pytest.fixture(scope="session")
def published_onnx(published_flow, tmp_path_factory):
    """Published weights exported to a tmp dir only (CC BY-NC-SA: never into the repo)."""
    pytest.importorskip("onnxruntime")
    from simcam.noise.flow.export import export_onnx

    return export_onnx(published_flow, tmp_path_factory.mktemp("published") / "model.onnx")
