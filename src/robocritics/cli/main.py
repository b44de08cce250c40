"""The ``robocritics`` command.

Subcommands are built from a registry, :data:`SUBCOMMANDS`: each entry is a
function that adds its parser to argparse's subparsers and sets
``func=handler`` (a handler returns the exit code). One module per subcommand
registers itself with the :func:`subcommand` decorator::

    @subcommand("run")
    def _build_run(sub):
        p = sub.add_parser("run", help="...")
        p.add_argument(...)
        p.set_defaults(func=_cmd_run)

Exit codes: 0 success (``check``: no Error verdict), 1 ``check`` found an Error,
2 bad input (any :class:`~robocritics.errors.RoboCriticsError`, a missing file,
bad JSON, a bad argument), with a one-line message on stderr that names the
argument or file, never a traceback; 130 interrupted (Ctrl-C).
"""

from __future__ import annotations

import argparse
import gc
import importlib
import sys

from .._threads import single_threaded_blas
from ..errors import CriticError, RoboCriticsError
from ._common import SUBCOMMANDS, UsageError, one_line

__all__ = ["main", "build_parser"]

#: The built-in subcommands, each the module of that name here (in help order). A command line naming one
#: imports only that module: ``robocritics check`` does not pay for batch, deploy, studio or the LLM client.
BUILTIN = ("batch", "check", "critics", "deploy", "export", "fix", "run", "studio", "ursim")


def _register(names) -> None:
    for name in names:
        importlib.import_module(f"{__package__}.{name}")  # registers its builder in SUBCOMMANDS


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors: ``robocritics check: error: argument --rate: ...``."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {one_line(message)} (see {self.prog} --help)\n")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser of every subcommand, or with ``only`` (a built-in's name) of that one and any registered
    by other code."""
    _register(BUILTIN if only not in BUILTIN else (only,))
    parser = _Parser(
        prog="robocritics",
        description="LLM robot programming with expert-informed motion critics.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, builder in SUBCOMMANDS.items():
        if only not in BUILTIN or name == only or name not in BUILTIN:
            builder(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line ``argv`` (default ``sys.argv[1:]``); returns the exit status (never raises for bad
    input).

    A process running the command checks one program at a time: before anything loads numpy, BLAS is set to
    one thread (:mod:`robocritics._threads`; a value in the environment wins). With ``argv`` None this process
    is the command and ends when this returns, so its objects are then frozen (``gc.freeze``): the
    interpreter's exit would otherwise collect every module's function/class reference cycles one by one
    (~60 ms, a sixth of a cold ``check``'s CPU) just before the OS frees the memory anyway. ``atexit``
    handlers, ``weakref.finalize`` callbacks and the flushing of stdout/stderr run at exit as before.
    """
    single_threaded_blas()
    if argv is not None:
        return _run(list(argv))
    try:
        return _run(sys.argv[1:])
    finally:
        gc.freeze()


def _run(argv: list[str]) -> int:
    if argv[:1] == ["ursim"]:
        from .ursim import ursim_command

        return ursim_command(argv[1:])
    parser = build_parser(argv[0] if argv else None)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, or argparse's own usage error (status 2)
        return int(exc.code) if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    try:
        return int(args.func(args))
    except (CriticError, UsageError) as exc:
        print(f"robocritics: error: {one_line(exc)}", file=sys.stderr)
        return 2
    except RoboCriticsError as exc:
        print(f"robocritics: error: {type(exc).__name__}: {one_line(exc)}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # e.g. `robocritics critics | head`
        return 0
    except KeyboardInterrupt:
        print("robocritics: interrupted", file=sys.stderr)
        return 130
