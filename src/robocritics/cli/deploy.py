"""``robocritics deploy``: plan a program from where the arm is, critique it and, if the gate passes, stream it."""

from __future__ import annotations

import argparse
import sys

from .._text import safe_text
from ._common import add_robot_options, host, one_line, port, read_text, robot_for, scene_for, subcommand


REPORT_CHARS = 20_000
"""Most characters of the critics' report printed before deploying."""


@subcommand("deploy")
def _build_deploy(sub) -> None:
    p = sub.add_parser(
        "deploy",
        help="plan a program from the arm's joints, critique it and, if the gate passes, stream it to a UR arm",
        description="Connect to the UR controller at HOST (a UR3e, or `robocritics ursim`), read the arm's actual "
        "joints, simulate PROGRAM from there, run every critic, and stream the verified trajectory over RTDE. The "
        "deploy gate refuses a report with an Error and a controller that is not RUNNING, not NORMAL, not in remote "
        "control or already running a program. Exit status: 0 deployed (or, with --dry-run, the gate passed), "
        "1 refused or stopped by a fault, 2 bad input.",
    )
    p.add_argument("program", metavar="PROGRAM", help="robot program file (Python using the skill API)")
    p.add_argument("--scene", metavar="NAME|PATH", help="scene name or JSON file (default as for `check`)")
    p.add_argument("--host", type=host, default="127.0.0.1", help="controller address (default 127.0.0.1)")
    p.add_argument("--rtde-port", type=port, default=30004)
    p.add_argument("--dashboard-port", type=port, default=29999)
    p.add_argument("--secondary-port", type=port, default=30002)
    add_robot_options(p)
    p.add_argument("--dry-run", action="store_true", help="do everything but send the program and move")
    p.set_defaults(func=_cmd_deploy)


def _cmd_deploy(args: argparse.Namespace) -> int:
    from ..deploy import URArm
    from ..errors import DeployError
    from ..pipeline import check
    from ..program.sandbox import run_program

    scene = scene_for(args.program, args.scene)
    robot = robot_for(args, scene)  # a URDF's error is bad input, before connecting
    plan = run_program(read_text(args.program, "program"), scene)  # a bad program is reported before connecting
    try:
        with URArm(
            args.host, rtde_port=args.rtde_port, dashboard_port=args.dashboard_port, secondary_port=args.secondary_port
        ) as arm:
            start_q = arm.actual_q()
            execution, report = check(plan, scene, robot=robot, start_q=start_q)  # every installed critic gates the deploy
            print(f"planned from the arm's joints [{', '.join(f'{v:.4f}' for v in start_q)}] rad")
            print(safe_text(report.to_text(), REPORT_CHARS, newlines=True))  # it quotes names from the scene file
            result = arm.deploy(execution, report, dry_run=args.dry_run)
    except DeployError as exc:
        print(f"robocritics: deploy stopped: {one_line(exc)}", file=sys.stderr)
        return 1
    print(result.summary())
    return 0
