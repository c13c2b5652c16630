"""The loop on capture sets unlike its own generator's: it must finish, and every statistic that is
undefined on the data must be reported "not applicable" with its reason (never a crash, never a NaN).

Independent generators: the ``emva1288`` package's camera simulator (``Camera``: Poisson
photo-electrons, Gaussian dark noise, ADC of 8 to 16 bits) and its descriptor writer
(``DatasetGenerator``: EMVA 1288 R3.0 / R4.0 descriptor + images), plus constant frames.
"""

import json
import math

import numpy as np
import pytest

pytest.importorskip("emva1288")

from emva1288.camera.camera import Camera  # noqa: E402

from simcam.calibration import diagnostics as dg  # noqa: E402
from simcam.calibration.capture import CaptureSet, Sequence  # noqa: E402
from simcam.calibration.loop import LoopConfig, run_loop  # noqa: E402

FAST = LoopConfig(replicates=8, heldout_replicates=4, max_size=64)


def _camera_set(*, bits=12, K=1.0, sigma_e=4.0, dark_e=60.0, n=8, kinds=("dark", "flat"), cfa=None, size=64,
                levels=(0.2, 0.4, 0.6), step=None, seed=0, iso=100, exposure_s=0.01):
    cam = Camera(bit_depth=bits, width=size, height=size, K=K, dark_signal_0=dark_e, sigma2_dark_0=sigma_e ** 2,
                 seed=seed)
    white = float(cam.img_max)

    def seq(name, kind, radiance):
        fr = np.stack([cam.grab(radiance) for _ in range(n)]).astype(np.float32)
        if step:  # a coarse ADC: codes in steps of ``step`` DN
            fr = np.floor(fr / step) * step
        return Sequence(f"{name}_iso{iso}", kind, fr, iso, exposure_s, cfa, None, white)

    seqs = []
    if "dark" in kinds:
        seqs.append(seq("dark", "dark", 0.0))
    if "flat" in kinds:
        seqs += [seq(f"flat_{k}", "flat", cam.get_radiance_for(mean=m * white)) for k, m in enumerate(levels)]
    if "scene" in kinds:
        seqs.append(seq("scene", "scene", cam.get_radiance_for(mean=0.3 * white)))
    return seqs


def _check(results):
    """Every diagnostic is either evaluated (finite discrepancy) or not applicable with a reason."""
    assert results
    for r in results:
        evaluated = {d.name for d in r.base_disc}
        for d in r.base_disc + r.final:
            assert math.isfinite(d.z) and math.isfinite(d.value), d
        for name in dg.DIAGNOSTICS:
            assert name in evaluated or name in r.not_applicable, name
        for name, why in r.not_applicable.items():
            assert isinstance(why, str) and why, name
        assert math.isfinite(r.model.K) and math.isfinite(r.model.read_dn)
    return results


CASES = {
    # 8 bit, K = 0.02 DN/e-, dark noise 0.5 DN (below one code), darks sitting on code 0..1
    "8bit_subcode_dark_noise": dict(bits=8, K=0.02, sigma_e=25.0, dark_e=0.0),
    "darks_only": dict(kinds=("dark",)),
    "flats_only": dict(kinds=("flat",)),
    "scenes_only": dict(kinds=("scene",)),
    "two_frame_sequences": dict(n=2),
    "bayer_two_frames": dict(n=2, cfa="RGGB"),
    "coarse_adc_8dn_steps": dict(step=8),
    "16_bit": dict(bits=16, K=4.0, dark_e=200.0),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_no_crash(case):
    _check(run_loop(CaptureSet("memory", "directory", _camera_set(**CASES[case])), FAST))


def test_darks_only_states_what_is_not_measured():
    r = _check(run_loop(CaptureSet("memory", "directory", _camera_set(kinds=("dark",))), FAST))[0]
    assert r.base.K == 0.0  # no signal: no photon-transfer slope (no shot noise in the model)
    assert "flat" in r.not_applicable["prnu_excess"]
    # the read noise is still the camera's: sigma_d K = 4 DN, SE of a 64x64x8 variance ~1 %
    assert r.base.read_dn == pytest.approx(4.0, rel=0.05)


def test_quantisation_dominated_darks_are_not_applicable_with_a_reason():
    """Constant darks (zero temporal variance): the ratio statistics have no denominator."""
    dark = Sequence("dark", "dark", np.full((6, 32, 32), 12.0, np.float32), 100, 0.01, None, None, 255.0)
    flats = _camera_set(bits=8, K=0.05, kinds=("flat",), size=32, n=6)
    r = _check(run_loop(CaptureSet("memory", "directory", [dark] + flats), FAST))[0]
    for name in ("dark_checker_jitter", "dsnu_excess", "lag1_corr", "dark_tail_mass"):
        assert name in r.not_applicable
    assert "0" in r.not_applicable["dark_checker_jitter"]


def test_constant_frames():
    seqs = [Sequence("dark", "dark", np.full((4, 32, 32), 10.0, np.float32), 100, 0.01, None, None, 255.0),
            Sequence("flat", "flat", np.full((4, 32, 32), 100.0, np.float32), 100, 0.01, None, None, 255.0)]
    r = _check(run_loop(CaptureSet("memory", "directory", seqs), FAST))[0]
    assert r.model.K == 0.0


def test_several_isos():
    seqs = _camera_set(iso=100, seed=1) + _camera_set(iso=800, K=4.0, seed=2, kinds=("dark", "flat"))
    res = _check(run_loop(CaptureSet("memory", "directory", seqs), FAST))
    assert [r.iso for r in res] == [100, 800]
    # K of each ISO from its own flats (K SE ~2 % for 3 flats of 64x64x8)
    assert res[0].base.K == pytest.approx(1.0, rel=0.08) and res[1].base.K == pytest.approx(4.0, rel=0.08)


@pytest.mark.parametrize("version,bits,fmt", [("3.0", 12, "tiff"), ("4.0", 8, "png"), ("4.0", 10, "tiff")])
@pytest.mark.parametrize("seed", [0, 4])
def test_emva_descriptor_layouts(tmp_path, version, bits, fmt, seed):
    """Descriptors written by the emva1288 package (exposure-variant points: a 2-frame dark beside each
    2-frame flat, spatial points of L frames): ISO absent, shown as such."""
    from emva1288.camera.dataset_generator import DatasetGenerator

    from simcam.calibration.report import run_and_write

    DatasetGenerator(steps=6, L=4, version=version, outdir=str(tmp_path / "set"), width=64, height=48,
                     bit_depth=bits, image_format=fmt, seed=seed)
    doc = run_and_write(tmp_path / "set", tmp_path / "out", cfg=FAST)
    g = doc["isos"][0]
    assert g["iso_label"] == "ISO not given"
    for d in g["diagnostics_base"]:
        assert d["discrepancy"] is not None
    names = {d["name"] for d in g["diagnostics_base"]} | {x["diagnostic"] for x in g["not_applicable"]}
    assert names == set(dg.DIAGNOSTICS)
    assert json.loads((tmp_path / "out" / "report.json").read_text())["layout"] == "emva1288"


def test_8bit_cmos_full_size_subcode_dark_noise():
    """The issue's 8-bit CMOS geometry: 2048 x 512, K = 0.02 DN/e-, dark noise 0.5 DN (below one code);
    analysed as a tile mosaic spanning the frame."""
    cam = Camera(bit_depth=8, width=2048, height=512, K=0.02, dark_signal_0=10.0, sigma2_dark_0=625.0, seed=3)
    white = float(cam.img_max)
    seqs = [Sequence("dark", "dark", np.stack([cam.grab(0.0) for _ in range(4)]).astype(np.float32), 0, 0.01,
                     None, None, white)]
    for k, m in enumerate((0.3, 0.6)):
        rad = cam.get_radiance_for(mean=m * white)
        seqs.append(Sequence(f"flat_{k}", "flat", np.stack([cam.grab(rad) for _ in range(4)]).astype(np.float32),
                             0, 0.01, None, None, white))
    cfg = LoopConfig(replicates=8, heldout_replicates=4)
    r = _check(run_loop(CaptureSet("memory", "directory", seqs), cfg))[0]
    assert r.plots["group"].region["pixels_analysed"] <= cfg.max_pixels
    assert "tiles" in r.plots["group"].region["layout"]


@pytest.mark.slow
def test_twelve_megapixel_set(tmp_path):
    """A 4000 x 3000 Bayer set read from disk (darks at two exposure times, two flats), whole frames:
    EMVA numbers from every pixel, the loop on its tile mosaic."""
    from simcam.calibration.report import run_and_write
    import yaml

    rng = np.random.default_rng(5)
    h, w, K = 3000, 4000, 2.0
    for name, t, level, n in (("dark_a", 0.01, 0.0, 4), ("dark_b", 0.1, 0.0, 4), ("flat_0", 0.01, 300.0, 4),
                              ("flat_1", 0.01, 900.0, 4)):
        d = tmp_path / "set" / name
        d.mkdir(parents=True)
        for i in range(n):
            e = rng.poisson(level + 50.0 * t, (h, w)) + rng.normal(0, 2.0, (h, w))
            np.save(d / f"f{i}.npy", np.clip(np.round(64 + K * e), 0, 4095).astype(np.uint16))
        (d / "sequence.yaml").write_text(yaml.safe_dump({"iso": 400, "exposure_s": t, "cfa": "RGGB",
                                                          "black_level": 64, "white_level": 4095}))
    doc = run_and_write(tmp_path / "set", tmp_path / "out", cfg=LoopConfig(replicates=8, heldout_replicates=4))
    g = doc["isos"][0]
    assert g["analysed"]["frame"] == [4000, 3000]
    assert doc["emva"]["K_dn_per_e"] == pytest.approx(K, rel=0.02)
    assert g["dark_current"]["applicable"]
