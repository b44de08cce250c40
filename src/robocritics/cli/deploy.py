"""``robocritics deploy``: simulate, critique and, if the gate passes, stream a program to a UR arm."""

from __future__ import annotations

import argparse
import sys

from ._common import read_text, scene_for, subcommand


@subcommand("deploy")
def _build_deploy(sub) -> None:
    p = sub.add_parser(
        "deploy",
        help="simulate, critique and, if the gate passes, stream a program to a UR arm over RTDE",
        description="Simulate PROGRAM, run every critic, and stream the verified trajectory to the UR controller at "
        "HOST (a UR3e, or `robocritics ursim`). The deploy gate refuses a report with an Error, a controller not in "
        "remote control or not NORMAL, and an arm that is not at the trajectory's start (use --approach). "
        "Exit status: 0 deployed, 1 refused or stopped by a fault, 2 bad input.",
    )
    p.add_argument("program", metavar="PROGRAM", help="robot program file (Python using the skill API)")
    p.add_argument("--scene", metavar="NAME|PATH", help="scene name or JSON file (default as for `check`)")
    p.add_argument("--host", default="127.0.0.1", help="controller address (default 127.0.0.1)")
    p.add_argument("--rtde-port", type=int, default=30004)
    p.add_argument("--dashboard-port", type=int, default=29999)
    p.add_argument("--secondary-port", type=int, default=30002)
    p.add_argument("--approach", action="store_true", help="first move slowly to the start configuration (critiqued too)")
    p.add_argument("--dry-run", action="store_true", help="do everything but send the program and move")
    p.set_defaults(func=_cmd_deploy)


def _cmd_deploy(args: argparse.Namespace) -> int:
    from ..critic import critique
    from ..errors import DeployError
    from ..simulate import simulate
    from ..deploy.stream import URArm

    scene = scene_for(args.program, args.scene)
    execution = simulate(read_text(args.program, "program"), scene)
    report = critique(execution.trajectory, execution.scene)
    print(report.to_text())
    try:
        with URArm(
            args.host, rtde_port=args.rtde_port, dashboard_port=args.dashboard_port, secondary_port=args.secondary_port
        ) as arm:
            if args.approach:
                approach, approach_report = arm.approach(execution)
                print(f"approach: {approach.trajectory.duration_s:.2f} s, score {approach_report.score:g}/10")
                arm.deploy(approach, approach_report, dry_run=args.dry_run)
            result = arm.deploy(execution, report, dry_run=args.dry_run)
    except DeployError as exc:
        print(f"robocritics: deploy stopped: {' '.join(str(exc).split())}", file=sys.stderr)
        return 1
    print(result)
    return 0
