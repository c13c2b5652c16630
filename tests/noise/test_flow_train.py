"""Noise Flow data, metrics and training.

References: closed-form Gaussian statistics (NLF synthesis, NLL of the true NLF via
scipy.stats.norm), the marginal-KL definition checked on hand-computed histograms,
and the training acceptance (slow): a flow trained on pairs from the SIDD Google
Pixel NLF (ISO 100-1600) reaches the true NLF's test NLL/dim within 0.02 nats and a
marginal KL <= 0.01.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from simcam.errors import DatasetError, NoiseModelError
from simcam.noise.flow.data import (
    load_npz,
    load_sidd_pairs,
    nlf_nll_per_dim,
    read_nlf_table,
    save_npz,
    split_by_condition,
    synthesize_nlf_pairs,
)
from simcam.noise.metrics import KL_EDGES, marginal_kl

REPO = Path(__file__).resolve().parents[2]
NLF = {("GP", 100.0): (2.28e-4, 2e-6), ("GP", 1600.0): (3.519e-3, 4.5e-5), ("XX", 400.0): (1e-3, 1e-5)}


def test_nlf_table_in_profiles_reads():
    t = read_nlf_table(REPO / "profiles" / "sidd_pixel_nlf.csv")
    assert t[("GP", 1600.0)] == (0.003519, 0.000045)
    assert len(t) == 22


def test_synthesis_matches_nlf_variance():
    ps = synthesize_nlf_pairs(NLF, 40, size=16, seed=1, cameras=["GP"])
    assert ps["clean"].shape == (80, 4, 16, 16) and set(ps["camera"]) == {"GP"}
    m = ps["iso"] == 1600.0
    c, n = ps["clean"][m].ravel().astype(np.float64), ps["noise"][m].ravel().astype(np.float64)
    z = n / np.sqrt(3.519e-3 * c + 4.5e-5)
    # N = 40*1024 standardised values: sd of the variance estimate is sqrt(2/N) = 0.007; 5 sigma
    assert abs(z.var() - 1.0) < 5 * np.sqrt(2 / z.size)
    assert abs(z.mean()) < 5 / np.sqrt(z.size)


def test_nlf_nll_matches_scipy():
    from scipy.stats import norm

    ps = synthesize_nlf_pairs(NLF, 3, size=8, seed=2)
    sd = np.stack([np.sqrt(NLF[(c, i)][0] * ps["clean"][k].astype(np.float64) + NLF[(c, i)][1])
                   for k, (c, i) in enumerate(zip(ps["camera"], ps["iso"]))])
    ref = -norm.logpdf(ps["noise"], scale=sd).mean()
    assert abs(nlf_nll_per_dim(ps, NLF) - ref) < 1e-9


def test_split_keeps_every_condition_in_both():
    ps = synthesize_nlf_pairs(NLF, 5, size=4, seed=0)
    tr, te = split_by_condition(ps, 0.2, seed=3)
    keys = lambda s: set(zip(s["camera"].tolist(), s["iso"].tolist()))  # noqa: E731
    assert keys(tr) == keys(te) == keys(ps)
    assert tr["clean"].shape[0] + te["clean"].shape[0] == 15
    one = {k: v[:1] for k, v in ps.items()}
    with pytest.raises(DatasetError, match="has 1 patch; need 2"):
        split_by_condition(one)


def test_npz_round_trip_and_errors(tmp_path):
    ps = synthesize_nlf_pairs(NLF, 2, size=4, seed=0)
    save_npz(tmp_path / "a.npz", ps)
    back = load_npz(tmp_path / "a.npz")
    np.testing.assert_array_equal(back["noise"], ps["noise"])
    np.savez(tmp_path / "b.npz", clean=ps["clean"], noisy=ps["clean"] + ps["noise"], iso=ps["iso"], camera=ps["camera"])
    np.testing.assert_allclose(load_npz(tmp_path / "b.npz")["noise"], ps["noise"], atol=1e-7)
    np.savez(tmp_path / "c.npz", clean=ps["clean"][:, :3], noise=ps["noise"][:, :3], iso=ps["iso"], camera=ps["camera"])
    with pytest.raises(DatasetError, match=r"c.npz: clean: expected shape \[N, 4, h, w\]"):
        load_npz(tmp_path / "c.npz")
    np.savez(tmp_path / "d.npz", clean=ps["clean"], iso=ps["iso"], camera=ps["camera"])
    with pytest.raises(DatasetError, match="d.npz: missing array 'noise'"):
        load_npz(tmp_path / "d.npz")


def test_sidd_mat_pairs(tmp_path):
    h5py = pytest.importorskip("h5py")
    from simcam.cfa import pack

    d = tmp_path / "0001_001_GP_00800_00060_3200_L"
    d.mkdir()
    rng = np.random.default_rng(0)
    gt = rng.random((80, 96)).astype(np.float32) * 0.8
    noisy = gt + 0.01 * rng.standard_normal(gt.shape).astype(np.float32)
    for name, arr in (("0001_GT_RAW_010.MAT", gt), ("0001_NOISY_RAW_010.MAT", noisy)):
        with h5py.File(d / name, "w") as f:
            f["x"] = arr.T  # MATLAB v7.3 stores column-major
    ps = load_sidd_pairs(tmp_path, patches_per_image=5, size=8)
    assert ps["clean"].shape == (5, 4, 8, 8)
    assert set(ps["camera"]) == {"GP"} and set(ps["iso"]) == {800.0}
    # each patch is a packed 16x16 window of the mosaic at an even offset
    full_c, full_n = pack(gt), pack(np.clip(noisy, 0, 1) - np.clip(gt, 0, 1))
    for c, n in zip(ps["clean"], ps["noise"]):
        hits = [(y, x) for y in range(0, 33) for x in range(0, 41) if np.array_equal(full_c[:, y : y + 8, x : x + 8], c)]
        assert len(hits) == 1
        y, x = hits[0]
        np.testing.assert_array_equal(full_n[:, y : y + 8, x : x + 8], n)
    with pytest.raises(DatasetError, match="no SIDD scene folders"):
        load_sidd_pairs(d)


def test_marginal_kl_definition():
    assert KL_EDGES.size == 67 and np.isclose(np.diff(KL_EDGES[1:-1]), 0.2 / 64).all()
    real = np.array([0.0005, 0.0005, 0.0040, 0.5])  # bins 32, 32, 33, overflow
    model = np.array([0.0005, 0.0040, 0.0040, -0.5])  # bins 32, 33, 33, underflow
    p, q = np.array([0.5, 0.25]), np.array([0.25, 0.5])
    assert np.isclose(marginal_kl(real, model).kl, np.sum(p * np.log(p / q)))
    assert marginal_kl(real, real).kl == 0.0


torch = pytest.importorskip("torch")


def test_train_writes_outputs_and_resumes(tmp_path):
    from simcam.noise.flow.model import NoiseFlow
    from simcam.noise.flow.train import train

    ps = synthesize_nlf_pairs(NLF, 6, size=8, seed=0, cameras=["GP"])
    out = tmp_path / "run"
    r1 = train(ps, out, epochs=1, batch_size=4, progress=False, threads=1, plot_every=9)
    rows = list(csv.DictReader(open(out / "metrics.csv")))
    assert [int(r["epoch"]) for r in rows] == [1]
    assert (out / "metrics.png").stat().st_size > 0 and (out / "best.pt").is_file()
    train(ps, out, epochs=2, batch_size=4, progress=False, threads=1, resume=True, plot_every=9)
    rows = list(csv.DictReader(open(out / "metrics.csv")))
    assert [int(r["epoch"]) for r in rows] == [1, 2]
    # resuming reproduces an uninterrupted run exactly (same seeds, same batch order)
    train(ps, tmp_path / "straight", epochs=2, batch_size=4, progress=False, threads=1, plot_every=9)
    a, _ = NoiseFlow.load(out / "last.pt")
    b, _ = NoiseFlow.load(tmp_path / "straight" / "last.pt")
    for (k, va), vb in zip(a.state_dict().items(), b.state_dict().values()):
        assert torch.equal(va, vb), k
    assert r1["epoch"] == 1
    with pytest.raises(NoiseModelError, match="no checkpoint to resume from"):
        train(ps, tmp_path / "empty", epochs=1, resume=True, progress=False)


def test_cli_train_and_export(tmp_path):
    from simcam.cli import main

    ps = synthesize_nlf_pairs(NLF, 4, size=8, seed=0, cameras=["GP"])
    save_npz(tmp_path / "d.npz", ps)
    assert main(["flow", "train", str(tmp_path / "d.npz"), "--out", str(tmp_path / "r"), "--epochs", "1",
                 "--batch-size", "4", "--threads", "1"]) == 0
    assert main(["flow", "export", str(tmp_path / "r" / "best.pt"), "--out", str(tmp_path / "m.onnx")]) == 0
    assert (tmp_path / "m.onnx").is_file() and (tmp_path / "m.loglik.onnx").is_file()
    from simcam.noise.onnx_sampler import NoiseFlowRuntime

    s = NoiseFlowRuntime(tmp_path / "m.onnx")
    assert s.cameras == ["GP"] and s.iso_range == (100.0, 1600.0)
    assert main(["flow", "export", "--out", str(tmp_path / "x.onnx")]) == 2
    assert main(["flow", "export", str(tmp_path / "missing.pt"), "--out", str(tmp_path / "x.onnx")]) == 2


def test_training_recovers_sidd_pixel_nlf(tmp_path):
    """Acceptance: GP NLF pairs (ISO 100-1600), 400 patches per ISO, 32x32, 2 epochs.

    (profiles/noiseflow_sidd_gp.sh is the full-size run: 1000 per ISO, 8 epochs.) The bound
    0.02 nats is the issue's; the model-minus-truth NLL/dim difference is paired on the same
    test patches, so its sampling noise is far below it.
    """
    from simcam.noise.flow.train import train

    nlf = read_nlf_table(REPO / "profiles" / "sidd_pixel_nlf.csv")
    ps = synthesize_nlf_pairs(nlf, 400, size=32, seed=0, cameras=["GP"], isos=[100.0, 400.0, 800.0, 1600.0])
    _, te = split_by_condition(ps, 0.2, 0)
    row = train(ps, tmp_path, epochs=2, progress=False, threads=2)
    assert abs(row["test_nll_per_dim"] - nlf_nll_per_dim(te, nlf)) <= 0.02
    assert row["test_marginal_kl"] <= 0.01
