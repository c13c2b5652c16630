"""The ``simcam`` command line (typer).

Commands live in ``simcam/commands/*.py``; each module defines
``register(app)``. Heavy imports (numpy, rawpy, torch, ...) happen inside the
commands so that ``simcam --help`` stays fast.

Every failure is one line on stderr:

* a :class:`~simcam.errors.SimcamError` (bad input) -> ``simcam CMD: error: ...``, exit 2;
* a usage error (unknown option or command, missing or malformed argument) -> one line and a
  usage hint on a second line, exit 2;
* any other exception inside a command -> ``simcam CMD: internal error: Type: message``,
  exit 1; the traceback is printed only with ``--debug`` or ``SIMCAM_DEBUG=1``.

typer >= 0.16 vendors click as ``typer._click`` and no longer installs ``click``; older typer
uses ``click`` itself. The exception classes are therefore taken from the classes typer exports
(:func:`_click_exceptions`), never from an ``import click``.
"""

from __future__ import annotations

import importlib
import os
import pkgutil
import sys
from types import ModuleType

import typer

CONTEXT_SETTINGS = {"help_option_names": ["-h", "--help"]}

#: command (or command group) -> the module of ``simcam.commands`` that registers it: a run of one command
#: imports that module alone (tests/test_cli.py checks the table against what the modules register)
COMMANDS = {"bench": "bench", "flow": "flow", "gt": "gt", "info": "info", "loop": "loop", "profile": "profile",
            "render": "render", "synth": "synth", "validate": "render"}


def _new_app() -> typer.Typer:
    a = typer.Typer(
        name="simcam",
        help="Camera-pipeline simulator and raw noise-synthesis toolkit.",
        no_args_is_help=True,
        add_completion=False,
        pretty_exceptions_enable=False,
        context_settings=CONTEXT_SETTINGS,
        rich_markup_mode=None,  # help texts are plain: "SeedSequence([seed, 0, i])" is not rich markup
    )
    a.callback()(_root)
    return a


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("simcam")
    except PackageNotFoundError:  # pragma: no cover - running from a source tree
        return "unknown"


def _show_version(value: bool) -> None:
    if value:
        typer.echo(f"simcam {_version()}")
        raise typer.Exit(0)


def _root(
    version: bool = typer.Option(False, "--version", is_eager=True, callback=_show_version,
                                 help="Print the version and exit."),
    debug: bool = typer.Option(False, "--debug", help="Print the traceback of an internal error."),
) -> None:
    """Camera-pipeline simulator and raw noise-synthesis toolkit."""


def _register_commands(target: typer.Typer, modules=None) -> None:
    """Register the commands of ``modules`` (names in ``simcam.commands``; all of them when None) on ``target``."""
    from . import commands

    names = sorted(m.name for m in pkgutil.iter_modules(commands.__path__) if not m.name.startswith("_")) \
        if modules is None else sorted(set(modules))
    for name in names:
        importlib.import_module(f"{commands.__name__}.{name}").register(target)


def build_app(modules=None) -> typer.Typer:
    """The command-line app with the commands of ``modules`` (all when None)."""
    a = _new_app()
    _register_commands(a, modules)
    _plain_metavars(a)
    return a


def _metavar(annotation) -> str:
    """A plain metavar for an option's type: PATH, INT, NUM, TEXT ('' for flags: no value to show)."""
    import typing
    from pathlib import Path

    while typing.get_origin(annotation) in (typing.Union, list) or str(typing.get_origin(annotation)) == \
            "<class 'types.UnionType'>":
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        annotation = args[0] if args else str
    return {bool: "", Path: "PATH", int: "INT", float: "NUM", str: "TEXT"}.get(annotation, "VALUE")


def _plain_metavars(typer_app: typer.Typer) -> None:
    """Options show PATH / INT / NUM / TEXT (typer >= 0.2x would print <path>, <list[str]>, <bool>)."""
    import inspect
    import typing

    for info in typer_app.registered_commands:
        fn = info.callback
        hints = typing.get_type_hints(fn)
        for name, param in inspect.signature(fn).parameters.items():
            d = param.default
            if isinstance(d, typer.models.OptionInfo) and d.metavar is None:
                d.metavar = _metavar(hints.get(name, str))
    for group in typer_app.registered_groups:
        _plain_metavars(group.typer_instance)


def _plain_argument_help() -> None:
    """Arguments show their metavar alone (``FILE``, ``INPUT...``): typer >= 0.2x adds the Python type
    (``<path>``, ``<list[Path]>``) after it, which tells a user nothing the metavar and help do not."""
    argument = getattr(typer.core, "TyperArgument", None)
    if argument is not None and hasattr(argument, "display_type_rich"):
        argument.display_type_rich = lambda self, ctx: None


_plain_argument_help()


def _full_app() -> typer.Typer:
    """``simcam.cli.app``, the app with every command, built on first use."""
    if "app" not in globals():
        globals()["app"] = build_app()
    return globals()["app"]


def __getattr__(name: str):
    """``simcam.cli.app`` (:func:`_full_app`; a run of one command builds an app with that command alone,
    :func:`main`)."""
    if name == "app":
        return _full_app()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _app_for(argv: list[str]) -> typer.Typer:
    """The app a run needs: the command module of the first word of ``argv`` when it names one of
    :data:`COMMANDS`, else every command (help, typos: the usage lists them all)."""
    if "app" in globals():  # built already (and perhaps extended by the caller): the one app
        return globals()["app"]
    word = next((a for a in argv if not a.startswith("-")), None)
    return build_app([COMMANDS[word]]) if word in COMMANDS else _full_app()


def _click_exceptions() -> ModuleType:
    """The ``exceptions`` module of the click that typer runs on (``typer._click`` or ``click``)."""
    package = typer.BadParameter.__module__.rpartition(".")[0]  # "typer._click.exceptions" -> "typer._click"
    return importlib.import_module(f"{package}.exceptions")


def _classes(module: ModuleType, name: str, *extra: type) -> tuple[type, ...]:
    """``module.name`` (when this click has it) together with ``extra``, as an ``except`` tuple."""
    found = getattr(module, name, None)
    return tuple(c for c in (found, *extra) if isinstance(c, type))


def _command_name(argv: list[str], group) -> str:
    """``simcam render`` / ``simcam profile import-darktable``: the words before the first option or argument
    (``group``: the app's click command)."""
    words = ["simcam"]
    for arg in argv:
        if arg.startswith("-"):
            continue
        sub = getattr(group, "commands", {}).get(arg) if hasattr(group, "commands") else None
        if sub is None:
            break
        words.append(arg)
        group = sub
    return " ".join(words)


def _usage_hint(exc) -> str:
    ctx = getattr(exc, "ctx", None)
    if ctx is None:
        return "usage: simcam COMMAND [OPTIONS] ... (simcam --help)"
    import re

    usage = " ".join(ctx.get_usage().replace("Usage:", "").split())
    usage = re.sub(r"\{(\w+)\}", lambda m: m.group(1).upper(), usage)  # typer >= 0.2x writes {input}
    return f"usage: {usage} ({ctx.command_path} --help)"


def main(argv: list[str] | None = None) -> int:
    """Run the app; turn every failure into one line on stderr and an exit code.

    Parameters
    ----------
    argv : list of str, optional
        Arguments without the program name (default ``sys.argv[1:]``).

    Returns
    -------
    int
        0 on success, 2 for bad input or usage, 1 for an internal error, 130 when interrupted.
    """
    import warnings

    from .errors import SimcamWarning

    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv or os.environ.get("SIMCAM_DEBUG", "") not in ("", "0")
    command = typer.main.get_command(_app_for(argv))
    name = _command_name(argv, command)
    if not argv:  # the help, as a usage error (click < 8.2 would exit 0 here, >= 8.2 exits 2)
        argv = ["--help"]
        usage_only = True
    else:
        usage_only = False

    def show(message, category, filename, lineno, file=None, line=None):
        # simcam's own warnings: one line each; a library's only with --debug (never raw)
        if issubclass(category, SimcamWarning) or debug:
            print(f"{name}: warning: {' '.join(str(message).split())}", file=sys.stderr)

    with warnings.catch_warnings():
        warnings.showwarning = show
        warnings.simplefilter("default")
        return _dispatch(command, argv, name=name, debug=debug, usage_only=usage_only)


def _dispatch(command, argv: list[str], *, name: str, debug: bool, usage_only: bool) -> int:
    """Run the app's click ``command`` once; map every outcome to (one line on stderr and) an exit status."""
    from .errors import SimcamError

    ce = _click_exceptions()
    try:
        rv = command.main(args=argv, prog_name="simcam", standalone_mode=False)
    except SimcamError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        return 130
    except _classes(ce, "Exit", typer.Exit) as exc:
        return 2 if usage_only else int(getattr(exc, "exit_code", 0) or 0)
    except ce.UsageError as exc:
        if type(exc).__name__ == "NoArgsIsHelpError":  # help already printed
            return 2
        print(f"{name}: error: {' '.join(exc.format_message().split())}", file=sys.stderr)
        print(_usage_hint(exc), file=sys.stderr)
        return 2
    except ce.ClickException as exc:  # click's own file / option errors
        print(f"{name}: error: {' '.join(exc.format_message().split())}", file=sys.stderr)
        return int(getattr(exc, "exit_code", 2) or 2)
    except _classes(ce, "Abort", typer.Abort):
        print(f"{name}: aborted", file=sys.stderr)
        return 1
    except Exception as exc:
        if debug:
            import traceback

            traceback.print_exc()
        message = " ".join(str(exc).split()) or "(no message)"
        print(f"{name}: internal error: {type(exc).__name__}: {message} "
              "(a bug in simcam; run with --debug or SIMCAM_DEBUG=1 for the traceback)", file=sys.stderr)
        return 1
    if usage_only:
        return 2
    return rv if isinstance(rv, int) and not isinstance(rv, bool) else 0




def entry() -> None:  # console_scripts target
    status = main()
    # The command is over: its outputs are written and closed. The interpreter's shutdown would now
    # walk every object the imports made (pydantic's and typer's schemas, numpy's, the stage models)
    # in its final garbage collections, ~0.05 s of a 0.6 s render; frozen, they are left to the OS
    # (reference counting, atexit hooks and flushes still run). Not once OpenImageIO is loaded: its
    # binding (nanobind) reports the instances still alive when it is torn down.
    if "OpenImageIO" not in sys.modules:
        import gc

        gc.freeze()
    sys.exit(status)
