"""``robocritics check``: simulate a program and print the critics' report."""

from __future__ import annotations

import argparse

from ._common import (
    UsageError,
    add_critic_options,
    add_robot_options,
    add_goal_option,
    check_output,
    file_name,
    load_params,
    one_line,
    read_text,
    robot_for,
    sample_rate,
    scene_for,
    subcommand,
    terminal_text,
)


@subcommand("check")
def _build_check(sub) -> None:
    p = sub.add_parser(
        "check",
        help="simulate a robot program and run the critics on its motion",
        description="Simulate PROGRAM in a scene, run the critics on the trajectory and print the report. "
        "The score is the 0-10 index of the five built-in motion critics; other critics are reported beside it. "
        "A program that does not run (rejected by the sandbox, or a motion that cannot be planned) gets a report "
        "with one 'runtime' Error naming the line. "
        "Exit status: 0 no Error verdict (from any critic), 1 at least one Error (or the program does not run), "
        "2 bad input.",
    )
    p.add_argument(
        "program",
        metavar="PROGRAM",
        help="robot program file (Python using the skill API), or motion from another tool: URScript (.script, "
        ".urscript), a ur_rtde or generic CSV recording, JointTrajectory JSON, MoveIt YAML, rosbag2 (.mcap, .db3) "
        "(docs/formats.md)",
    )
    p.add_argument(
        "--scene",
        metavar="NAME|PATH",
        help="built-in scene name (recycling, sorting, breakfast) or a scene JSON file; default: the built-in "
        "scene the program's file name starts with (sorting_naive.py -> sorting), else an empty table",
    )
    add_critic_options(p)
    add_goal_option(p)
    add_robot_options(p)
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument(
        "--html",
        metavar="OUT.html",
        type=file_name,
        help="also write the 3-D replay with its critic timeline and the report to one self-contained HTML file "
        "(no external URLs: it opens from file:// with no server)",
    )
    p.add_argument(
        "--rate",
        metavar="HZ",
        type=sample_rate,
        default=125.0,
        help="trajectory sample rate, Hz, from 25 (sparser sampling hides fast motion from the critics) to 500 "
        "(the controller's rate); default 125",
    )
    from ._motion import add_motion_options

    add_motion_options(p)
    p.set_defaults(func=_cmd_check)


def _cmd_check(args: argparse.Namespace) -> int:
    """One check with the cyclic garbage collector paused (and restored after).

    A check is one bounded run: the garbage it can leave in reference cycles is bounded by the sandbox's budget
    (100,000 steps, 50 MB of values) and the motion budget, a few MB at most. Collecting would mostly re-walk
    the ~40,000 objects the check path's imports create as they age through the generations: ~20 ms, 5 % of
    a cold check's CPU.
    """
    import gc

    paused = gc.isenabled()
    gc.disable()
    try:
        return _check(args)
    finally:
        if paused:
            gc.enable()


def _check(args: argparse.Namespace) -> int:
    import sys

    from ..goals import parse_goals
    from ..pipeline import check

    from ..formats import motion_kind

    if motion_kind(args.program) is not None:
        from ._motion import check_motion

        return check_motion(args)
    source = read_text(args.program, "program")
    if args.html:  # checked before simulating, so a typo (or a link at the name) costs nothing
        check_output(args.html, "--html")
    scene = scene_for(args.program, args.scene)
    params = load_params(args.params)
    critics = [c.strip() for c in args.critics.split(",") if c.strip()] if args.critics else None
    goals = parse_goals(args.goals, scene)  # GoalError naming a wrong id, before simulating
    robot = robot_for(args, scene)
    execution, report = check(source, scene, goals=goals, critics=critics, params=params, robot=robot,
                              sample_rate_hz=args.rate)  # fmt: skip
    print(report.to_json() if args.json else terminal_text(report.to_text()))  # it quotes the program
    if execution is None:  # the program did not run: its error, as before, beside the report
        verdict = report.verdicts[0]
        print(f"robocritics: error: {verdict.details['error']}: {one_line(verdict.details['text'])}", file=sys.stderr)
        if args.html:
            print(f"robocritics: no replay written to {args.html}: the program did not run", file=sys.stderr)
        return 1
    if args.html:
        from .._files import OutputFileError, write_file_atomically
        from ..viz import replay_html

        page = replay_html(execution, report, title=f"{args.program} in {scene.name}: {report.score_text}")
        try:
            write_file_atomically(args.html, page, "--html")
        except OutputFileError as exc:
            raise UsageError(str(exc)) from None
    return 1 if report.has_errors else 0
