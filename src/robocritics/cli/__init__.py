"""The ``robocritics`` command line: one module per subcommand (``check``, ``critics``, ``run``, ``deploy``, ``ursim``)."""

from ._common import SUBCOMMANDS, UsageError, subcommand
from .main import build_parser, main

__all__ = ["main", "build_parser", "subcommand", "SUBCOMMANDS", "UsageError"]
