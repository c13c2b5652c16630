"""benchmarks/render.py runs end to end on a tiny image (script correctness, not timing)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "render.py"


def load_script():
    spec = importlib.util.spec_from_file_location("simcam_bench_render", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_render_benchmark_quick_runs_and_agrees_with_libraw(tmp_path):
    pytest.importorskip("rawpy")
    mod = load_script()
    lines: list[str] = []
    res = mod.run_benchmark(384, 256, 1, workdir=tmp_path, out=lines.append)
    text = "\n".join(lines)
    for label in ("simcam bilinear", "simcam malvar2004", "rawpy LINEAR", "rawpy AHD"):
        assert f"| {label} |" in text
        assert len(res["results"][label]) == 1 and res["results"][label][0] > 0
    assert "| streamed: opcodes + normalize + " in text and " + demosaic + " in text
    assert "| read_dng |" in text and "Threads:" in text
    # The whole simcam render (DNG read, black/white, WB, demosaic, colour, sRGB curve) agrees
    # with LibRaw's on the synthetic chart: means of the 8-bit differences away from borders.
    # Measured ~2.4 levels for Malvar vs AHD (demosaicing differences in the zone plate);
    # a wrong white balance, matrix or transfer curve gives tens of levels.
    assert res["mean_abs_diff"]["simcam malvar2004"] < 5.0, res["mean_abs_diff"]
    assert res["mean_abs_diff"]["simcam bilinear"] < 8.0, res["mean_abs_diff"]


def test_render_benchmark_cli_quick_size(tmp_path, capsys):
    pytest.importorskip("rawpy")
    mod = load_script()
    mod.main(["--quick", "--size", "256x384", "--runs", "1", "--workdir", str(tmp_path)])
    out = capsys.readouterr().out
    assert "256x384 (0.1 MP), median of 1 runs" in out


def test_render_benchmark_rejects_bad_size():
    mod = load_script()
    with pytest.raises(SystemExit):
        mod.main(["--size", "12by5"])
