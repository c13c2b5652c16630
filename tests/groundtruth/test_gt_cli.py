"""``simcam gt`` on directories of DNG and PNG frames, and the real EMVA 1288 CCD stacks."""

import json

import numpy as np

from simcam.cli import main
from simcam.groundtruth import Burst, SyntheticBurst, estimate_ground_truth
from simcam.groundtruth.synthetic_burst import write_dng_burst


def test_cli_on_dng_burst(tmp_path, capsys):
    sb = SyntheticBurst(shape=(96, 128), n=5, beta1=2e-4, beta2=2e-6, drift_px=1.0, hot_fraction=0.004, seed=2)
    write_dng_burst(sb, tmp_path / "b", frames=range(5))
    write_dng_burst(sb, tmp_path / "d", dark=5, frames=[])
    out = tmp_path / "gt.npz"
    rc = main(["gt", str(tmp_path / "b"), "--dark", str(tmp_path / "d"), "-o", str(out), "-o",
               str(tmp_path / "gt.dng"), "--no-progress", "--save-defects", str(tmp_path / "defects.npz")])
    assert rc == 0, capsys.readouterr().err
    z = np.load(out)
    assert set(z.files) >= {"gt", "sigma", "defects", "valid"}
    assert z["gt"].dtype == np.float32 and z["gt"].shape == (96, 128)
    assert z["defects"][sb.hot & (sb.hot_level > 0.05)].all()
    rep = json.loads((tmp_path / "gt.json").read_text())
    assert rep["frames"] == 5 and rep["defects"]["count"] == int(z["defects"].sum())
    assert (tmp_path / "gt.dng").exists() and (tmp_path / "defects.npz").exists()
    # reuse the saved defect map
    rc = main(["gt", str(tmp_path / "b"), "--defects", str(tmp_path / "defects.npz"), "-o", str(tmp_path / "g2.npz"),
               "--no-progress"])
    assert rc == 0
    np.testing.assert_array_equal(np.load(tmp_path / "g2.npz")["defects"], z["defects"])


def test_cli_errors(tmp_path, capsys):
    import OpenImageIO as oiio

    d = tmp_path / "png"
    d.mkdir()
    for i, shape in enumerate([(32, 32), (32, 32), (32, 40)]):
        out = oiio.ImageOutput.create(str(d / f"f{i}.png"))
        out.open(str(d / f"f{i}.png"), oiio.ImageSpec(shape[1], shape[0], 1, oiio.UINT16))
        out.write_image(np.full(shape, 1000, np.uint16))
        out.close()
    assert main(["gt", str(d), "-o", str(tmp_path / "x.npz"), "--no-progress"]) == 2
    assert "shape" in capsys.readouterr().err
    assert main(["gt", str(d), "-o", str(tmp_path / "x.txt"), "--no-progress"]) == 2
    assert "output" in capsys.readouterr().err
    assert main(["gt", str(tmp_path / "nope"), "-o", str(tmp_path / "x.npz")]) == 2
    assert "not found" in capsys.readouterr().err
    # DNG output needs DNG input (metadata to copy)
    (d / "f2.png").unlink()
    out = oiio.ImageOutput.create(str(d / "f2.png"))
    out.open(str(d / "f2.png"), oiio.ImageSpec(32, 32, 1, oiio.UINT16))
    out.write_image(np.full((32, 32), 1000, np.uint16))
    out.close()
    assert main(["gt", str(d), "-o", str(tmp_path / "x.dng"), "--no-progress"]) == 2
    assert "DNG output" in capsys.readouterr().err


def test_emva_ccd_flat_equals_plain_mean(shared_file):
    # real 12-bit mono CCD, 50 flat frames: with no motion the ground truth must equal the plain mean
    # within its standard error s/sqrt(50) per pixel; WLS vs mean differ by ~sqrt(1/eff - 1) ~ 0.25 SE
    img = shared_file("emva1288_ccd/images")
    burst = Burst.from_directory(img, pattern="b_s_*.png", white_level=4095)
    dark = Burst.from_directory(img, pattern="d_s_*.png", white_level=4095)
    assert len(burst) == 50 and len(dark) == 50 and burst.cfa is None
    g = estimate_ground_truth(burst, dark=dark)
    x = np.stack([burst.load(i) for i in range(50)])
    pm, se = x.mean(0), x.std(0, ddof=1) / np.sqrt(50)
    ok = ~g.defects
    z = (g.gt - pm)[ok] / se[ok]
    assert abs(z.mean()) < 0.02             # no bias: mean z over 300k pixels has SE ~0.0005
    assert np.sqrt(np.mean(z ** 2)) < 0.5    # measured 0.26
    assert np.abs(z).max() < 3
    assert g.report["alignment"]["max_shift_px"] < 0.5  # no spurious shifts on a flat field
    assert g.report["dropped"] == []
    assert 0 < g.report["defects"]["count"] < 0.01 * x[0].size


def test_gt_on_a_sidd_scene_instance_layout(tmp_path):
    """SIDD's layout: <instance>/<id>_NOISY_RAW_NNN.MAT frames + _GT_RAW_ + _METADATA_RAW_ (from the shared data)."""
    import scipy.io

    from shared_data import shared_path
    from simcam.cli import main

    meta = shared_path("sidd/0001_METADATA_RAW_010.MAT")
    root = tmp_path / "SIDD_Small"
    inst = root / "0001_001_S6_00100_00060_3200_L"
    inst.mkdir(parents=True)
    (inst / "0001_METADATA_RAW_010.MAT").write_bytes(meta.read_bytes())
    rng = np.random.default_rng(0)
    clean = np.tile(np.linspace(0.1, 0.6, 64, dtype=np.float32), (48, 1))
    for i in range(6):
        noisy = np.clip(clean + rng.normal(0, 0.01, clean.shape), 0, 1).astype(np.float32)
        scipy.io.savemat(inst / f"0001_NOISY_RAW_{i + 1:03d}.MAT", {"x": noisy})
    scipy.io.savemat(inst / "0001_GT_RAW_001.MAT", {"x": clean})
    out = tmp_path / "out"
    assert main(["gt", str(root), "-o", str(out), "--workers", "0", "--alignment", "none"]) == 0
    gt = np.load(out / f"{inst.name}.npz")["gt"]
    assert gt.shape == clean.shape
    assert np.abs(gt - clean).mean() < 0.01 / np.sqrt(6) * 2  # the mean of 6 frames
