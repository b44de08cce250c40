"""``robocritics ursim`` / ``python -m robocritics.testing.ursim``: the loopback controller until Ctrl-C."""

from __future__ import annotations

import argparse
import logging
import math
import sys
import time
from typing import Sequence

from robocritics._text import safe_text
from robocritics.errors import DeployError
from robocritics.robot.arms import ARMS
from robocritics.testing.ursim.controller import DEFAULT_ROBOT_MODE, URSim

__all__ = ["main"]


class _OneLineParser(argparse.ArgumentParser):
    """Bad options end in one line on stderr (not the usage block) and exit status 2."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {safe_text(' '.join(message.split()), 500)} (see {self.prog} --help)\n")


def _port_arg(text: str) -> int:
    try:
        value = int(text) if len(text) <= 5 else None
    except ValueError:
        value = None
    if value is None or not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"{safe_text(text, 40)!r} is not a TCP port (a whole number from 0 to 65535)")
    return value


def _finite_arg(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{safe_text(text, 40)!r} is not a finite number")
    return value


def main(argv: Sequence[str] | None = None) -> int:
    """``robocritics ursim``: run the loopback controller until Ctrl-C. Bad options: one line on stderr, exit 2."""
    ap = _OneLineParser(prog="robocritics ursim", description="Loopback UR3e controller (RTDE, Dashboard, secondary interface) on 127.0.0.1.")
    ap.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    ap.add_argument("--rtde-port", type=_port_arg, default=30004, help="RTDE port (0 = any free port; default 30004)")
    ap.add_argument("--dashboard-port", type=_port_arg, default=29999, help="Dashboard port (default 29999)")
    ap.add_argument("--secondary-port", type=_port_arg, default=30002, help="secondary interface port (default 30002)")
    ap.add_argument("--initial-q", type=_finite_arg, nargs=6, metavar="RAD",
                    help="initial joint positions [rad] (default the robot model's home pose, where `simulate` starts)")
    ap.add_argument("--robot-mode", default=DEFAULT_ROBOT_MODE, choices=["POWER_OFF", "IDLE", "RUNNING"],
                    help=f"initial robot mode (default {DEFAULT_ROBOT_MODE})")
    ap.add_argument("--local-control", action="store_true", help="start in local control (programs are refused)")
    ap.add_argument("--fieldbus", action="store_true", help="a fieldbus holds input registers 0-23")
    ap.add_argument("--protocol", type=int, choices=[1, 2], default=2, help="highest RTDE protocol version accepted")
    ap.add_argument("--model", default="ur3e", choices=list(ARMS),
                    help="which arm to be: home pose, speed limits, 'get robot model' answer (default ur3e)")
    ap.add_argument("-v", "--verbose", action="store_true", help="log every event")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(asctime)s %(message)s")
    try:
        sim = URSim(
            host=args.host,
            rtde_port=args.rtde_port,
            dashboard_port=args.dashboard_port,
            secondary_port=args.secondary_port,
            initial_q=args.initial_q,
            robot_mode=args.robot_mode,
            remote_control=not args.local_control,
            fieldbus_registers=args.fieldbus,
            protocol_versions=tuple(range(1, args.protocol + 1)),
            model=args.model,
        )
        sim.start()
    except DeployError as exc:
        print(f"robocritics ursim: error: {safe_text(' '.join(str(exc).split()), 500)}", file=sys.stderr)
        return 2
    print(
        f"URSim on {sim.host}: RTDE {sim.rtde_port}, dashboard {sim.dashboard_port}, "
        f"secondary {sim.secondary_port} — Ctrl-C to stop",
        flush=True,
    )
    try:
        while True:
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    finally:
        sim.stop()
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
