"""Calibration profiles: shipped SIDD profiles, interpolation, extrapolation flag, bad input; the noise stage; metrics."""

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from simcam.errors import PipelineError, ProfileError, StageError
from simcam.frame import CameraMeta, RawFrame
from simcam.noise import NoiseCondition, model_from_entry
from simcam.noise.metrics import KL_EDGES, marginal_kl, nll_per_dim, variance_vs_intensity
from simcam.pipeline import Pipeline
from simcam.profiles.schema import ProfileExtrapolationWarning, load_profile, profile_from_dict

REPO = Path(__file__).resolve().parents[2]
PROFILES = REPO / "profiles"


def _doc(**over):
    doc = {"schema_version": 1, "provenance": {"source": "test"},
           "cameras": [{"id": "CAM", "cfa": "RGGB", "entries": [
               {"iso": 100.0, "model": {"type": "nlf", "beta1": 1e-4, "beta2": 1e-6}},
               {"iso": 1600.0, "model": {"type": "nlf", "beta1": 1.6e-3, "beta2": [1e-5, 2e-5, 2e-5, 1e-5]}}]}]}
    doc.update(over)
    return doc


@pytest.mark.parametrize("cam", ["ip", "gp", "s6", "n6", "g4"])
def test_shipped_sidd_profiles_match_the_table(cam, shared_file):
    prof = load_profile(PROFILES / f"sidd-{cam}.yaml")
    assert prof.schema_version == 1 and prof.provenance.source
    table = shared_file("noiseflow/cam_iso_nlf_all.txt")
    rows = [r for r in csv.DictReader(open(table)) if r["cam_iso"].startswith(cam.upper() + "_")]
    assert len(rows) == len(prof.cameras[0].entries)
    for r in rows:
        iso = float(r["cam_iso"].split("_")[1])
        m = prof.model_for(iso)
        assert (m.type, m.beta1, m.beta2) == ("nlf", float(r["beta1"]), float(r["beta2"]))


def test_shipped_profiles_floats_have_dots():
    for p in PROFILES.glob("*.yaml"):
        for line in p.read_text().splitlines():
            for tok in line.replace(",", " ").replace("[", " ").replace("]", " ").split():
                if "e-" in tok and tok[0].isdigit():
                    assert "." in tok.split("e")[0], (p, tok)


def test_log_iso_interpolation():
    prof = profile_from_dict(_doc())
    m = prof.model_for(400.0)  # log-midpoint... t = log(4)/log(16) = 0.5
    assert m.beta1 == pytest.approx(1e-4 + 0.5 * (1.6e-3 - 1e-4))
    assert m.beta2 == pytest.approx([1e-6 + 0.5 * (x - 1e-6) for x in [1e-5, 2e-5, 2e-5, 1e-5]])
    assert prof.model_for(100).beta1 == 1e-4


def test_outside_range_refused_or_extrapolated_with_warning():
    prof = profile_from_dict(_doc(), source="p.yaml")
    with pytest.raises(ProfileError, match=r"p.yaml: camera 'CAM': iso: 3200 is outside the calibrated range \[100, 1600\]"):
        prof.model_for(3200)
    with pytest.warns(ProfileExtrapolationWarning):
        m = prof.model_for(3200, extrapolate=True)
    t = math.log(32) / math.log(16)
    assert m.beta1 == pytest.approx(1e-4 + t * (1.6e-3 - 1e-4))


@pytest.mark.parametrize("change,msg", [
    ({"schema_version": 2}, "schema_version: expected 1, got 2"),
    ({"cameras": []}, "cameras"),
    ({"provenance": None}, "provenance"),
])
def test_bad_profiles(change, msg):
    with pytest.raises(ProfileError, match=msg) as ei:
        profile_from_dict(_doc(**change), source="bad.yaml")
    assert "\n" not in str(ei.value) and "bad.yaml" in str(ei.value)


def test_bad_model_entry_and_unknown_camera(tmp_path):
    doc = _doc()
    doc["cameras"][0]["entries"][0]["model"]["beta1"] = "1e-4"  # YAML 1.1 reads this as a string: accepted as a number
    assert profile_from_dict(doc).model_for(100).beta1 == 1e-4
    doc["cameras"][0]["entries"][0]["model"]["beta1"] = "high"
    with pytest.raises(ProfileError, match="beta1"):
        profile_from_dict(doc)
    prof = profile_from_dict(_doc())
    with pytest.raises(ProfileError, match="unknown camera 'XYZ'; expected one of \\['CAM'\\]"):
        prof.model_for(100, "XYZ")
    p = prof.save(tmp_path / "p.yaml")
    assert load_profile(p).model_for(100).to_entry() == prof.model_for(100).to_entry()
    (tmp_path / "q.yaml").write_text("schema_version: [1\n")
    with pytest.raises(ProfileError, match="invalid YAML"):
        load_profile(tmp_path / "q.yaml")


def _frame(cfa="RGGB", shape=(64, 64), value=0.3):
    return RawFrame(np.full(shape, value, np.float32), CameraMeta(cfa=cfa, source="f.dng"), kind="raw")


def test_noise_stage_profile_and_inline(tmp_path):
    prof = profile_from_dict(_doc())
    path = prof.save(tmp_path / "cam.yaml")
    pipe = Pipeline.from_dict({"version": 1, "input": "raw", "stages": [
        {"type": "noise", "profile": str(path), "iso": 400.0}, {"type": "clip_raw"}]})
    a = pipe(_frame(), seed=3)
    b = pipe(_frame(), seed=3)
    c = pipe(_frame(), seed=4)
    assert a.data.tobytes() == b.data.tobytes() and not np.array_equal(a.data, c.data)
    assert a.meta.noise_profile.shape == (3, 2)  # R, G, B planes (DNG NoiseProfile)
    # inline model, sensor seed on a composite; round trip through YAML
    node = {"type": "noise", "model": {"type": "composite", "base": {"type": "nlf", "beta1": 1e-3, "beta2": 1e-5},
                                       "effects": [{"type": "dsnu", "sigma": 1e-3}]}, "sensor_seed": 5}
    p2 = Pipeline.from_dict({"version": 1, "input": "raw", "stages": [node]})
    again = Pipeline.from_yaml(p2.to_yaml())
    assert again(_frame(), seed=1).data.tobytes() == p2(_frame(), seed=1).data.tobytes()
    # drawn noise re-applied deterministically
    st = p2.stages[0]
    drawn = st.sample(np.random.default_rng(0), _frame())
    assert st.apply(_frame(), drawn).data.tobytes() == st.apply(_frame(), drawn).data.tobytes()


def test_noise_stage_errors(tmp_path):
    path = profile_from_dict(_doc()).save(tmp_path / "cam.yaml")
    with pytest.raises(PipelineError, match="outside the calibrated range"):
        Pipeline.from_dict({"version": 1, "input": "raw", "stages": [{"type": "noise", "profile": str(path), "iso": 51200.0}]})
    with pytest.raises(PipelineError, match="profile needs iso"):
        Pipeline.from_dict({"version": 1, "input": "raw", "stages": [{"type": "noise", "profile": str(path)}]})
    with pytest.raises(PipelineError, match="impossible order"):
        Pipeline.from_dict({"version": 1, "input": "raw_dn", "stages": [{"type": "noise", "profile": str(path), "iso": 100.0}]})
    pipe = Pipeline.from_dict({"version": 1, "input": "raw", "stages": [{"type": "noise", "profile": str(path), "iso": 100.0}]})
    with pytest.raises(StageError, match="cfa: the profile .* CFA RGGB, the frame is GRBG"):
        pipe(_frame(cfa="GRBG"), seed=0)
    with pytest.raises(Exception, match="NaN"):
        pipe(_frame(value=float("nan")), seed=0)


def test_marginal_kl_and_nll():
    rng = np.random.default_rng(0)
    a = rng.normal(0, 0.01, 100_000)
    assert marginal_kl(a, a).kl == 0.0
    b = rng.normal(0, 0.02, 100_000)
    res = marginal_kl(a, b)
    p = np.histogram(a, KL_EDGES)[0] / a.size
    q = np.histogram(b, KL_EDGES)[0] / b.size
    ok = (p > 0) & (q > 0)
    assert res.kl == pytest.approx(np.sum(p[ok] * np.log(p[ok] / q[ok])))
    assert len(KL_EDGES) == 67 and "linspace(-0.1, 0.1, 65)" in str(res)
    # NLL/dim of N(0, s^2) data under the true model: 0.5 log(2 pi e s^2) (SE s.d./sqrt(n) of -log p: sqrt(1/2)/sqrt(n))
    m = model_from_entry({"type": "gaussian", "sigma": 0.01})
    clean = np.zeros((200, 500), np.float32)
    noisy = m.sample(clean, NoiseCondition(), np.random.default_rng(1))
    assert nll_per_dim(m, noisy, clean, NoiseCondition()) == pytest.approx(0.5 * np.log(2 * np.pi * np.e * 1e-4),
                                                                           abs=5 * np.sqrt(0.5 / noisy.size))


def test_variance_curve_recovers_nlf():
    m = model_from_entry({"type": "nlf", "beta1": [1e-3, 2e-3, 2e-3, 4e-3], "beta2": 1e-5})
    clean = np.tile(np.linspace(0, 1, 256, dtype=np.float32), (256, 1))
    noisy = m.sample(clean, NoiseCondition(cfa="GRBG"), np.random.default_rng(2))
    curves = variance_vs_intensity(noisy, clean, cfa="GRBG", bins=8)
    assert [c.colour for c in curves] == list("GRBG")
    for c, b1 in zip(curves, [1e-3, 2e-3, 2e-3, 4e-3]):
        th = b1 * c.mean_clean + 1e-5
        assert np.all(np.abs(c.variance - th) < 5 * c.variance_se)
