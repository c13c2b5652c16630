"""Registry-driven stage tests (albumentations style).

Every registered stage needs an entry in STAGE_CASES: a parameter node and the kind
of frame to feed it. A stage registered without an entry fails ``test_every_stage_has_a_case``.
Each case checks the contract: builds from its YAML node, round-trips ``to_node``,
produces the kind it declares as float32 of the right shape, and is deterministic
(random stages: same rng seed -> same bytes).
"""

from __future__ import annotations

import numpy as np
import pytest

from simcam.frame import MOSAIC_KINDS, RawFrame
from simcam.io.sample_dng import radial_gain_maps, synthetic_meta
from simcam.pipeline import build_stage
from simcam.stages.base import stage_types

H, W = 16, 24

#: type -> (params node, input kind)
STAGE_CASES: dict[str, tuple[dict, str]] = {
    "normalize": ({}, "raw_dn"),
    "crop": ({"region": "explicit", "rect": [2, 4, 12, 20]}, "raw"),
    "lens_shading": ({}, "raw"),
    "white_balance": ({"source": "as_shot"}, "raw"),
    "demosaic": ({"method": "malvar2004"}, "raw"),
    "camera_to_xyz": ({}, "camera_rgb"),
    "xyz_to_srgb": ({}, "xyz"),
    "tone": ({"curve": "sidd"}, "linear_srgb"),
    "gamma": ({"curve": "srgb"}, "linear_srgb"),
    "orientation": ({"value": 6}, "display"),
    "clip": ({}, "linear_srgb"),
    "quantize": ({"bits": 8}, "display"),
    "noise": ({"model": {"type": "nlf", "beta1": 1.0e-3, "beta2": 1.0e-5}}, "raw"),
    "clip_raw": ({}, "raw"),
    "highlights": ({"method": "propagate"}, "raw"),
    "opcodes": ({"list": 2}, "raw"),
    "dcp": ({"exposure": 0.5}, "camera_rgb"),
}


def make_frame(kind: str) -> RawFrame:
    rng = np.random.default_rng(1)
    meta = synthetic_meta("GRBG", black=64.0, white=1023.0, active_area=(0, 0, H, W),
                          opcode_list2=radial_gain_maps(H, W))
    if kind == "raw_dn":
        data = rng.uniform(64, 1023, (H, W))
    elif kind in MOSAIC_KINDS:
        data = rng.uniform(0.0, 1.0, (H, W))
    else:
        data = rng.uniform(0.0, 1.0, (H, W, 3))
    return RawFrame(data.astype(np.float32), meta, kind=kind)


def registered():
    return sorted(k for k in stage_types() if not k.startswith("_"))


def test_every_stage_has_a_case():
    missing = [k for k in registered() if k not in STAGE_CASES]
    assert not missing, f"stages without a test case in STAGE_CASES: {missing}"


@pytest.mark.parametrize("key", registered())
def test_stage_contract(key):
    if key not in STAGE_CASES:
        pytest.fail(f"no STAGE_CASES entry for {key!r}")
    params, kind = STAGE_CASES[key]
    stage = build_stage({"type": key, **params}, where=f"case {key}")
    again = build_stage(stage.to_node(), where=f"case {key} (round trip)")
    assert again.to_node() == stage.to_node()
    assert kind in stage.accepts
    frame = make_frame(kind)
    before = frame.data.copy()

    def run():
        rng = np.random.default_rng(123) if stage.random else None
        return stage(frame, rng)

    out1, out2 = run(), run()
    assert np.array_equal(frame.data, before), "a stage must not modify its input in place"
    assert out1.kind == stage.output_kind(kind)
    assert out1.data.dtype == np.float32
    assert out1.data.ndim == (2 if out1.kind in MOSAIC_KINDS else 3)
    assert out1.data.tobytes() == out2.data.tobytes(), "same input (and seed) must give the same bytes"


def test_stage_kinds_are_valid():
    from simcam.frame import SIGNAL_KINDS

    for key, cls in stage_types().items():
        assert cls.accepts and set(cls.accepts) <= set(SIGNAL_KINDS), key
        assert cls.produces is None or cls.produces in SIGNAL_KINDS, key


def test_the_builtin_table_names_every_stage_module_registers():
    """``BUILTIN_STAGES`` (type -> module, imported on first use) is what the modules of simcam.stages define."""
    import importlib
    import pkgutil

    import simcam.stages
    from simcam.stages.base import BUILTIN_STAGES

    found = {}
    for mod in pkgutil.iter_modules(simcam.stages.__path__):
        if mod.name != "base" and not mod.name.startswith("_"):
            m = importlib.import_module(f"simcam.stages.{mod.name}")
            for cls in vars(m).values():
                if isinstance(cls, type) and cls.__module__ == m.__name__ and isinstance(getattr(cls, "type", None), str):
                    found[cls.type] = mod.name
    assert found == BUILTIN_STAGES


def test_a_pipeline_imports_only_the_stage_modules_it_names():
    import subprocess
    import sys

    code = ("import sys; from simcam.pipeline import Pipeline; Pipeline.from_yaml('srgb'); "
            "print(sorted(m for m in sys.modules if m.startswith('simcam.stages.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "simcam.stages.demosaic" in out and "simcam.stages.raw" in out
    assert "simcam.stages.dcp" not in out and "simcam.stages.noise" not in out


def test_a_user_stage_cannot_take_a_builtin_name_not_yet_imported():
    import subprocess
    import sys

    code = ("from simcam.stages.base import Stage, register_stage\n"
            "try:\n"
            "    @register_stage\n"
            "    class Mine(Stage, type='dcp'):\n"
            "        pass\n"
            "except TypeError as exc:\n"
            "    print(exc)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "registered twice" in out, out
