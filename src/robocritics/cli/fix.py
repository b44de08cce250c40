"""``robocritics fix``: repair a program with the critics' own edits (no LLM) and print the diff and report."""

from __future__ import annotations

import argparse

from ._common import (
    UsageError,
    add_critic_options,
    add_goal_option,
    add_robot_options,
    check_output,
    file_name,
    load_params,
    one_line,
    read_text,
    robot_for,
    scene_for,
    subcommand,
    terminal_text,
)


@subcommand("fix")
def _build_fix(sub) -> None:
    p = sub.add_parser(
        "fix",
        help="repair a robot program with the critics' own edits (no LLM), verified by simulation",
        description="Simulate PROGRAM, let every critic that flags an Error or a Warning propose program edits from its "
        "evidence (slow only the offending moves, lift over an obstacle in transit, lower hover heights, release "
        "each object at its own spot, ...), re-simulate every candidate and keep those that improve the program "
        "(a bounded search: at most robocritics.repair.MAX_SIMULATIONS re-simulations), and print the diff, the "
        "changes with their cycle-time cost, the new report and what is left. -o writes the best program found even "
        "when something is left. Exit status: 0 the result has no Error, 1 an Error is left, 2 bad input.",
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
    p.add_argument("-o", "--output", metavar="OUT.py", type=file_name, help="write the repaired program here")
    p.set_defaults(func=_cmd_fix)


def _cmd_fix(args: argparse.Namespace) -> int:
    from .._files import OutputFileError, write_file_atomically
    from ..repair import repair

    source = read_text(args.program, "program")
    if args.output:  # before the repair, so a typo (or a link at the name) costs nothing
        check_output(args.output, "-o")
    scene = scene_for(args.program, args.scene)
    critics = [c.strip() for c in args.critics.split(",") if c.strip()] if args.critics else None
    result = repair(
        source, scene, goal=args.goals or None, critics=critics, robot=robot_for(args, scene), params=load_params(args.params)
    )
    print(terminal_text(result.diff) or "(no change)")  # the diff quotes the program's lines
    for change in result.changes:
        print(f"changed: {one_line(change)}")
    print(terminal_text(result.report.to_text()))
    left = [v for v in result.report.verdicts if v.flag.name != "OK"]
    for verdict in left:
        print(f"left: {verdict.critic} {verdict.flag.name}: {one_line(verdict.message)}")
    print(terminal_text(result.summary()))
    if args.output:
        try:
            write_file_atomically(args.output, result.program, "-o")
        except OutputFileError as exc:
            raise UsageError(str(exc)) from None
    return 1 if result.errors else 0
