"""``robocritics export``: a checked trajectory as URScript, JointTrajectory JSON or CSV."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ._common import UsageError, check_output, one_line, read_text, sample_rate, scene_for, subcommand


@subcommand("export")
def _build_export(sub) -> None:
    p = sub.add_parser(
        "export",
        help="export a checked trajectory as URScript, JointTrajectory JSON or CSV",
        description="Simulate PROGRAM (or read a motion file, as `check` does), critique it and write its "
        "trajectory for another tool: --to urscript (a servoj program a UR pendant runs, with the planned "
        "timing), jointtrajectory (trajectory_msgs/JointTrajectory JSON for MoveIt/ros2_control) or csv. The "
        "report's summary goes to stderr. Exit status: 0 written, 1 the program does not run, 2 bad input.",
    )
    p.add_argument("program", metavar="PROGRAM", help="robot program file, or a motion file (docs/formats.md)")
    p.add_argument("--to", required=True, choices=("urscript", "jointtrajectory", "csv"), help="output format")
    p.add_argument("-o", "--output", metavar="OUT", help="output file (default: stdout)")
    p.add_argument("--scene", metavar="NAME|PATH", help="scene name or JSON file (default as for `check`)")
    p.add_argument("--rate", metavar="HZ", type=sample_rate, default=125.0, help="samples per second written; default 125")
    p.set_defaults(func=_cmd_export)


def _cmd_export(args: argparse.Namespace) -> int:
    from ..pipeline import check
    from ..formats import load_motion, motion_kind
    from ..formats.export import to_csv, to_joint_trajectory, to_urscript

    if args.output:
        check_output(args.output, "-o")
    scene = scene_for(args.program, args.scene)
    if motion_kind(args.program) is not None:
        execution, report = check(load_motion(args.program, scene=scene, rate_hz=args.rate))
    else:
        execution, report = check(read_text(args.program, "program"), scene, sample_rate_hz=args.rate)
    if execution is None:
        verdict = report.verdicts[0]
        print(f"robocritics: error: {verdict.details['error']}: {one_line(verdict.details['text'])}", file=sys.stderr)
        return 1
    trajectory = execution.trajectory
    if args.to == "urscript":
        comment = f"{Path(args.program).name} in {scene.name}: {report.summary()}"
        text = to_urscript(trajectory, rate_hz=args.rate, comment=comment)
    elif args.to == "jointtrajectory":
        text = to_joint_trajectory(trajectory, rate_hz=args.rate)
    else:
        text = to_csv(trajectory, rate_hz=args.rate)
    print(f"robocritics: {report.summary()}", file=sys.stderr)
    if report.has_errors:
        print("robocritics: warning: the report has Errors; fix them before running this motion", file=sys.stderr)
    if args.output:
        from .._files import OutputFileError, write_file_atomically

        try:
            write_file_atomically(args.output, text, "-o")
        except OutputFileError as exc:
            raise UsageError(str(exc)) from None
    else:
        sys.stdout.write(text)
    return 0
