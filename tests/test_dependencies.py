"""simcam imports only what pyproject.toml declares.

typer >= 0.16 stopped installing ``click``; an ``import click`` kept working on machines that
still had it and broke every usage error on a new one. This test parses every module of the
package and fails on an import of a distribution that is not a declared dependency (core or an
extra).
"""

from __future__ import annotations

import ast
import re
import sys
import tomllib
from importlib.metadata import packages_distributions
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def declared() -> set[str]:
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    reqs = list(project["dependencies"])
    for extra in project.get("optional-dependencies", {}).values():
        reqs += extra
    return {_norm(re.split(r"[\s<>=!~\[;]", r, maxsplit=1)[0]) for r in reqs}


def imported_top_level() -> dict[str, str]:
    """Top-level module -> first file importing it (absolute imports only)."""
    found: dict[str, str] = {}
    for path in sorted((REPO / "simcam").rglob("*.py")):
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for n in names:
                found.setdefault(n.split(".")[0], str(path.relative_to(REPO)))
    return found


def test_every_import_is_declared():
    dists = packages_distributions()
    decl = declared()
    missing = []
    for mod, where in sorted(imported_top_level().items()):
        if mod == "simcam" or mod in sys.stdlib_module_names:
            continue
        provided_by = {_norm(d) for d in dists.get(mod, [])}
        if not provided_by & decl:
            missing.append(f"{mod} (in {where}; installed from {sorted(provided_by) or 'nothing'})")
    assert not missing, "imports of undeclared distributions: " + "; ".join(missing)
