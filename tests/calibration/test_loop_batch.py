"""``simcam loop SET... --out DIR`` on dask: the same reports as the serial path; a bad set fails alone."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from loop_generator import DEFAULT_EFFECTS, SensorSpec, capture_set, write_capture_set

pytest.importorskip("distributed")

REPO = Path(__file__).resolve().parents[2]


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "simcam", *map(str, args)], capture_output=True, text=True, cwd=REPO)


def test_loop_batch_two_workers_same_bytes_as_serial(tmp_path):
    sets = []
    for name, effects in (("base", ()), ("fpn", ("column_fpn",))):
        spec = SensorSpec(effects={e: DEFAULT_EFFECTS[e] for e in effects})
        sets.append(write_capture_set(tmp_path / "in" / name, capture_set(spec)))
    bad = tmp_path / "in" / "bad"
    (bad / "dark").mkdir(parents=True)
    (bad / "dark" / "frame_000.npy").write_bytes(b"not numpy")
    sets.append(bad)
    runs = {}
    for w in (2, 0):
        out = tmp_path / f"w{w}"
        r = run_cli("loop", *sets, "--out", out, "--workers", w, "--replicates", 8)
        assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
        failed = [ln for ln in r.stderr.splitlines() if "failed:" in ln]
        assert len(failed) == 1 and "bad" in failed[0]
        runs[w] = {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}
        assert not (out / "bad").exists() or not any((out / "bad").iterdir())
    assert sorted(runs[2]) == sorted(runs[0]) and "fpn/report.json" in runs[2]
    assert runs[2] == runs[0]
