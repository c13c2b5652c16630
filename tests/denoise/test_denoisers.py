"""Baseline denoisers: VST statistics, improvement over the noisy input, external command, DnCNN checkpoints."""

import sys

import numpy as np
import pytest

from simcam.denoise.denoisers import BlockInfo, gat_forward, gat_inverse, get_denoiser
from simcam.denoise.image_metrics import psnr
from simcam.errors import DatasetError


def test_gat_stabilises_variance_and_inverts_mean():
    # Poisson-Gaussian z = b1 Poisson(y / b1) + N(0, b2) (Abdelhamed 2020, eq. 3.6): the GAT gives var(f(z)) -> 1
    # (Makitalo & Foi 2013). With n = 200,000 draws the sample variance has relative SE
    # sqrt(2/n) = 0.3 %; the transform's own residual at y >= 0.05 (>= 12 expected counts) is < 1 %.
    rng = np.random.default_rng(0)
    b1, b2 = 4e-3, 1e-4
    for y in (0.05, 0.3, 0.8):
        z = b1 * rng.poisson(y / b1, 200_000) + np.sqrt(b2) * rng.standard_normal(200_000)
        f = gat_forward(z, b1, b2)
        assert f.var() == pytest.approx(1.0, rel=0.02)
        assert gat_inverse(f.mean(), b1, b2) == pytest.approx(y, rel=0.01)


def _noisy_block(seed=1, n=64, b1=4e-3, b2=1e-4):
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:n, 0:n] / n
    clean = (0.2 + 0.5 * xx + 0.2 * (yy > 0.5)).astype(np.float32)
    noisy = clean + np.sqrt(b1 * clean + b2) * rng.standard_normal(clean.shape).astype(np.float32)
    return clean, noisy, (b1, b2)


@pytest.mark.parametrize("spec", ["bm3d", "nlm"])
def test_classical_denoisers_improve_psnr(spec):
    clean, noisy, nlf = _noisy_block()
    name, den = get_denoiser(spec)
    out = den(noisy, BlockInfo(cfa="RGGB", nlf=nlf))
    assert out.shape == noisy.shape and out.dtype == np.float32
    assert psnr(clean, out, data_range=1.0) > psnr(clean, noisy, data_range=1.0) + 5.0


def test_estimated_nlf_used_when_missing():
    clean, noisy, _ = _noisy_block(n=128)
    _, den = get_denoiser("nlm")
    out = den(noisy, BlockInfo(cfa="RGGB", nlf=None))
    assert psnr(clean, out, data_range=1.0) > psnr(clean, noisy, data_range=1.0) + 5.0


def test_external_command_and_python_callable(tmp_path):
    script = tmp_path / "halve.py"
    script.write_text("import sys, numpy as np\nnp.save(sys.argv[2], np.load(sys.argv[1]) * 0.5)\n")
    _, den = get_denoiser(f"cmd:{sys.executable} {script} {{input}} {{output}}")
    x = np.arange(16, dtype=np.float32).reshape(4, 4)
    np.testing.assert_array_equal(den(x, BlockInfo()), x * 0.5)
    bad = tmp_path / "fail.py"
    bad.write_text("import sys\nsys.exit('model file missing')\n")
    _, den = get_denoiser(f"cmd:{sys.executable} {bad} {{input}} {{output}}")
    with pytest.raises(DatasetError, match="exit code 1.*model file missing"):
        den(x, BlockInfo())
    name, f = get_denoiser("python:numpy:copy")
    assert name == "copy"
    with pytest.raises(DatasetError, match="expected none"):
        get_denoiser("median")


def test_dncnn_checkpoint_round_trip_and_training(tmp_path):
    torch = pytest.importorskip("torch")
    from simcam.denoise.dncnn import build_dncnn, load_checkpoint, save_checkpoint, train_dncnn
    torch.manual_seed(0)
    model = build_dncnn(depth=3, width=8)
    rng = np.random.default_rng(0)
    clean = torch.full((2, 4, 8, 8), 0.5)
    batches = [{"clean": clean, "noisy": clean + 0.05 * torch.randn(clean.shape)} for _ in range(4)]
    losses = train_dncnn(model, batches, steps=20, lr=3e-3, log=None)
    # the untrained model is the identity (zero-initialised last layer): loss = noise variance 2.5e-3
    assert losses[0] == pytest.approx(2.5e-3, rel=0.3)
    # 5 batches of 512 values: the loss of the identity has relative SE ~3 %; 0.85 is > 5 SE below
    assert np.mean(losses[-5:]) < 0.85 * 2.5e-3
    path = save_checkpoint(model, tmp_path / "m.pt", steps=20)
    name, den = get_denoiser(f"dncnn:{path}")
    x = rng.random((32, 32), dtype=np.float32)
    with torch.no_grad():
        from simcam.cfa import pack, unpack
        want = unpack(model(torch.from_numpy(pack(x))[None])[0].numpy())
    np.testing.assert_allclose(den(x, BlockInfo()), want, atol=1e-6)
    (tmp_path / "junk.pt").write_bytes(b"junk")
    with pytest.raises(DatasetError, match="junk.pt"):
        load_checkpoint(tmp_path / "junk.pt")
