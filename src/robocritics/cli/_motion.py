"""``robocritics check FILE`` for motion from other tools: URScript, recordings, JointTrajectory, rosbag2.

The options a URScript file or a recording needs (``--tcp``, ``--payload``, ``--start-q``, ``--gripper-io``,
``--passes``, ``--topic``) and the check itself, called by :mod:`.check` when the file's type says so.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ._common import UsageError, bounded_float, check_output, load_params, one_line, positive_int, scene_for, terminal_text

__all__ = ["add_motion_options", "check_motion", "numbers"]


def numbers(count: int, what: str):
    def parse(text: str) -> tuple[float, ...]:
        try:
            values = tuple(float(v) for v in text.replace(" ", "").split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"{what}: {count} comma-separated numbers, got {text!r}") from None
        if len(values) != count or not all(abs(v) < 1e6 for v in values):
            raise argparse.ArgumentTypeError(f"{what}: {count} comma-separated finite numbers, got {text!r}")
        return values

    return parse


def add_motion_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("motion from other tools (URScript, recordings)")
    g.add_argument("--topic", metavar="TOPIC", help="rosbag2: the JointTrajectory or JointState topic (default: the only one)")
    g.add_argument(
        "--passes",
        type=positive_int,
        default=1,
        metavar="N",
        help="URScript: iterations judged of a loop that runs forever (PolyScope's 'loop forever') or waits on an "
        "input; default 1",
    )
    g.add_argument(
        "--tcp",
        type=numbers(6, "--tcp"),
        metavar="X,Y,Z,RX,RY,RZ",
        help="URScript: the installation's TCP (flange to TCP: m, rotation vector rad); a set_tcp in the script "
        "wins; default the robot model's gripper fingertips",
    )
    g.add_argument("--payload", type=bounded_float(0.0, 100.0, "kg"), default=0.0, metavar="KG", help="URScript: payload, kg")
    g.add_argument("--start-q", type=numbers(6, "--start-q"), metavar="Q0,...,Q5", help="URScript: start joints, rad (default: home)")
    g.add_argument(
        "--gripper-io", type=int, metavar="N", help="URScript: the digital output that closes the gripper when high"
    )


def check_motion(args: argparse.Namespace) -> int:
    from ..critic import runtime_report, select_critics
    from ..errors import PlanningError, ProgramError
    from ..formats import load_motion
    from ..formats.urscript import UnsupportedURScript
    from ..goals import parse_goals
    from ..pipeline import check
    from ..robot.model import Robot, default_robot

    if not Path(args.program).exists():
        raise UsageError(f"{args.program}: no such file")
    if args.html:
        check_output(args.html, "--html")
    scene = scene_for(args.program, args.scene)
    params = load_params(args.params)
    critics = [c.strip() for c in args.critics.split(",") if c.strip()] if args.critics else None
    if args.goals:
        raise UsageError(
            f"--goal: {args.program} is motion from another tool; it does not say what the gripper held, so goals "
            "cannot be checked (check the robot program instead)"
        )
    goals = parse_goals(args.goals, scene)
    select_critics(critics, params)
    robot = getattr(args, "robot", None)
    robot = robot if isinstance(robot, Robot) else (Robot.ur(robot) if robot else default_robot())
    try:
        execution = load_motion(
            args.program, robot, scene, topic=args.topic, rate_hz=args.rate, passes=args.passes, tcp=args.tcp,
            payload_kg=args.payload, start_q=args.start_q, gripper_io=args.gripper_io,
        )  # fmt: skip
    except UnsupportedURScript:
        raise  # outside the subset: bad input (exit 2), one line naming the construct and its line
    except (ProgramError, PlanningError) as exc:
        report = runtime_report(exc)
        print(report.to_json() if args.json else terminal_text(report.to_text()))  # it may quote the file
        print(f"robocritics: error: {type(exc).__name__}: {one_line(exc)}", file=sys.stderr)
        return 1
    report = check(execution, critics=critics, params=params, goals=goals).report
    print(report.to_json() if args.json else terminal_text(report.to_text()))  # it may quote the file
    if args.html:
        from .._files import OutputFileError, write_file_atomically
        from ..viz import replay_html

        page = replay_html(execution, report, title=f"{args.program}: {report.score_text}")
        try:
            write_file_atomically(args.html, page, "--html")
        except OutputFileError as exc:
            raise UsageError(str(exc)) from None
    return 1 if report.has_errors else 0
