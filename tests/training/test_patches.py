"""On-the-fly training data: worker-count independence, no duplicates, epochs differ, CFA phase, noise statistics."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from simcam.training.samplers import GaussianNoise, NLFNoise  # noqa: E402
from simcam.training.patches import NoisyPatchDataset, NoisyPatchStream, make_loader  # noqa: E402
from simcam.training.unprocess import SRGB_TO_XYZ, Unprocess, inverse_smoothstep  # noqa: E402
from simcam.errors import DatasetError  # noqa: E402


def _clean_sources(n=3, size=64, seed=0):
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:size, 0:size] / size
    return [(0.1 + 0.8 * (a * xx + (1 - a) * yy)).astype(np.float32) for a in rng.random(n)]


NLF = NLFNoise(beta1=(1e-4, 1e-2), beta2=(1e-6, 1e-4))


def _batches(loader):
    return [(b["noisy"].clone(), b["clean"].clone(), b["meta"]["index"].clone()) for b in loader]


def test_map_dataset_same_tensors_with_0_and_2_workers_no_duplicates_epochs_differ():
    ds = NoisyPatchDataset(_clean_sources(), NLF, length=12, patch_size=8, seed=3)
    b0 = _batches(make_loader(ds, batch_size=4, num_workers=0))
    b2 = _batches(make_loader(ds, batch_size=4, num_workers=2))
    assert len(b0) == len(b2) == 3
    for (n0, c0, i0), (n2, c2, i2) in zip(b0, b2):
        assert torch.equal(n0, n2) and torch.equal(c0, c2) and torch.equal(i0, i2)
    idx = torch.cat([b[2] for b in b2]).tolist()
    assert sorted(idx) == list(range(12))
    noises = torch.cat([b[0] - b[1] for b in b2]).reshape(12, -1)
    assert len({tuple(r[:16].tolist()) for r in noises}) == 12  # every sample has its own noise
    ds.set_epoch(1)
    e1 = _batches(make_loader(ds, batch_size=4, num_workers=0))
    assert not torch.equal(e1[0][0], b0[0][0])
    # same (seed, epoch, index) -> same sample from a fresh object
    ds2 = NoisyPatchDataset(_clean_sources(), NLF, length=12, patch_size=8, seed=3, epoch=1)
    assert torch.equal(ds2[5]["noisy"], ds[5]["noisy"])


def test_batched_fetch_equals_per_sample_fetch_and_plain_dataloader():
    # make_loader fetches whole batches (__getitems__ writes them in place, collate_patches passes
    # them through); a plain DataLoader stacks the per-sample views; both equal [ds[i] for i in ...]
    ds = NoisyPatchDataset(_clean_sources(), NLF, length=8, patch_size=8, seed=5)
    ours = _batches(make_loader(ds, batch_size=4, num_workers=0))
    plain = _batches(torch.utils.data.DataLoader(ds, batch_size=4, num_workers=0))
    single = [ds[i] for i in range(8)]
    for k, ((n0, c0, i0), (n1, c1, i1)) in enumerate(zip(ours, plain)):
        assert torch.equal(n0, n1) and torch.equal(c0, c1) and torch.equal(i0, i1)
        assert torch.equal(n0, torch.stack([s["noisy"] for s in single[4 * k:4 * k + 4]]))


def test_thread_workers_give_the_batches_of_process_workers():
    ds = NoisyPatchDataset(_clean_sources(), NLF, length=12, patch_size=8, seed=3)
    for shuffle in (False, True):
        b0 = _batches(make_loader(ds, batch_size=4, num_workers=0, shuffle=shuffle, generator_seed=9))
        bt = _batches(make_loader(ds, batch_size=4, num_workers=2, shuffle=shuffle, generator_seed=9, workers="thread"))
        assert len(b0) == len(bt) == 3
        for (n0, c0, i0), (n1, c1, i1) in zip(b0, bt):
            assert torch.equal(n0, n1) and torch.equal(c0, c1) and torch.equal(i0, i1)
    loader = make_loader(ds, batch_size=5, num_workers=2, workers="thread", drop_last=True)
    assert len(loader) == 2 and [b["noisy"].shape[0] for b in loader] == [5, 5]
    for b in loader:  # stopping early leaves no thread behind
        break
    st = NoisyPatchStream(_clean_sources(2), NLF, patches_per_file=2, batch_size=2, patch_size=8)
    with pytest.raises(DatasetError, match="iterable dataset"):
        make_loader(st, batch_size=2, num_workers=2, workers="thread")
    with pytest.raises(DatasetError, match="pin_memory"):
        make_loader(ds, batch_size=2, num_workers=2, workers="thread", pin_memory=True)
    with pytest.raises(DatasetError, match="'process' or 'thread'"):
        make_loader(ds, batch_size=2, workers="threads")


def test_fused_pack_and_noise_gives_the_bytes_of_pack_then_noise():
    # NLFNoise/GaussianNoise pack and add noise in one kernel pass; hiding that (a plain callable)
    # takes the pack-then-__call__ path, which must give identical samples
    for noise in (NLF, GaussianNoise(sigma=(0.01, 0.05))):
        fused = NoisyPatchDataset(_clean_sources(), noise, length=4, patch_size=8, seed=2, cfa="GRBG")
        plain = NoisyPatchDataset(_clean_sources(), lambda c, r, i, n=noise: n(c, r, i), length=4, patch_size=8,
                                  seed=2, cfa="GRBG")
        assert noise.packs
        for i in range(4):
            a, b = fused[i], plain[i]
            assert torch.equal(a["noisy"], b["noisy"]) and torch.equal(a["clean"], b["clean"])
            assert a["meta"] == b["meta"]


def test_stream_same_batches_with_0_and_2_workers():
    st = NoisyPatchStream(_clean_sources(5), NLF, patches_per_file=3, batch_size=4, patch_size=8, seed=1)
    b0 = _batches(make_loader(st, batch_size=4, num_workers=0))
    b2 = _batches(make_loader(st, batch_size=4, num_workers=2))
    assert [b[2].tolist() for b in b0] == [b[2].tolist() for b in b2]
    assert all(torch.equal(x[0], y[0]) for x, y in zip(b0, b2))
    assert torch.cat([b[2] for b in b2]).tolist() == list(range(15))
    with pytest.raises(DatasetError, match="batch_size"):
        make_loader(st, batch_size=2, num_workers=2)


def test_cfa_phase_aligned_to_rggb():
    # GRBG mosaic with R=1.0, G=0.5, B=0.0: packed RGGB patches must read (1, .5, .5, 0) everywhere.
    m = np.full((32, 32), 0.5, np.float32)
    m[0::2, 1::2] = 1.0  # R at (0, 1) in GRBG
    m[1::2, 0::2] = 0.0  # B at (1, 0)
    ds = NoisyPatchDataset([m], GaussianNoise(sigma=(0.01, 0.01)), length=6, patch_size=4, cfa="GRBG")
    for i in range(6):
        s = ds[i]
        assert s["meta"]["cfa"] == "RGGB" and s["meta"]["left"] % 2 == 1
        np.testing.assert_array_equal(s["clean"].mean(dim=(1, 2)).numpy(), [1.0, 0.5, 0.5, 0.0])


def test_nlf_noise_variance():
    # var(noisy - clean) at y = 0.3 must equal beta1 y + beta2; n = 4*64*64*8 = 131k values,
    # relative SE of a sample variance sqrt(2/n) = 0.4 %: allow 2 %.
    clean = [np.full((128, 128), 0.3, np.float32)]
    ds = NoisyPatchDataset(clean, NLFNoise(nlfs=[(4e-3, 2e-4)]), length=8, patch_size=64)
    d = torch.stack([ds[i]["noisy"] - ds[i]["clean"] for i in range(8)])
    assert float(d.var()) == pytest.approx(4e-3 * 0.3 + 2e-4, rel=0.02)
    assert ds[0]["meta"]["beta1"] == 4e-3


def test_unprocess_inverts_a_forward_render():
    # Forward render (Brooks et al. 2019): camera RGB x WB gains x brightness -> CCM -> gamma 1/2.2 -> smoothstep.
    rng = np.random.default_rng(0)
    cm = np.array([[0.9, -0.3, -0.05], [-0.4, 1.2, 0.2], [-0.05, 0.1, 0.6]])  # XYZ -> camera, made up
    up = Unprocess(xyz_to_cam=[cm])
    drawn = up.sample(rng)
    srgb = rng.uniform(0.05, 0.6, (4, 4, 3)).astype(np.float32)
    mosaic = up.apply(srgb, drawn)
    rgb2cam = cm @ SRGB_TO_XYZ
    rgb2cam /= rgb2cam.sum(1, keepdims=True)
    assert np.allclose(drawn["rgb2cam"], rgb2cam)
    # forward on the full-colour camera image that the mosaic samples
    lin = (srgb.astype(np.float64) ** 1.0)
    x = 0.5 - np.sin(np.arcsin(1 - 2 * np.clip(lin, 0, 1)) / 3)  # same as inverse_smoothstep
    cam = np.clip((x ** 2.2) @ rgb2cam.T, 0, 1) * np.array([1 / drawn["red_gain"], 1, 1 / drawn["blue_gain"]]) / drawn["rgb_gain"]
    fwd = np.clip(cam * np.array([drawn["red_gain"], 1, drawn["blue_gain"]]) * drawn["rgb_gain"], 0, 1)
    fwd = fwd @ np.linalg.inv(rgb2cam).T
    fwd = np.clip(fwd, 0, 1) ** (1 / 2.2)
    fwd = 3 * fwd**2 - 2 * fwd**3
    np.testing.assert_allclose(fwd, srgb, atol=1e-4)
    np.testing.assert_allclose(mosaic[0::2, 0::2], cam[0::2, 0::2, 0], rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(mosaic[1::2, 1::2], cam[1::2, 1::2, 2], rtol=1e-4, atol=1e-6)
    assert np.allclose(3 * inverse_smoothstep(np.array(0.3)) ** 2 - 2 * inverse_smoothstep(np.array(0.3)) ** 3, 0.3)


def test_srgb_sources_are_unprocessed():
    img = np.random.default_rng(1).uniform(0.1, 0.8, (40, 40, 3)).astype(np.float32)
    ds = NoisyPatchDataset([img], NLF, length=2, patch_size=8)
    s = ds[0]
    assert s["clean"].shape == (4, 8, 8) and {"red_gain", "blue_gain", "rgb_gain"} <= set(s["meta"])
    assert 0 <= float(s["clean"].min()) and float(s["clean"].max()) <= 1


def test_bad_sources(tmp_path):
    with pytest.raises(DatasetError, match="no such clean source"):
        NoisyPatchDataset([tmp_path / "x.npy"], NLF, length=1)
    ds = NoisyPatchDataset([np.zeros((8, 8), np.float32)], NLF, length=1, patch_size=8)
    with pytest.raises(DatasetError, match="smaller than a 16x16 patch"):
        ds[0]


@pytest.mark.slow
def test_spawn_workers_with_npy_files(tmp_path):
    paths = []
    for k, a in enumerate(_clean_sources(3)):
        paths.append(tmp_path / f"c{k}.npy")
        np.save(paths[-1], a)
    ds = NoisyPatchDataset(paths, NLF, length=8, patch_size=8, seed=2)
    b0 = _batches(make_loader(ds, batch_size=4, num_workers=0))
    b2 = _batches(make_loader(ds, batch_size=4, num_workers=2, multiprocessing_context="spawn"))
    assert all(torch.equal(x[0], y[0]) for x, y in zip(b0, b2))


def test_pair_dataset_aligned_crops():
    from simcam.training.patches import PairPatchDataset

    rng = np.random.default_rng(0)
    clean = rng.random((40, 40)).astype(np.float32)
    frames = clean[None] + np.arange(3, dtype=np.float32)[:, None, None]  # frame f = clean + f
    ds = PairPatchDataset([(frames, clean)], length=6, patch_size=4, seed=1)
    for i in range(6):
        s = ds[i]
        np.testing.assert_allclose((s["noisy"] - s["clean"]).numpy(), s["meta"]["frame"])
    assert torch.equal(ds[2]["clean"], PairPatchDataset([(frames, clean)], length=6, patch_size=4, seed=1)[2]["clean"])


def test_simcam_noise_models_profile_and_noise_stage_plug_in():
    """The noise branch's models, profiles and ``noise`` stage as samplers; workers 0 == 2."""
    from simcam.training.samplers import ModelNoise, PipelineNoise, ProfileNoise
    from simcam.noise.base import model_from_entry
    from simcam.pipeline import Pipeline

    profile = str(__import__("pathlib").Path(__file__).resolve().parents[2] / "profiles" / "sidd-gp.yaml")
    clean = [np.full((64, 64), 0.3, np.float32)]
    nlf = model_from_entry({"type": "nlf", "beta1": 4.0e-3, "beta2": 2.0e-4})
    pipe = Pipeline.from_dict({"version": 1, "input": "raw",
                               "stages": [{"type": "noise", "model": {"type": "nlf", "beta1": 4.0e-3, "beta2": 2.0e-4}}]})
    for sampler in (ModelNoise(nlf, conds=[{"iso": 800.0}]), PipelineNoise(pipe),
                    ProfileNoise(profile, isos=[800.0, 1600.0])):
        ds = NoisyPatchDataset(clean, sampler, length=8, patch_size=16, seed=4)
        b0 = _batches(make_loader(ds, batch_size=4, num_workers=0))
        b2 = _batches(make_loader(ds, batch_size=4, num_workers=2))
        assert all(torch.equal(x[0], y[0]) for x, y in zip(b0, b2))
        d = torch.cat([b[0] - b[1] for b in b0])
        if not isinstance(sampler, ProfileNoise):
            # 8 x 1024 values: sample variance relative SE 1.6 %; allow 6 %
            assert float(d.var()) == pytest.approx(4e-3 * 0.3 + 2e-4, rel=0.06)
        else:
            assert float(d.var()) > 0


def test_onnx_noise_flow_sampler(tmp_path):
    """An exported (untrained, data-free) simcam Noise Flow as a sampler: deterministic, picklable, needs spawn."""
    pytest.importorskip("onnxruntime")
    from simcam.training.samplers import FlowNoise
    from simcam.noise.flow.export import export_onnx
    from simcam.noise.flow.model import FlowConfig, NoiseFlow

    flow = NoiseFlow(FlowConfig(arch="paper", cameras=["A"], iso_knots=[100.0, 800.0]), seed=0)
    onnx_path, _ = export_onnx(flow, tmp_path / "model.onnx")
    sampler = FlowNoise(str(onnx_path), conds=[(400.0, "A")])
    ds = NoisyPatchDataset(_clean_sources(1), sampler, length=3, patch_size=8, seed=5)
    assert ds.needs_spawn
    a = ds[1]
    import pickle

    b = pickle.loads(pickle.dumps(ds))[1]  # what a spawned worker computes
    assert torch.equal(a["noisy"], b["noisy"]) and a["meta"]["iso"] == 400.0
    assert not torch.equal(a["noisy"], a["clean"])
