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
import sys

from ..errors import CriticError, RoboCriticsError
from . import batch, check, critics, deploy, fix, run, studio, ursim  # noqa: F401  (each registers its subcommand)
from ._common import SUBCOMMANDS, UsageError, one_line
from .ursim import ursim_command

__all__ = ["main", "build_parser"]


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors: ``robocritics check: error: argument --rate: ...``."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {one_line(message)} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="robocritics",
        description="LLM robot programming with expert-informed motion critics.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for builder in SUBCOMMANDS.values():
        builder(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status (never raises for bad input)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["ursim"]:
        return ursim_command(argv[1:])
    parser = build_parser()
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
