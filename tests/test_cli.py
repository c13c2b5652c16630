"""CLI behaviour: fast help, one-line errors with exit code 2, no partial outputs."""

from __future__ import annotations

import subprocess
import sys
import time

from simcam.cli import main


def run_cli(*args: str):
    return subprocess.run([sys.executable, "-m", "simcam", *args], capture_output=True, text=True)


def test_help_lists_commands_and_is_fast():
    t0 = time.perf_counter()
    r = run_cli("--help")
    elapsed = time.perf_counter() - t0
    assert r.returncode == 0
    for cmd in ("render", "validate"):
        assert cmd in r.stdout
    # Not a performance target: a guard against heavy imports at start-up
    # (the budget is 1 s; a loaded CI machine gets 3x slack).
    assert elapsed < 3.0


def test_help_does_not_import_heavy_modules():
    code = ("import sys; from simcam.cli import app; "
            "heavy = [m for m in ('rawpy', 'torch', 'onnxruntime', 'colour', 'scipy', 'OpenImageIO', 'matplotlib')"
            " if m in sys.modules]; print(','.join(heavy))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.strip() == "", r.stdout + r.stderr


def test_command_table_names_what_each_module_registers():
    """``simcam.cli.COMMANDS`` (which module a run of one command imports) against the modules themselves."""
    from simcam import cli

    names = {m: {c.name for c in cli.build_app([m]).registered_commands}
             | {g.name for g in cli.build_app([m]).registered_groups} for m in set(cli.COMMANDS.values())}
    assert {cmd: mod for mod, cmds in names.items() for cmd in cmds} == cli.COMMANDS
    everything = cli.build_app()
    assert {c.name for c in everything.registered_commands} | {g.name for g in everything.registered_groups} == set(
        cli.COMMANDS)


def test_one_command_imports_its_module_alone():
    code = ("import sys; from simcam.cli import main; main(['validate', '--help']); "
            "print(sorted(m for m in sys.modules if m.startswith('simcam.commands.')), file=sys.stderr)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0 and r.stderr.strip() == "['simcam.commands.render']", r.stderr


def test_validate_errors_are_one_line_with_exit_2(tmp_path, capsys):
    p = tmp_path / "bad.yaml"
    p.write_text("version: 1\nstages:\n  - type: normalise\n")
    assert main(["validate", str(p)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "stages[0].type" in err and "normalise" in err
    assert "Traceback" not in err


def test_validate_ok(tmp_path, capsys):
    p = tmp_path / "ok.yaml"
    p.write_text("version: 1\nstages:\n  - type: normalize\n  - type: crop\n")
    assert main(["validate", str(p)]) == 0
    assert "ok" in capsys.readouterr().out


def test_render_missing_input_exit_2_and_no_output(tmp_path):
    out = tmp_path / "o.png"
    r = run_cli("render", str(tmp_path / "missing.dng"), "-o", str(out))
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr and r.stderr.strip().count("\n") == 0
    assert not out.exists()


def test_render_bad_set_option(tmp_path):
    r = run_cli("render", "x.dng", "-o", str(tmp_path / "o.png"), "--set", "noequals")
    assert r.returncode == 2 and "STAGE.PARAM=VALUE" in r.stderr


def test_help_shows_no_python_types(capsys):
    """Options show PATH / INT / NUM / TEXT, flags nothing, arguments their name: never ``<bool>``,
    ``<path>`` or ``<list[Path]>`` (what typer >= 0.2x prints by itself)."""
    for cmd in ("render", "synth", "gt", "loop", "info", "bench", "validate"):
        assert main([cmd, "--help"]) == 0
        out = capsys.readouterr().out
        for bad in ("<bool>", "<path>", "<list[", "<int>", "<str>", "<float>"):
            assert bad not in out, (cmd, bad)
