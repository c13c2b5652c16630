"""Benchmark: per-block scores equal scikit-image's, JSON/CSV/leaderboard layout, CLI on v5 and v7.3 files."""

import json

import numpy as np
import pytest
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from simcam.cli import main
from simcam.denoise.benchmark import pipeline_renderer, run_benchmark, update_leaderboard
from simcam.errors import DatasetError
from simcam.frame import CameraMeta
from simcam.io.sidd_blocks import write_blocks
from simcam.stages.base import Stage, StageParams, register_stage


def _blocks(seed=0, shape=(2, 3, 16, 16), sigma=0.02):
    rng = np.random.default_rng(seed)
    ramp = np.add.outer(np.arange(shape[2]), np.arange(shape[3])) / (shape[2] + shape[3])
    gt = (0.2 + 0.4 * ramp + 0.2 * rng.random(shape[:2] + (1, 1))).astype(np.float32)
    noisy = (gt + sigma * rng.standard_normal(shape)).astype(np.float32)
    return noisy, gt


def _sk_ssim(a, b, **kw):
    return structural_similarity(a, b, data_range=1.0, gaussian_weights=True, sigma=1.5,
                                 use_sample_covariance=False, **kw)


def test_raw_scores_equal_skimage_per_block_and_mean():
    noisy, gt = _blocks()
    res = run_benchmark(noisy, gt, "none", cfa="RGGB")
    ps = [peak_signal_noise_ratio(gt[i, j], noisy[i, j], data_range=1.0) for i in range(2) for j in range(3)]
    ss = [_sk_ssim(gt[i, j], noisy[i, j]) for i in range(2) for j in range(3)]
    assert [b.psnr_raw for b in res.per_block] == pytest.approx(ps, rel=1e-9)
    assert res.raw["psnr"] == pytest.approx(np.mean(ps), rel=1e-9)
    # float32 blocks: scikit-image's SSIM runs in float32, ours in float64
    assert res.raw["ssim"] == pytest.approx(np.mean(ss), abs=1e-6)
    assert res.srgb is None and res.seconds_per_mp > 0
    d = res.to_dict()
    assert set(d) >= {"raw", "srgb", "seconds_per_mp", "per_block"}
    assert d["per_block"][0]["image"] == 0 and len(d["per_block"]) == 6


def test_callable_denoiser_srgb_renderer_and_srgb_track():
    noisy, gt = _blocks(1)

    def shrink(x, info):  # a Python callable denoiser
        assert info.cfa == "GRBG"
        return (0.5 * x + 0.5 * x.mean()).astype(np.float32)

    def render(block, meta):  # any renderer: mosaic -> grey RGB
        return np.repeat(np.clip(block, 0, 1)[..., None], 3, axis=2)

    metas = [CameraMeta(cfa="GRBG"), CameraMeta(cfa="GRBG")]
    res = run_benchmark(noisy, gt, shrink, metas=metas, renderer=render)
    b = res.per_block[4]
    out = (0.5 * noisy[1, 1] + 0.5 * noisy[1, 1].mean()).astype(np.float32)
    want = _sk_ssim(render(gt[1, 1], None), render(out, None), channel_axis=-1)
    assert b.ssim_srgb == pytest.approx(want, abs=1e-6)
    assert b.psnr_srgb == pytest.approx(b.psnr_raw, rel=1e-9)  # grey render of clip(x) = x here
    # sRGB track: uint8 [N, M, H, W, 3] blocks are scored in sRGB only
    rng = np.random.default_rng(2)
    g8 = rng.integers(0, 256, (1, 2, 16, 16, 3), dtype=np.uint8)
    n8 = np.clip(g8.astype(int) + rng.integers(-9, 10, g8.shape), 0, 255).astype(np.uint8)
    res8 = run_benchmark(n8, g8, "none")
    assert res8.raw is None
    want = np.mean([peak_signal_noise_ratio(g8[0, j], n8[0, j], data_range=255) for j in range(2)])
    assert res8.srgb["psnr"] == pytest.approx(want, rel=1e-6)


@register_stage
class _GreyDisplay(Stage):
    """Test-only stage: mosaic -> grey display RGB."""

    type = "_test_bench_grey"
    accepts = frozenset({"raw"})
    produces = "display"

    class Params(StageParams):
        gain: float = 1.0

    def apply(self, frame, drawn=None):
        return frame.evolve(np.repeat(frame.data[..., None] * self.params.gain, 3, axis=2), kind="display")


def test_pipeline_renderer_and_errors():
    from simcam.pipeline import Pipeline

    pipe = Pipeline.from_dict({"version": 1, "input": "raw", "stages": [{"type": "_test_bench_grey", "gain": 2.0}]})
    render = pipeline_renderer(pipe)
    x = np.full((4, 4), 0.3, np.float32)
    np.testing.assert_allclose(render(x, CameraMeta()), 0.6, rtol=1e-6)
    noisy, gt = _blocks()
    with pytest.raises(DatasetError, match="gt: 1 images"):
        run_benchmark(noisy, gt[:1])
    with pytest.raises(DatasetError, match="returned shape"):
        run_benchmark(noisy, gt, lambda x, info: x[:4])


def test_cli_v5_v73_json_csv_leaderboard(tmp_path, capsys):
    noisy, gt = _blocks(3, shape=(2, 2, 32, 32), sigma=0.03)
    write_blocks(tmp_path / "noisy.mat", noisy, "ValidationNoisyBlocksRaw", format="v7.3")
    write_blocks(tmp_path / "gt.mat", gt, "ValidationGtBlocksRaw", format="v5")
    board = tmp_path / "board.md"
    args = ["bench", "--noisy", str(tmp_path / "noisy.mat"), "--gt", str(tmp_path / "gt.mat"),
            "--leaderboard", str(board)]
    assert main(args + ["--json", str(tmp_path / "r.json"), "--csv", str(tmp_path / "r.csv")]) == 0
    r = json.loads((tmp_path / "r.json").read_text())
    assert r["raw"]["psnr"] == pytest.approx(
        np.mean([peak_signal_noise_ratio(gt[i, j], noisy[i, j], data_range=1.0) for i in range(2) for j in range(2)]),
        rel=1e-9)
    assert r["srgb"] is None and len(r["per_block"]) == 4 and r["seconds_per_mp"] > 0
    assert (tmp_path / "r.csv").read_text().count("\n") == 5
    assert main(args + ["--denoiser", "nlm", "--blocks", "1"]) == 0
    text = board.read_text()
    assert "| 1 | nlm |" in text and "| 2 | none |" in text  # NLM ranks first
    assert main(["bench", "--noisy", str(tmp_path / "noisy.mat"), "--gt", str(tmp_path / "nope.mat")]) == 2
    assert "nope.mat: no such file" in capsys.readouterr().err


def test_cli_pairs_folder(tmp_path):
    noisy, gt = _blocks(4, shape=(1, 1, 16, 16))
    np.save(tmp_path / "a_NOISY.npy", noisy[0, 0])
    np.save(tmp_path / "a_GT.npy", gt[0, 0])
    assert main(["bench", "--pairs", str(tmp_path), "--json", str(tmp_path / "r.json")]) == 0
    r = json.loads((tmp_path / "r.json").read_text())
    assert r["raw"]["psnr"] == pytest.approx(peak_signal_noise_ratio(gt[0, 0], noisy[0, 0], data_range=1.0))


def test_leaderboard_refuses_foreign_file(tmp_path):
    p = tmp_path / "README.md"
    p.write_text("# my notes\n")
    with pytest.raises(DatasetError, match="refusing to overwrite"):
        update_leaderboard(p, {"denoiser": "x", "raw": None, "srgb": None, "seconds_per_mp": 1.0})


def test_metadata_folder_with_real_sidd_file(tmp_path, shared_file):
    import os

    from simcam.denoise.benchmark import load_metadata_dir, nlf_from_meta

    src = shared_file("sidd/0001_METADATA_RAW_010.MAT")
    os.symlink(src, tmp_path / "0001_METADATA_RAW_010.MAT")  # a link, not a copy
    (metas,) = [load_metadata_dir(tmp_path, 1)]
    assert metas[0].cfa == "GRBG" and metas[0].iso == 100.0
    b1, b2 = nlf_from_meta(metas[0])
    assert b1 == pytest.approx(4.7946e-4, rel=1e-3) and b2 == 0.0
    with pytest.raises(DatasetError, match="expected one per image"):
        load_metadata_dir(tmp_path, 2)


def test_cli_srgb_scores_with_sidd_metadata_and_pipeline(tmp_path, shared_file):
    import os

    from simcam.io.sidd import read_sidd_meta

    src = shared_file("sidd/0001_METADATA_RAW_010.MAT")
    meta_dir = tmp_path / "meta"
    meta_dir.mkdir()
    os.symlink(src, meta_dir / "0001_METADATA_RAW_010.MAT")
    noisy, gt = _blocks(5, shape=(1, 1, 32, 32), sigma=0.02)
    write_blocks(tmp_path / "n.mat", noisy, "N")
    write_blocks(tmp_path / "g.mat", gt, "G")
    assert main(["bench", "--noisy", str(tmp_path / "n.mat"), "--gt", str(tmp_path / "g.mat"),
                 "--metadata", str(meta_dir), "--json", str(tmp_path / "r.json")]) == 0
    r = json.loads((tmp_path / "r.json").read_text())
    render = pipeline_renderer("sidd-srgb")
    meta = read_sidd_meta(src)
    a, b = render(gt[0, 0], meta), render(noisy[0, 0], meta)
    assert a.shape == (32, 32, 3)
    assert r["srgb"]["psnr"] == pytest.approx(peak_signal_noise_ratio(a, b, data_range=1.0), rel=1e-9)
    assert r["srgb"]["ssim"] == pytest.approx(_sk_ssim(a, b, channel_axis=-1), abs=1e-6)
