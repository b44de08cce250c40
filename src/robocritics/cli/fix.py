"""``robocritics fix``: repair a program with the critics' own edits (no LLM) and print the diff and report."""

from __future__ import annotations

import argparse
from pathlib import Path

from ._common import (
    UsageError,
    add_critic_options,
    add_goal_option,
    add_robot_options,
    load_params,
    read_text,
    robot_for,
    scene_for,
    subcommand,
)


@subcommand("fix")
def _build_fix(sub) -> None:
    p = sub.add_parser(
        "fix",
        help="repair a robot program with the critics' own edits (no LLM), verified by simulation",
        description="Simulate PROGRAM, let every critic that flags an Error propose program edits from its evidence "
        "(slow only the offending moves, lower hover heights, avoid an object, ...), keep each edit only when the "
        "re-simulated program loses that flag without any verdict or goal getting worse, and print the diff, the "
        "changes and the new report. Exit status: 0 the result has no Error, 1 an Error is left, 2 bad input.",
    )
    p.add_argument("program", metavar="PROGRAM", help="robot program file (Python using the skill API)")
    p.add_argument(
        "--scene",
        metavar="NAME|PATH",
        help="built-in scene name or a scene JSON file; default: the built-in scene the file name starts with",
    )
    add_critic_options(p)
    add_goal_option(p)
    add_robot_options(p)
    p.add_argument("-o", "--output", metavar="OUT.py", help="write the repaired program here")
    p.set_defaults(func=_cmd_fix)


def _cmd_fix(args: argparse.Namespace) -> int:
    from ..repair import repair

    source = read_text(args.program, "program")
    if args.output and not Path(args.output).resolve().parent.is_dir():
        raise UsageError(f"-o {args.output}: the directory {Path(args.output).resolve().parent} does not exist")
    scene = scene_for(args.program, args.scene)
    critics = [c.strip() for c in args.critics.split(",") if c.strip()] if args.critics else None
    result = repair(
        source, scene, goal=args.goals or None, critics=critics, robot=robot_for(args, scene), params=load_params(args.params)
    )
    print(result.diff or "(no change)")
    for change in result.changes:
        print(f"changed: {change}")
    print(result.report.to_text())
    if args.output:
        try:
            Path(args.output).write_text(result.program)
        except OSError as exc:
            raise UsageError(f"-o {args.output}: cannot write: {exc.strerror or exc}") from None
    return 1 if result.errors else 0
