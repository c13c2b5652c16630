"""The README's two set-up commands are exactly what .ci/run executes."""

from __future__ import annotations

import re

from shared_data import REPO


def setup_commands() -> list[str]:
    text = (REPO / "README.md").read_text()
    section = text.split("## Set-up", 1)[1]
    block = re.search(r"```bash\n(.*?)```", section, re.S).group(1)
    return [line.strip() for line in block.splitlines() if line.strip()]


def test_readme_has_two_setup_commands_and_ci_runs_them():
    cmds = setup_commands()
    assert len(cmds) == 2, cmds
    ci = [line.strip() for line in (REPO / ".ci" / "run").read_text().splitlines()
          if line.strip() and not line.lstrip().startswith("#")]
    for cmd in cmds:
        assert cmd in ci, f"README command not run by .ci/run: {cmd}"


def test_python_quick_start_runs_as_written(tmp_path, monkeypatch):
    """The README's Python quick start, executed as a user would paste it (from the repo root)."""
    text = (REPO / "README.md").read_text()
    section = text.split("### Python quick start", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    monkeypatch.chdir(REPO)
    ns: dict = {}
    exec(compile(code, "README.md: Python quick start", "exec"), ns)  # noqa: S102 - our own README
    assert ns["rgb"].ndim == 3 and ns["png8"].dtype.name == "uint8"
    assert ns["noisy"].shape == ns["raw"].data.shape
    assert tuple(ns["batch"]["noisy"].shape) == (8, 4, 64, 64)
