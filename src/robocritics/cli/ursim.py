"""``robocritics ursim``: a loopback UR controller until Ctrl-C (its options are the controller's own)."""

from __future__ import annotations

import argparse

from ._common import subcommand


@subcommand("ursim")
def _build_ursim(sub: "argparse._SubParsersAction") -> None:
    p = sub.add_parser(
        "ursim",
        help="run a loopback UR3e controller (RTDE, Dashboard, secondary interface) until Ctrl-C",
        add_help=False,
    )
    # its options belong to the controller's own parser; main() hands them over untouched
    p.set_defaults(func=lambda args: ursim_command([]))


def ursim_command(argv: list[str]) -> int:
    from ..testing.ursim import main as ursim_main

    try:
        return int(ursim_main(argv))
    except SystemExit as exc:  # --help (0) or a bad option (2, its one line already printed)
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
