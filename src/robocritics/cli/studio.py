"""``robocritics studio``: the web interface — chat, editor, Run, critics, Fix, replay, history, Deploy.

::

    robocritics studio --scene sorting --program examples/programs/sorting_naive.py \\
        [--host 127.0.0.1] [--port 8765] [--token SECRET] [--base-url URL --model NAME ...] \\
        [--deploy-host 127.0.0.1 --deploy-rtde-port 30004 ...] [--no-browser]

Prints the URL (for ``--host 0.0.0.0``: one per address of this machine) and serves until Ctrl-C (exit 0);
``--program`` is Run as soon as the studio starts; a URScript file or a recording (docs/formats.md) is judged and
replayed the same way, with Fix, chat and Deploy off. Binding a host that is not loopback (127.0.0.0/8, ::1,
localhost) without ``--token`` is refused with exit status 2: the studio can move a robot. Without
``--base-url``/``--model`` (or their environment variables) chat and Fix are disabled and the page says why.
See docs/studio.md.
"""

from __future__ import annotations

import argparse
import sys

from ._common import (
    UsageError,
    add_goal_option,
    add_llm_options,
    add_robot_options,
    file_name,
    host,
    llm_api_key,
    llm_client,
    one_line,
    port,
    read_text,
    robot_for,
    scene_for,
    subcommand,
)
from ._motion import add_motion_options

__all__ = ["studio_command"]


@subcommand("studio")
def _build_studio(sub) -> None:
    p = sub.add_parser(
        "studio",
        help="open the studio: write, check, fix, replay and deploy a program in the browser",
        description="Serve the RoboCritics studio (chat, program editor, Run, critics with Fix, 3-D replay, "
        "revision history, Deploy) on HOST:PORT and print its URL; serve until Ctrl-C. A non-loopback --host "
        "needs --token. Exit status: 0 after Ctrl-C, 2 bad input.",
    )
    p.add_argument("--scene", metavar="NAME|PATH", help="scene name or JSON file (default as for `check`)")
    p.add_argument("--program", metavar="FILE", type=file_name, help="program file to open in the editor and Run; a "
                   "URScript file or a recording (ur_rtde or generic CSV, JointTrajectory JSON, MoveIt YAML, rosbag2) "
                   "is judged and replayed (docs/formats.md)")
    add_goal_option(p)
    add_motion_options(p)
    add_robot_options(p)
    p.add_argument("--host", type=host, default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8765, help="port to bind (default 8765; 0: any free port)")
    p.add_argument("--token", metavar="SECRET", help="require this token on every request (needed off loopback)")
    add_llm_options(p)
    p.add_argument("--deploy-host", type=host, help="UR controller for Deploy (e.g. `robocritics ursim`)")
    p.add_argument("--deploy-rtde-port", type=port, default=30004)
    p.add_argument("--deploy-dashboard-port", type=port, default=29999)
    p.add_argument("--deploy-secondary-port", type=port, default=30002)
    p.add_argument("--no-browser", action="store_true", help="do not open a web browser")
    p.set_defaults(func=studio_command)


def studio_command(args: argparse.Namespace) -> int:
    """Handle ``robocritics studio``; returns the exit status."""
    from ..viz.studio import Studio, is_loopback

    if not is_loopback(args.host) and not args.token:
        print(f"robocritics studio: error: --host {args.host} is not a loopback address; the studio can move a "
              "robot, so binding it there needs --token SECRET", file=sys.stderr)
        return 2
    if not 0 <= args.port <= 65535:
        raise UsageError(f"--port {args.port} is not a TCP port (0 to 65535)")
    from ..formats import motion_kind

    motion = args.program if args.program and motion_kind(args.program) is not None else None
    program = read_text(args.program, "program") if args.program and motion is None else ""
    scene = scene_for(args.program, args.scene) if args.program else _scene(args.scene)
    model, reason = None, "no LLM endpoint is configured (start the studio with --base-url and --model)"
    if args.base_url or args.model or _env_configured():
        model = llm_client(args, llm_api_key(args))
    deploy = None
    if args.deploy_host:
        deploy = {"host": args.deploy_host, "rtde_port": args.deploy_rtde_port,
                  "dashboard_port": args.deploy_dashboard_port, "secondary_port": args.deploy_secondary_port}
    studio = Studio(scene, program, host=args.host, port=args.port, token=args.token, model=model, deploy=deploy,
                    goals=args.goals, no_model_reason=reason, run_program=bool(args.program), motion=motion,
                    motion_options=_motion_options(args, motion), robot=robot_for(args, scene))
    try:
        studio.start()
    except OSError as exc:
        print(f"robocritics studio: error: cannot bind {args.host}:{args.port}: {one_line(exc)}", file=sys.stderr)
        return 2
    urls = studio.urls()
    print(f"robocritics studio: {urls[0]}  (scene {studio.scene.name!r}; Ctrl-C to stop)", flush=True)
    for other in urls[1:]:
        print(f"robocritics studio: also {other}", flush=True)
    if not args.no_browser:
        import webbrowser

        webbrowser.open(urls[-1] if studio.host in ("0.0.0.0", "::") else urls[0])
    try:
        studio.serve_forever()
    except KeyboardInterrupt:
        print("robocritics studio: stopped", file=sys.stderr)
    finally:
        studio.stop()
    return 0


def _motion_options(args: argparse.Namespace, motion: str | None) -> dict:
    """The URScript and rosbag options given (``--tcp`` …), for a motion file; none is allowed for a program."""
    given = {"topic": args.topic, "passes": args.passes if args.passes != 1 else None, "tcp": args.tcp,
             "payload_kg": args.payload or None, "start_q": args.start_q, "gripper_io": args.gripper_io}
    given = {k: v for k, v in given.items() if v is not None}
    if given and motion is None:
        raise UsageError("--topic, --passes, --tcp, --payload, --start-q and --gripper-io are for a URScript file or "
                         "a recording (--program FILE with its suffix: docs/formats.md)")
    return given


def _scene(name: str | None):
    from ..scene import Scene

    return Scene.resolve(name or "sorting")


def _env_configured() -> bool:
    import os

    return bool(os.environ.get("ROBOCRITICS_BASE_URL") and os.environ.get("ROBOCRITICS_MODEL"))
