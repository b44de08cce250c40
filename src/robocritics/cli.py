"""The ``robocritics`` command.

Subcommands are built from a registry, :data:`SUBCOMMANDS`: each entry is a
function that adds its parser to argparse's subparsers and sets
``func=handler`` (a handler returns the exit code). Add one with the
:func:`subcommand` decorator::

    @subcommand("run")
    def _build_run(sub):
        p = sub.add_parser("run", help="...")
        p.add_argument(...)
        p.set_defaults(func=_cmd_run)

Exit codes: 0 success (``check``: no Error verdict), 1 ``check`` found an Error,
2 bad input (any :class:`~robocritics.errors.RoboCriticsError`, a missing file,
bad JSON), with a one-line message on stderr.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Callable

from .errors import CriticError, RoboCriticsError

__all__ = ["main", "build_parser", "subcommand", "SUBCOMMANDS", "UsageError"]

Builder = Callable[["argparse._SubParsersAction"], None]

#: name -> builder(subparsers); parsers are added in this order.
SUBCOMMANDS: dict[str, Builder] = {}


class UsageError(RoboCriticsError):
    """Bad command-line input that is not a library error (a missing file, bad JSON)."""


def subcommand(name: str) -> Callable[[Builder], Builder]:
    """Register a subcommand builder under ``name`` (replacing any earlier one of that name)."""

    def decorate(builder: Builder) -> Builder:
        SUBCOMMANDS[name] = builder
        return builder

    return decorate


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"{text!r} must be a positive number")
    return value


def _read_text(path: str, what: str) -> str:
    p = Path(path)
    try:
        return p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise UsageError(f"no such {what} file {path!r}") from None
    except IsADirectoryError:
        raise UsageError(f"{what} {path!r} is a directory, not a file") from None
    except UnicodeDecodeError as exc:
        raise UsageError(f"{what} file {path!r} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise UsageError(f"cannot read {what} file {path!r}: {exc.strerror}") from None


def _load_params(path: str | None) -> dict:
    if not path:
        return {}
    text = _read_text(path, "params")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise UsageError(f"params file {path!r} is not valid JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}") from None
    if not isinstance(data, dict) or not all(isinstance(v, dict) for v in data.values()):
        raise UsageError(
            f'params file {path!r} must hold a JSON object of critic names to objects, e.g. {{"joint_speed": {{"warn_speed_m_s": 0.8}}}}'
        )
    return data


def _scene_for(program_path: str, scene_arg: str | None):
    from .scene import Scene

    if scene_arg:
        looks_like_name = not scene_arg.endswith(".json") and "/" not in scene_arg and "\\" not in scene_arg
        if looks_like_name and not Path(scene_arg).exists():
            return Scene.builtin(scene_arg)  # unknown names get a did-you-mean
        return Scene.resolve(scene_arg)
    stem = Path(program_path).stem
    for name in Scene.builtin_names():
        if stem == name or stem.startswith(name + "_"):
            return Scene.builtin(name)
    return Scene()


# --- check -------------------------------------------------------------------------


@subcommand("check")
def _build_check(sub) -> None:
    p = sub.add_parser(
        "check",
        help="simulate a robot program and run the critics on its motion",
        description="Simulate PROGRAM in a scene, run the critics on the trajectory and print the report. "
        "Exit status: 0 no Error verdict, 1 at least one Error, 2 bad input.",
    )
    p.add_argument("program", metavar="PROGRAM", help="robot program file (Python using the skill API)")
    p.add_argument(
        "--scene",
        metavar="NAME|PATH",
        help="built-in scene name (recycling, sorting, breakfast) or a scene JSON file; default: the built-in "
        "scene the program's file name starts with (sorting_naive.py -> sorting), else an empty table",
    )
    p.add_argument("--critics", metavar="A,B", help="comma-separated critic names to run (default: all installed)")
    p.add_argument(
        "--params",
        metavar="FILE",
        help='JSON file of threshold overrides, e.g. {"joint_speed": {"warn_speed_m_s": 0.8}}',
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--rate", metavar="HZ", type=_positive_float, default=125.0, help="trajectory sample rate, Hz (default 125)")
    p.set_defaults(func=_cmd_check)


def _cmd_check(args: argparse.Namespace) -> int:
    from .critic import critique, select_critics

    source = _read_text(args.program, "program")
    scene = _scene_for(args.program, args.scene)
    params = _load_params(args.params)
    critics = [c.strip() for c in args.critics.split(",") if c.strip()] if args.critics else None
    select_critics(critics, params)  # fail fast on bad names or params, before simulating
    try:
        from .program.simulate import simulate
    except ImportError as exc:  # pragma: no cover - only while the simulator is missing
        raise UsageError(f"simulation is not available in this installation: {exc}") from None
    execution = simulate(source, scene, sample_rate_hz=args.rate)
    report = critique(execution.trajectory, getattr(execution, "scene", scene), critics=critics, params=params)
    print(report.to_json() if args.json else report.to_text())
    return 1 if report.has_errors else 0


# --- critics -----------------------------------------------------------------------


@subcommand("critics")
def _build_critics(sub) -> None:
    p = sub.add_parser(
        "critics",
        help="list the installed critics and the plugins that failed to load",
        description="List every installed critic (built-in and plugins): name, providing package, description.",
    )
    p.add_argument("-v", "--verbose", action="store_true", help="also list each critic's parameters and defaults")
    p.add_argument("--json", action="store_true", help="print the list as JSON")
    p.set_defaults(func=_cmd_critics)


def _cmd_critics(args: argparse.Namespace) -> int:
    from .plugins import critic_distributions, get_critics, plugin_errors

    critics = get_critics()
    dists = critic_distributions()
    rows = []
    for name, critic in critics.items():
        dist, version = dists.get(name, ("", ""))
        fields = {
            field: {"default": info.default, "description": info.description or ""}
            for field, info in critic.Params.model_fields.items()
        }
        rows.append(
            {"name": name, "package": dist, "version": version, "description": critic.description, "params": fields}
        )
    failed = [
        {"name": e.name, "entry_point": e.value, "package": e.distribution, "error": e.error} for e in plugin_errors
    ]
    if args.json:
        print(json.dumps({"critics": rows, "failed_plugins": failed}, indent=2, default=str))
        return 0
    name_w = max([len(r["name"]) for r in rows] + [4])
    pkg_w = max([len(f"{r['package']} {r['version']}".strip()) for r in rows] + [7])
    print(f"{'NAME':<{name_w}}  {'PACKAGE':<{pkg_w}}  DESCRIPTION")
    for r in rows:
        pkg = f"{r['package']} {r['version']}".strip() or "(registered in-process)"
        print(f"{r['name']:<{name_w}}  {pkg:<{pkg_w}}  {r['description']}")
        if args.verbose:
            for field, info in r["params"].items():
                print(f"{'':<{name_w}}    {field} = {info['default']!r}: {info['description']}")
    if failed:
        print()
        print("Failed plugins (skipped):")
        for f in failed:
            where = f" from {f['package']}" if f["package"] else ""
            print(f"  {f['name']}{where}: {f['error']}")
    return 0


# --- more subcommands ----------------------------------------------------------------


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
    from .critic import critique
    from .errors import DeployError
    from .program.simulate import simulate
    from .robot.ur.deploy import URArm

    scene = _scene_for(args.program, args.scene)
    execution = simulate(_read_text(args.program, "program"), scene)
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



@subcommand("run")
def _build_run(sub: "argparse._SubParsersAction") -> None:
    from .llm.cli_run import add_run_parser

    add_run_parser(sub)


@subcommand("ursim")
def _build_ursim(sub: "argparse._SubParsersAction") -> None:
    p = sub.add_parser(
        "ursim",
        help="run a loopback UR3e controller (RTDE, Dashboard, secondary interface) until Ctrl-C",
        add_help=False,
    )
    # its options belong to the controller's own parser; main() hands them over untouched
    p.set_defaults(func=lambda args: _cmd_ursim([]))


def _cmd_ursim(argv: list[str]) -> int:
    from .robot.ur.sim import main as ursim_main

    return int(ursim_main(argv))


# --- entry point -------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="robocritics",
        description="LLM robot programming with expert-informed motion critics.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for builder in SUBCOMMANDS.values():
        builder(sub)
    return parser


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status (never raises for bad input)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["ursim"]:
        return _cmd_ursim(argv[1:])
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, or argparse's own usage error (status 2)
        return int(exc.code) if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    try:
        return int(args.func(args))
    except (CriticError, UsageError) as exc:
        print(f"robocritics: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except RoboCriticsError as exc:
        print(f"robocritics: error: {type(exc).__name__}: {_one_line(exc)}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # e.g. `robocritics critics | head`
        return 0


if __name__ == "__main__":  # pragma: no cover - `python -m robocritics.cli`
    # Use the imported module, not this __main__ copy, so subcommands registered
    # by other modules (which import robocritics.cli) are seen.
    from robocritics.cli import main as _main

    sys.exit(_main())
