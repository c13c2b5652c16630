"""Every CLI failure is one clear line (issue: "Every failure is one clear line").

Usage errors: one line plus a usage hint, exit 2. Bad input: one line, exit 2, before any work
and without partial outputs. Anything else: one line naming the command and the exception,
exit 1, the traceback only with ``--debug`` / ``SIMCAM_DEBUG=1``. Run in subprocesses with the
installed typer (CI installs the newest the bounds allow into a fresh venv).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from simcam.cli import app, main

REPO = Path(__file__).resolve().parent.parent
CHART = REPO / "examples" / "data" / "chart.dng"


def run_cli(*args: str, env: dict | None = None):
    return subprocess.run([sys.executable, "-m", "simcam", *args], capture_output=True, text=True,
                          env={**os.environ, **(env or {})}, cwd=REPO)


def assert_clean_error(r, code: int, *needles: str, max_lines: int = 1):
    err = r.stderr.strip()
    assert r.returncode == code, (r.returncode, r.stderr)
    assert "Traceback" not in err, err
    assert 1 <= len(err.splitlines()) <= max_lines, err
    for n in needles:
        assert n in err, (n, err)


@pytest.mark.parametrize("args, needle", [
    (("render",), "Missing argument"),
    (("render", "--bogus", "x"), "No such option: --bogus"),
    (("synth", "x.dng", "-o", "y", "--profile", "p.yaml", "--iso", "abc"), "'--iso'"),
    (("synth", "x.dng", "-o", "y", "--profile", "p.yaml", "--iso", "800", "--frames", "0"), "'--frames'"),
    (("foo",), "No such command 'foo'"),
    (("profile", "import-darktable"), "Missing argument"),
    (("gt",), "Missing argument"),
])
def test_usage_errors_are_one_line_and_a_hint(args, needle):
    r = run_cli(*args)
    assert_clean_error(r, 2, needle, "simcam", max_lines=2)
    assert r.stderr.strip().splitlines()[-1].startswith("usage: simcam")


def test_no_arguments_prints_help_and_exits_2():
    r = run_cli()
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "render" in r.stdout


@pytest.mark.parametrize("flag", ["-h", "--help"])
def test_help_flags(flag):
    for args in ((flag,), ("render", flag), ("profile", flag), ("flow", "train", flag)):
        r = run_cli(*args)
        assert r.returncode == 0 and "Usage" in r.stdout and r.stderr == "", (args, r.stderr)


def test_version():
    from importlib.metadata import version

    r = run_cli("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"simcam {version('simcam')}"


@pytest.fixture
def boom_command():
    """A temporary command that fails with an unexpected exception."""
    def boom() -> None:
        raise RuntimeError("kaput\nsecond line")

    app.command("boom")(boom)
    yield
    app.registered_commands[:] = [c for c in app.registered_commands if c.name != "boom"]


def test_internal_error_is_one_line_exit_1(boom_command, capsys, monkeypatch):
    monkeypatch.delenv("SIMCAM_DEBUG", raising=False)
    assert main(["boom"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert err.startswith("simcam boom: internal error: RuntimeError: kaput second line")


def test_internal_error_traceback_with_debug(boom_command, capsys, monkeypatch):
    assert main(["--debug", "boom"]) == 1
    assert "Traceback" in capsys.readouterr().err
    monkeypatch.setenv("SIMCAM_DEBUG", "1")
    assert main(["boom"]) == 1
    assert "Traceback" in capsys.readouterr().err


def test_render_into_an_existing_folder_writes_input_name(tmp_path):
    """An existing folder as -o is the batch form (``simcam render IN... -o DIR``): DIR/<stem>.png."""
    r = run_cli("render", str(CHART), "-o", str(tmp_path), "--workers", "0")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "chart.png").exists()


def test_render_output_is_a_file_where_a_folder_is_expected(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    r = run_cli("render", str(CHART), str(CHART), "-o", str(f), "--workers", "0")
    assert_clean_error(r, 2, str(f), "is a file; expected a folder")


def test_render_output_folder_missing(tmp_path):
    out = tmp_path / "missing" / "x.png"
    r = run_cli("render", str(CHART), "-o", str(out))
    assert_clean_error(r, 2, "does not exist", str(tmp_path / "missing"))
    assert not (tmp_path / "missing").exists()


def test_render_success_has_empty_stderr(tmp_path):
    r = run_cli("render", str(CHART), "-o", str(tmp_path / "c.png"))
    assert r.returncode == 0 and r.stderr == "", r.stderr


def test_gt_missing_output_folder_fails_before_work(tmp_path):
    """The output is checked before the burst is even looked at (the burst folder here does not exist)."""
    r = run_cli("gt", str(tmp_path / "no_burst"), "-o", str(tmp_path / "missing" / "gt.npz"))
    assert_clean_error(r, 2, "gt.npz", "does not exist")


def test_synth_nan_clean_names_the_input_and_leaves_no_folder(tmp_path):
    import tifffile

    clean = np.full((8, 8), 0.25, np.float32)
    clean[3, 4] = np.nan
    tif = tmp_path / "clean.tif"
    tifffile.imwrite(tif, clean)
    out = tmp_path / "out"
    r = run_cli("synth", str(tif), "-o", str(out), "--profile", str(REPO / "profiles" / "sidd-gp.yaml"),
                "--iso", "800")
    assert_clean_error(r, 2, str(tif), "NaN")
    assert not out.exists()


def test_synth_output_is_a_file(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    r = run_cli("synth", str(CHART), "-o", str(f), "--profile", str(REPO / "profiles" / "sidd-gp.yaml"),
                "--iso", "800")
    assert_clean_error(r, 2, str(f), "is a file; expected a folder")


def test_loop_on_a_dng_file_is_one_line(tmp_path):
    r = run_cli("loop", str(CHART), "--out", str(tmp_path / "rep"))
    assert_clean_error(r, 2, str(CHART), "not a text file")
    assert not (tmp_path / "rep").exists()


def test_flow_checkpoint_is_data_never_code(tmp_path):
    """A crafted pickle that would run a command is refused; the command never runs."""
    torch = pytest.importorskip("torch")
    marker = tmp_path / "pwned"

    class Evil:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    ckpt = tmp_path / "evil.pt"
    torch.save({"format": "simcam-noiseflow/1", "config": {}, "state_dict": {}, "payload": Evil()}, str(ckpt))
    r = run_cli("flow", "export", str(ckpt), "-o", str(tmp_path / "m.onnx"))
    assert_clean_error(r, 2, str(ckpt), "weights_only=True")
    assert not marker.exists()
    assert not (tmp_path / "m.onnx").exists()


def test_yaml_bomb_in_pipeline_is_refused_before_output(tmp_path):
    lines = ["version: 1", "a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 9)]
    lines += ["stages:", "  - type: normalize"]
    pipe = tmp_path / "bomb.yaml"
    pipe.write_text("\n".join(lines) + "\n")
    out = tmp_path / "o.png"
    for args in (("validate", str(pipe)), ("render", str(CHART), "-o", str(out), "-p", str(pipe))):
        r = run_cli(*args)
        assert_clean_error(r, 2, str(pipe), "aliases")
    assert not out.exists()


def test_profile_with_aliases_is_refused(tmp_path):
    from simcam.errors import ProfileError
    from simcam.profiles import load_profile

    p = tmp_path / "p.yaml"
    p.write_text("schema: 1\nx: &x {a: 1}\ny: *x\n")
    with pytest.raises(ProfileError, match="aliases"):
        load_profile(p)
