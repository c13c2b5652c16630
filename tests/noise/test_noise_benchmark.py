"""Smoke test of benchmarks/noise.py (--quick): it runs and prints the Markdown table."""

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_benchmark_quick_runs():
    r = subprocess.run([sys.executable, str(REPO / "benchmarks" / "noise.py"), "--quick"], capture_output=True, text=True,
                       cwd=REPO)
    assert r.returncode == 0, r.stderr
    assert "| sampler | MP/s | ratio |" in r.stdout
    assert "numpy poisson" in r.stdout and "simcam poisson_gaussian exact" in r.stdout
