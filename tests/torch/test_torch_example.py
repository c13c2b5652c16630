"""The GPU-noise training example runs end to end at tiny size on the CPU (in a subprocess, < 60 s)."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_train_denoiser_example_runs_tiny():
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "train_denoiser_gpu_noise.py"), "--tiny",
                        "--device", "cpu"], capture_output=True, text=True, timeout=60, env=env, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("step")]
    assert len(lines) == 2 and "done: 3 steps of 4 x 4x16x16 on cpu" in r.stdout
