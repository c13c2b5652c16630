"""The independent simulator against closed forms (EMVA 1288 R4.0) and the file round trips."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from tests.indepsim.capture import write_capture_set
from tests.indepsim.cases import CASES, case_spec
from tests.indepsim.effects import REGISTRY
from tests.indepsim.sensor import SensorModel, SensorSpec


def _frames(model, kind, iso, t, flux, n, seed=0):
    return np.stack([model.frame(kind, iso, t, flux, np.random.default_rng([seed, i]), i, n).astype(np.float64)
                     for i in range(n)])


def test_photon_transfer_gives_gain_and_read_noise():
    """EMVA 1288 R4.0 eq. 8: var_y = K^2 sigma_d^2 + sigma_q^2 + K (mu_y - mu_dark)."""
    sp = SensorSpec(width=128, height=128, bits=14, black_dn=512.0, full_well_e=12000.0)
    m = SensorModel(sp, {}, seed=1)
    iso = 400
    K = sp.gain(iso)
    dark = _frames(m, "dark", iso, 0.01, 0.0, 2)
    mu_d = dark.mean()
    var_d = np.var(dark[0] - dark[1]) / 2
    means, varis = [], []
    for lv in (0.1, 0.25, 0.4, 0.55, 0.7):
        f = _frames(m, "flat", iso, 0.01, lv * sp.saturation_e(iso) / 0.01, 2)
        means.append(f.mean() - mu_d)
        varis.append(np.var(f[0] - f[1]) / 2 - var_d)
    slope = np.polyfit(means, varis, 1)[0]
    n = sp.width * sp.height
    # std error of a variance from n pixels ~ var*sqrt(2/n); the slope is at worst that relative
    assert slope == pytest.approx(K, rel=5 * np.sqrt(2 / n) * 3)
    sigma_d_e = np.sqrt(max(var_d - 1 / 12, 0)) / K
    expect = np.hypot(sp.read_noise_e, sp.adc_noise_dn / K)
    assert sigma_d_e == pytest.approx(expect, rel=5 * np.sqrt(1 / (2 * n)) + 0.02)


def test_dark_current_mean_is_linear_in_exposure():
    sp = SensorSpec(width=96, height=96, bits=16, black_dn=1024.0)
    m = SensorModel(sp, {"dark_current": {"rate_e_per_s": 20.0, "spread": 0.5}}, seed=2)
    rate = float(m.effects[0].rate.mean())
    iso = 200
    K = sp.gain(iso)
    ts = np.array([0.5, 1.0, 2.0, 4.0])
    mu = np.array([_frames(m, "dark", iso, t, 0.0, 2).mean() - sp.black_dn for t in ts])
    slope, icpt = np.polyfit(ts, mu, 1)
    n = 2 * sp.width * sp.height
    se = K * np.sqrt(rate * ts.max() + sp.read_noise_e ** 2) / np.sqrt(n)
    assert slope == pytest.approx(K * rate, rel=0.01)
    assert abs(icpt) < 6 * se
    # Poisson: the temporal variance grows by K^2 * rate * t
    d = _frames(m, "dark", iso, 4.0, 0.0, 2)
    var = np.var(d[0] - d[1]) / 2
    expect = K ** 2 * (rate * 4.0 + sp.read_noise_e ** 2) + sp.adc_noise_dn ** 2 + 1 / 12
    assert var == pytest.approx(expect, rel=5 * np.sqrt(2 / (sp.width * sp.height)))


def test_dsnu_and_prnu_magnitudes():
    sp = SensorSpec(width=128, height=128, bits=16, black_dn=1024.0, full_well_e=20000.0)
    m = SensorModel(sp, {"dsnu": {"sigma_dn": 3.0}, "prnu": {"sigma_rel": 0.02}}, seed=3)
    iso, N = 100, 16
    dark = _frames(m, "dark", iso, 0.01, 0.0, N)
    spatial = dark.mean(0).var() - dark.var(0, ddof=1).mean() / N
    npx = sp.width * sp.height
    assert np.sqrt(spatial) == pytest.approx(3.0, rel=5 * np.sqrt(1 / (2 * npx)) + 0.01)
    assert np.sqrt(spatial) == pytest.approx(float(next(e for e in m.effects if e.name == "dsnu").map.std()), rel=0.02)
    K = sp.gain(iso)
    mu_e = 0.5 * sp.saturation_e(iso)
    flat = _frames(m, "flat", iso, 0.01, mu_e / 0.01, N)
    sig = flat.mean(0) - dark.mean(0)  # removes DSNU
    spatial_f = sig.var() - (flat.var(0, ddof=1).mean() + dark.var(0, ddof=1).mean()) / N
    prnu = np.sqrt(spatial_f) / sig.mean()
    assert prnu == pytest.approx(0.02, rel=5 * np.sqrt(1 / (2 * npx)) + 0.02)
    assert sig.mean() == pytest.approx(K * mu_e, rel=0.005)


def test_charge_crosstalk_lowers_flat_variance_not_dark():
    sp = SensorSpec(width=128, height=128, bits=16, black_dn=1024.0, read_noise_e=3.0, adc_noise_dn=0.0,
                    full_well_e=40000.0)
    f = 0.05
    m0, m1 = SensorModel(sp, {}, 4), SensorModel(sp, {"charge_crosstalk": {"fraction": f}}, 4)
    mu = 20000.0
    v = [np.var(np.diff(_frames(m, "flat", 100, 1.0, mu, 2), axis=0)) / 2 for m in (m0, m1)]
    K = sp.gain(100)
    shot0 = v[0] - (K * 3.0) ** 2 - 1 / 12
    shot1 = v[1] - (K * 3.0) ** 2 - 1 / 12
    assert shot1 / shot0 == pytest.approx((1 - 4 * f) ** 2 + 4 * f ** 2, rel=0.05)


def test_capture_round_trip_rawpy_and_simcam(tmp_path):
    rawpy = pytest.importorskip("rawpy")
    from simcam.calibration.capture import read_capture_set

    spec = {"sensor": {"width": 64, "height": 48, "cfa": "GRBG", "black_dn": [[256, 260], [252, 258]]},
            "effects": {"dsnu": {"sigma_dn": 2.0}}, "isos": [100, 800],
            "darks": {"exposures_s": [0.02], "frames": 3}, "flats": {"exposure_s": 0.01, "levels": [0.3],
                                                                    "frames": 3},
            "scene": {"exposure_s": 0.01, "level": 0.5, "frames": 2}, "fmt": "dng"}
    truth = write_capture_set(tmp_path / "dng", spec, seed=5)
    spec["fmt"] = "npy"
    write_capture_set(tmp_path / "npy", spec, seed=5)
    cs_d = read_capture_set(tmp_path / "dng")
    cs_n = read_capture_set(tmp_path / "npy")
    assert [s.name for s in cs_d.sequences] == sorted(s["name"] for s in truth["sequences"])
    for sd, sn in zip(cs_d.sequences, cs_n.sequences):
        assert np.array_equal(sd.frames, sn.frames)  # same pixels through both writers
        assert sd.cfa == sn.cfa == "GRBG"
        assert np.array_equal(sd.black_dn, [[256, 260], [252, 258]])
        assert np.array_equal(sn.black_dn, [[256, 260], [252, 258]])
        assert sd.white_dn == sn.white_dn == 4095
        plan = next(p for p in truth["sequences"] if p["name"] == sd.name)
        assert sd.iso == sn.iso == plan["iso"] and sd.kind == plan["kind"]
        assert sd.exposure_s == pytest.approx(plan["exposure_s"], rel=1e-6)
        assert sn.exposure_s == pytest.approx(plan["exposure_s"], rel=1e-6)
        files = sorted((tmp_path / "dng" / sd.name).glob("*.dng"))
        for i, fpath in enumerate(files):
            with rawpy.imread(str(fpath)) as r:
                assert np.array_equal(r.raw_image, sd.frames[i].astype(np.uint16))
                assert r.white_level == 4095
                # rawpy orders black per colour index (R, G, B, G2)
                assert sorted(r.black_level_per_channel) == [252, 256, 258, 260]
            assert np.array_equal(np.load(tmp_path / "npy" / sd.name / f"frame_{i:03d}.npy"), sn.frames[i])


def test_emva1288_descriptor_round_trip(tmp_path):
    from simcam.calibration.capture import read_capture_set

    spec = {"sensor": {"width": 40, "height": 32, "cfa": None, "bits": 12}, "isos": [100],
            "darks": {"exposures_s": [0.01], "frames": 2}, "flats": {"exposure_s": 0.01, "levels": [0.2, 0.5],
                                                                    "frames": 2},
            "scene": None, "fmt": "emva"}
    truth = write_capture_set(tmp_path, spec, seed=6)
    cs = read_capture_set(tmp_path)
    assert cs.layout == "emva1288" and [s.kind for s in cs.sequences] == ["dark", "flat", "flat"]
    spec["fmt"] = "npy"
    write_capture_set(tmp_path / "ref", spec, seed=6)
    ref = read_capture_set(tmp_path / "ref")
    for s, r in zip(cs.sequences, ref.sequences):
        assert np.array_equal(s.frames, r.frames)
    flats = [p for p in truth["sequences"] if p["kind"] == "flat"]
    assert [s.photons for s in cs.sequences[1:]] == pytest.approx([p["photons_per_pixel"] for p in flats], rel=1e-5)


def test_same_seed_same_bytes(tmp_path):
    spec = case_spec(next(c for c in CASES if c["name"] == "pair_dsnu__dark_current"))
    spec.update({"isos": [100], "darks": {"exposures_s": [0.5], "frames": 2}, "flats": None, "scene": None,
                 "fmt": "npy"})
    spec["sensor"] = {"width": 32, "height": 32}
    digests = []
    for d in ("a", "b"):
        write_capture_set(tmp_path / d, spec, seed=9)
        digests.append(hashlib.sha256(b"".join(p.read_bytes() for p in sorted((tmp_path / d).rglob("*.npy"))))
                       .hexdigest())
    assert digests[0] == digests[1]


@pytest.mark.parametrize("case", CASES, ids=[c["name"] for c in CASES])
def test_every_case_runs_and_records_truth(case, tmp_path):
    spec = case_spec(case)
    for k, r in REGISTRY.items():
        assert set(r.ranges)  # every effect documents a range
    for name, params in spec["effects"].items():
        cls = REGISTRY[name]
        for p, v in params.items():
            lo, hi = cls.ranges[p]
            assert lo <= v <= hi
    spec.setdefault("sensor", {})
    spec["sensor"] = dict(spec["sensor"], width=24, height=24)
    spec.update({"isos": spec.get("isos", [100])[:1]})
    for k in ("darks", "flats", "scene"):
        if spec.get(k, True) is not None:
            base = {"darks": {"exposures_s": [0.5], "frames": 2},
                    "flats": {"exposure_s": 0.01, "levels": [0.4], "frames": 2},
                    "scene": {"exposure_s": 0.01, "level": 0.5, "frames": 2}}[k]
            spec[k] = base if spec.get("fmt") != "emva" or k != "scene" else None
    if spec.get("fmt") == "dng" or "fmt" not in spec:
        spec["fmt"] = "npy"  # tiny frames: LibRaw refuses very small DNGs; the DNG path is tested above
    truth = write_capture_set(tmp_path, spec, seed=case["seed"])
    from simcam.calibration.capture import read_capture_set

    cs = read_capture_set(tmp_path)  # the input contract: sizes, metadata, unsaturated flats
    assert len(cs.sequences) == sum(1 for p in truth["sequences"] if spec["fmt"] != "emva" or p["kind"] != "scene")
    on_disk = json.loads((tmp_path / "truth.json").read_text())
    assert sorted(on_disk["effects"]) == sorted(case["effects"]) and on_disk["held_out"] == case["held_out"]
    for name in case["effects"]:
        if name.startswith("undeclared_"):
            fam = truth["effects"][name]["family"]
            assert fam["time"] in ("temporal", "fixed") and fam["mode"] in ("additive", "multiplicative")
            assert fam["support"] in ("pixel", "row", "column", "frame", "smooth_field", "code")


def test_held_out_share():
    share = np.mean([c["held_out"] for c in CASES])
    assert 0.2 <= share <= 0.4


def _one(effects, kind="dark", iso=100, t=0.02, level=0.0, n=8, seed=7, **sensor):
    sp = SensorSpec(**{"width": 96, "height": 96, "bits": 16, "black_dn": 1024.0, **sensor})
    m = SensorModel(sp, effects, seed=seed)
    flux = level * sp.saturation_e(iso) / t
    return sp, m, _frames(m, kind, iso, t, flux, n, seed)


def test_row_noise_and_column_fpn_magnitudes():
    sp, m, f = _one({"row_noise": {"sigma_e": 3.0}, "column_fpn": {"sigma_dn": 8.0}}, iso=100, n=16)
    K = sp.gain(100)
    white = np.hypot(K * sp.read_noise_e, sp.adc_noise_dn)
    # temporal per-row offset: variance of (row mean - its time average) minus white-noise share
    rm = f.mean(2)
    row_var = (rm - rm.mean(0)).var(ddof=0) * f.shape[0] / (f.shape[0] - 1) - white ** 2 / sp.width
    assert np.sqrt(row_var) == pytest.approx(K * 3.0, rel=0.15)  # 96 rows x 16 frames
    cm = f.mean((0, 1))
    col_var = cm.var() - white ** 2 / (f.shape[0] * sp.height)  # row offsets are common to all columns
    assert np.sqrt(col_var) == pytest.approx(float(next(e for e in m.effects if e.name == "column_fpn").col.std()),
                                             rel=0.1)


def test_quantization_codes_are_steps():
    _, _m, f = _one({"quantization": {"step_dn": 8}}, n=2)
    assert np.all(f % 8 == 0)


def test_dead_and_stuck_pixels():
    sp, m, f = _one({"dead_pixels": {"fraction": 1e-3}, "stuck_pixels": {"fraction": 5e-4, "white_share": 1.0}},
                    kind="flat", t=0.01, level=0.5, n=2)
    dead = next(e for e in m.effects if e.name == "dead_pixels").idx
    stuck = next(e for e in m.effects if e.name == "stuck_pixels").idx
    flat = f.reshape(2, -1)
    assert np.all(np.abs(flat[:, np.setdiff1d(dead, stuck)] - sp.black_dn) < 8 * sp.read_noise_e * sp.gain(100) + 4)
    assert np.all(flat[:, stuck] == sp.white_dn)


def test_amp_glow_grows_with_exposure_towards_a_corner():
    sp, m, f1 = _one({"amp_glow": {"rate_e_per_s": 100.0, "length_frac": 0.2}}, t=1.0, n=2)
    _, _, f4 = _one({"amp_glow": {"rate_e_per_s": 100.0, "length_frac": 0.2}}, t=4.0, n=2)
    g = next(e for e in m.effects if e.name == "amp_glow").map
    K = sp.gain(100)
    for f, t in ((f1, 1.0), (f4, 4.0)):
        assert f.mean() - sp.black_dn == pytest.approx(K * g.mean() * t, rel=0.03)
    corner = np.unravel_index(np.argmax(g), g.shape)
    assert corner in ((0, 0), (0, 95), (95, 0), (95, 95))


def test_rtn_pixels_are_bimodal():
    sp, m, f = _one({"rtn": {"fraction": 0.01, "amplitude_e": 200.0, "p_high": 0.5}}, n=16)
    e = next(x for x in m.effects if x.name == "rtn")
    v = f.reshape(16, -1)[:, e.idx]
    K = sp.gain(100)
    # each RTN pixel's temporal variance ~ p(1-p) (K A)^2 + read: far above the others
    expect = 0.25 * (K * e.amp) ** 2 + (K * sp.read_noise_e) ** 2 + sp.adc_noise_dn ** 2
    ratio = v.var(0, ddof=1) / expect
    assert 0.5 < np.median(ratio) < 1.5


def test_hot_pixels_count_and_level():
    sp, m, f = _one({"hot_pixels": {"fraction": 2e-3, "offset_e": 500.0, "rate_e_per_s": 100.0}}, t=2.0, n=4)
    e = next(x for x in m.effects if x.name == "hot_pixels")
    K = sp.gain(100)
    got = f.mean(0).reshape(-1)[e.idx] - sp.black_dn
    np.testing.assert_allclose(got, K * (e.off + e.rate * 2.0), rtol=0.25, atol=1.0)


def test_spatial_correlation_adjacent_correlation():
    c = 0.06
    _sp, _m, f = _one({"spatial_correlation": {"coupling": c}}, n=8, width=128, height=128)
    d = f - f.mean(0)
    r = np.mean(d[:, :, 1:] * d[:, :, :-1]) / np.mean(d * d)
    expect = 2 * c * (1 - 4 * c) / ((1 - 4 * c) ** 2 + 4 * c ** 2)
    n = d.size
    assert r == pytest.approx(expect, abs=6 / np.sqrt(n) + 0.01)  # quantisation adds a little white noise


def test_adc_dnl_code_occupancy_follows_code_widths():
    sp, m, f = _one({"adc_dnl": {"inl_dn": 0.3, "major_dn": 0.0}}, kind="flat", t=0.01, level=0.3, n=8,
                    bits=12, black_dn=256.0)
    e = next(x for x in m.effects if x.name == "adc_dnl")
    mu, sd = f.mean(), f.std()
    codes = np.arange(int(mu - sd), int(mu + sd))
    counts = np.bincount(f.astype(np.int64).ravel(), minlength=sp.white_dn + 1)[codes]
    from scipy.stats import norm

    width = e.edges[codes] - e.edges[codes - 1]
    expect = f.size * (norm.cdf(e.edges[codes], mu, sd) - norm.cdf(e.edges[codes - 1], mu, sd))
    # counts are binomial around the width-weighted density
    z = (counts - expect) / np.sqrt(expect)
    assert np.abs(z).max() < 5
    ideal = f.size * (norm.cdf(codes + 0.5, mu, sd) - norm.cdf(codes - 0.5, mu, sd))  # equal-width codes
    assert np.corrcoef(counts / ideal, width)[0, 1] > 0.8


def test_adc_dnl_beside_quantization_acts_on_the_coarse_codes():
    # both effects are ADC read-outs: the DNL must not be dropped (the first ADC hook used to win alone)
    sp, m, f = _one({"quantization": {"step_dn": 8}, "adc_dnl": {"inl_dn": 0.4, "major_dn": 0.0}},
                    kind="flat", t=0.01, level=0.3, n=8, bits=12, black_dn=256.0)
    assert np.all(f % 8 == 0)
    e = next(x for x in m.effects if x.name == "adc_dnl")
    mu, sd = f.mean() / 8, f.std() / 8  # in coarse codes
    codes = np.arange(int(mu - sd), int(mu + sd) + 1)
    counts = np.bincount((f // 8).astype(np.int64).ravel())[codes]
    from scipy.stats import norm

    expect = f.size * (norm.cdf(e.edges[codes], mu, sd) - norm.cdf(e.edges[codes - 1], mu, sd))
    z = (counts - expect) / np.sqrt(expect)
    assert np.abs(z).max() < 5
    ideal = f.size * (norm.cdf(codes + 0.5, mu, sd) - norm.cdf(codes - 0.5, mu, sd))
    assert np.abs((counts - ideal) / np.sqrt(ideal)).max() > 5  # unequal widths are visible


def test_undeclared_gain_drift_and_interleaved_adc():
    sp, _m, f = _one({"undeclared_gain_drift": {"drift_rel": 0.04}}, kind="flat", t=0.01, level=0.5, n=8)
    sig = f.mean((1, 2)) - sp.black_dn
    assert sig[-1] / sig[0] == pytest.approx(1.02 / 0.98, rel=0.003)
    sp, _m, f = _one({"undeclared_interleaved_adc": {"offset_dn": 3.0, "gain_rel": 0.0}}, n=8)
    cols = f.mean((0, 1))
    a, b = cols[(np.arange(sp.width) // 2) % 2 == 0].mean(), cols[(np.arange(sp.width) // 2) % 2 == 1].mean()
    assert a - b == pytest.approx(3.0, abs=0.2)


def test_monochrome_dng_round_trip_rawpy(tmp_path):
    rawpy = pytest.importorskip("rawpy")
    spec = {"sensor": {"width": 64, "height": 48, "cfa": None}, "isos": [200],
            "darks": {"exposures_s": [0.1], "frames": 2}, "flats": None, "scene": None, "fmt": "dng"}
    write_capture_set(tmp_path / "d", spec, seed=8)
    spec["fmt"] = "npy"
    write_capture_set(tmp_path / "n", spec, seed=8)
    for i in range(2):
        with rawpy.imread(str(tmp_path / "d" / "dark_iso200_t100ms" / f"frame_{i:03d}.dng")) as r:
            ref = np.load(tmp_path / "n" / "dark_iso200_t100ms" / f"frame_{i:03d}.npy")
            assert np.array_equal(r.raw_image, ref) and r.white_level == 4095
            assert list(r.black_level_per_channel) == [256] * 4


def test_heavy_tail_read_kurtosis():
    nu = 10.0
    sp, _m, f = _one({"heavy_tail_read": {"nu": nu}}, iso=800, n=8, read_noise_e=3.0)
    K = sp.gain(800)
    d = (f - f.mean(0)).ravel() * np.sqrt(8 / 7)
    var_r = (K * sp.read_noise_e) ** 2
    var = var_r + sp.adc_noise_dn ** 2 + 1 / 12
    assert d.var() == pytest.approx(var, rel=0.03)
    # Student-t excess kurtosis 6/(nu-4), diluted by the Gaussian parts (cumulants add); the residual
    # x_i - mean(x) = sum_j a_j x_j scales it by sum(a^4) / (sum(a^2))^2 (a_i = 1 - 1/n, else -1/n)
    n = 8
    a = np.r_[1 - 1 / n, np.full(n - 1, -1 / n)]
    ex = np.mean(d ** 4) / np.mean(d ** 2) ** 2 - 3
    expect = 6 / (nu - 4) * (var_r / var) ** 2 * np.sum(a ** 4) / np.sum(a ** 2) ** 2
    assert ex == pytest.approx(expect, abs=0.25)  # ~4 standard errors of a heavy-tailed kurtosis at 74k samples


def test_flat_given_in_photons_uses_the_qe(tmp_path):
    spec = {"sensor": {"width": 32, "height": 32, "qe": 0.5, "bits": 16, "black_dn": 1024.0}, "isos": [100],
            "darks": None, "scene": None, "fmt": "npy",
            "flats": {"exposure_s": 0.1, "photons_per_s": [40000.0], "frames": 4}}
    truth = write_capture_set(tmp_path, spec, seed=10)
    f = np.stack([np.load(p) for p in sorted((tmp_path / "flat_iso100_p40000").glob("*.npy"))]).astype(float)
    K = truth["sensor"]["gain_dn_per_e"]["100"]
    mu_e = 40000.0 * 0.5 * 0.1
    se = K * np.sqrt(mu_e) / np.sqrt(f.size)
    assert f.mean() - 1024.0 == pytest.approx(K * mu_e, abs=6 * se + 0.5)
    assert truth["sequences"][0]["photons_per_pixel"] == pytest.approx(4000.0)
