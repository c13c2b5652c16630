"""The ``simcam`` command line (typer).

Commands live in ``simcam/commands/*.py``; each module defines
``register(app)``. Heavy imports (numpy, rawpy, torch, ...) happen inside the
commands so that ``simcam --help`` stays fast. A :class:`SimcamError` is
printed as one line on stderr with exit code 2, never as a traceback.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys

import typer

app = typer.Typer(
    name="simcam",
    help="Camera-pipeline simulator and raw noise-synthesis toolkit.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _register_commands() -> None:
    from . import commands

    for mod in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if not mod.name.startswith("_"):
            importlib.import_module(f"{commands.__name__}.{mod.name}").register(app)


_register_commands()


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the app, turning SimcamError into one line and exit code 2."""
    from .errors import SimcamError

    try:
        app(args=argv, standalone_mode=False)
    except SimcamError as exc:
        print(f"simcam: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("simcam: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # click usage errors and friends
        import click

        if isinstance(exc, click.exceptions.Exit):
            return exc.exit_code
        if isinstance(exc, click.ClickException):
            exc.show()
            return 2
        if isinstance(exc, click.exceptions.Abort):
            return 1
        raise
    return 0


def entry() -> None:  # console_scripts target
    sys.exit(main())
