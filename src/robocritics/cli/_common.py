"""Shared pieces of the ``robocritics`` subcommands: the registry, input readers, argument types.

Every reader and argument type turns bad input into a one-line error naming the
argument or file (:class:`UsageError`, or argparse's ``ArgumentTypeError`` that
``main`` prints as ``robocritics check: error: argument --rate: ...``), never a
traceback.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Callable

from .._files import read_bounded_text
from ..errors import RoboCriticsError
from ..robot.arms import BUNDLED_ARM_NAMES

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


ONE_LINE_CHARS = 4000
"""Longest message :func:`one_line` prints [characters]: an error quoting a 900,000-character frame name is cut."""


def one_line(text: object, limit: int = ONE_LINE_CHARS) -> str:
    """``text`` with every run of whitespace (newlines included) folded to one space, control characters and
    escape sequences shown as escapes, and cut after ``limit`` characters with a note
    (:func:`robocritics._text.safe_text`): messages quote names from files and replies."""
    from .._text import safe_text  # only when there is something to say: `check` does not pay for it

    return safe_text(" ".join(str(text).split()), limit)


PRINTED_CHARS = 200_000
"""Most characters :func:`terminal_text` prints (a report, a diff, an LLM's reply are a few thousand)."""


def terminal_text(text: object, limit: int = PRINTED_CHARS) -> str:
    """Lines for stdout that may quote outside text (a report quoting a scene or a program, the diff of a program,
    an LLM's reply): newlines and tabs kept, every other control character and escape sequence shown as an escape
    (:func:`robocritics._text.safe_text`), so what is printed can neither clear the screen, set the window title
    nor forge a line of ours; cut after ``limit`` characters with a note."""
    from .._text import safe_text

    return safe_text(text, limit, newlines=True)


MAX_INPUT_BYTES = 1_000_000
"""Largest program or params file [bytes]: ten times the sandbox's longest program (100,000 characters), so an
over-long program still gets the sandbox's own error, and a mistaken path (a log, an image) a short one."""

_SHOWN_CHARS = 60
"""Arguments quoted in error messages are cut to this length."""


def shown(text: object) -> str:
    """``text`` quoted for an error message, cut to a readable length."""
    t = str(text)
    return repr(t) if len(t) <= _SHOWN_CHARS else repr(t[:_SHOWN_CHARS]) + f"... ({len(t):,} characters)"


def path_label(path: object) -> str:
    """A file name for an error message: whole if readable, else its start and its end (which names the file)."""
    t = str(path)
    return t if len(t) <= 200 else f"{t[:60]}...{t[-120:]} ({len(t):,} characters)"


def shown_path(path: object) -> str:
    """:func:`path_label`, quoted."""
    t = str(path)
    return repr(t) if len(t) <= 200 else repr(f"{t[:60]}...{t[-120:]}") + f" ({len(t):,} characters)"


def positive_int(text: str) -> int:
    try:
        value = int(text) if len(text) <= 20 else None
    except ValueError:
        value = None
    if value is None:
        raise argparse.ArgumentTypeError(f"{shown(text)} is not a whole number")
    if value < 1:
        raise argparse.ArgumentTypeError(f"{shown(text)} must be at least 1")
    return value


def sample_rate(text: str) -> float:
    """A trajectory sample rate [Hz] in the range the critics can trust (robot.motion.check_sample_rate)."""
    from ..errors import PlanningError
    from ..planning.timing import check_sample_rate

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{shown(text)} is not a number of Hz") from None
    try:
        return check_sample_rate(value, "the sample rate")
    except PlanningError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


_MAX_CRITIC_NAME_CHARS = 100
"""Longest critic name ``--critics`` accepts (so an unknown one is quoted briefly in the error)."""


def file_name(text: str) -> str:
    """A file argument (``--html``, ``-o``, ``--params``, ``--memory``): not empty. An empty value was read as
    "not given": ``--html=`` wrote nothing and exited 0, ``--params=`` ran with the defaults."""
    if not text:
        raise argparse.ArgumentTypeError("the file name is empty")
    return text


def critic_names(text: str) -> str:
    """A ``--critics`` value: comma-separated names, each at most :data:`_MAX_CRITIC_NAME_CHARS` characters, at
    least one (an empty value ran every critic as if the option were not given)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("no critic named; give names separated by commas, e.g. joint_speed,collision")
    for name in text.split(","):
        if len(name.strip()) > _MAX_CRITIC_NAME_CHARS:
            raise argparse.ArgumentTypeError(
                f"critic name {shown(name.strip())} is longer than {_MAX_CRITIC_NAME_CHARS} characters"
            )
    return text


def port(text: str) -> int:
    """A TCP port number, 1..65535."""
    try:
        value = int(text) if len(text) <= 5 else None
    except ValueError:
        value = None
    if value is None or not 1 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"{shown(text)} is not a TCP port (a whole number from 1 to 65535)")
    return value


def bounded_float(low: float, high: float, unit: str = "") -> Callable[[str], float]:
    """An argument type for a finite number in ``[low, high]`` (``unit`` names it in messages)."""
    suffix = f" {unit}" if unit else ""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{shown(text)} is not a number") from None
        if not (math.isfinite(value) and low <= value <= high):
            raise argparse.ArgumentTypeError(f"{shown(text)} must be a number from {low:g} to {high:g}{suffix}")
        return value

    return parse


def host(text: str) -> str:
    """A host name or IP address: non-empty, at most 253 characters of labels of at most 63, IDNA-encodable."""
    name = text.strip()
    problem = ""
    if not name:
        problem = "is empty"
    elif len(name) > 253 or any(c.isspace() or not c.isprintable() or c == "/" for c in name):
        problem = "is not a host name"
    else:
        try:
            labels = name.encode("idna").split(b".")
        except UnicodeError:
            labels = None
        if labels is None or any(len(label) > 63 for label in labels):
            problem = "is not a host name (labels are at most 63 characters)"
    if problem:
        raise argparse.ArgumentTypeError(f"{shown(text)} {problem}; give a host name or IP address, e.g. 192.168.1.10")
    return name


def read_text(path: str, what: str, max_bytes: int = MAX_INPUT_BYTES) -> str:
    """The UTF-8 text of the regular file ``path`` of at most ``max_bytes`` bytes; :class:`UsageError` otherwise."""
    return read_bounded_text(path, what, shown_path(path), max_bytes, UsageError)


def check_output(path: str, option: str) -> None:
    """A UsageError (one line, naming ``option`` and the path) unless a new file may be written at ``path``:
    no link, directory, FIFO or device there, and its directory exists (:func:`~robocritics._files.check_output_path`)."""
    from .._files import OutputFileError, check_output_path

    try:
        check_output_path(path, option)
    except OutputFileError as exc:
        raise UsageError(str(exc)) from None


def load_params(path: str | None) -> dict:
    if not path:
        return {}
    from ..errors import SceneError
    from ..scene import parse_json

    text = read_text(path, "params")
    try:
        data = parse_json(text, f"params file {shown_path(path)}")  # bounded: nesting, digits
    except SceneError as exc:
        raise UsageError(str(exc).replace(": not valid JSON", " is not valid JSON", 1)) from None
    if not isinstance(data, dict) or not all(isinstance(v, dict) for v in data.values()):
        raise UsageError(
            f'params file {shown_path(path)} must hold a JSON object of critic names to objects, e.g. {{"joint_speed": {{"warn_speed_m_s": 0.8}}}}'
        )
    return data


def scene_for(program_path: str, scene_arg: str | None):
    """The scene of ``--scene`` (a built-in name or a file), else the built-in one the program's file name starts
    with, else an empty table; refused (SceneError naming the field) if its ids are names of the skill API."""
    from ..errors import SceneError
    from ..scene import Scene
    from ..pipeline import check_scene_ids

    if scene_arg is not None and not scene_arg.strip():
        raise UsageError("--scene is empty; give a built-in scene name or a scene JSON file")
    if scene_arg:
        looks_like_name = not scene_arg.endswith(".json") and "/" not in scene_arg and "\\" not in scene_arg
        try:
            exists = Path(scene_arg).exists()
        except (OSError, ValueError):  # a NUL byte or an over-long name: Scene.resolve says so
            exists = True
        scene = Scene.builtin(scene_arg) if looks_like_name and not exists else Scene.resolve(scene_arg)
    else:
        stem = Path(program_path).stem
        scene = next(
            (Scene.builtin(n) for n in Scene.builtin_names() if stem == n or stem.startswith(n + "_")), Scene()
        )
    try:
        check_scene_ids(scene)
    except SceneError as exc:
        if not scene_arg or scene_arg in Scene.builtin_names():
            raise
        located = SceneError(f"{path_label(scene_arg)}: {exc}")  # the file, then the field
        located.path = exc.path
        raise located from None
    return scene


def add_critic_options(parser: argparse.ArgumentParser) -> None:
    """``--critics A,B`` and ``--params FILE``, the critic selection shared by ``check``, ``run`` and ``deploy``."""
    parser.add_argument(
        "--critics",
        metavar="A,B",
        type=critic_names,
        help="comma-separated critic names to run (default: all installed)",
    )
    parser.add_argument(
        "--params",
        metavar="FILE",
        type=file_name,
        help='JSON file of threshold overrides, e.g. {"joint_speed": {"warn_speed_m_s": 0.8}}',
    )


def goal_text(text: str):
    """A ``--goal`` value: ``'OBJECT in CONTAINER'`` or ``'OBJECT on SUPPORT'`` (:meth:`robocritics.goals.Goal.parse`)."""
    from ..goals import Goal, GoalError

    try:
        return Goal.parse(text)
    except GoalError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_goal_option(parser: argparse.ArgumentParser) -> None:
    """``--goal 'OBJ in BOX'`` (repeatable): task goals the ``task_outcome`` critic checks on the final scene;
    shared by ``check``, ``run``, ``fix`` and ``studio``. Parsed values are :class:`~robocritics.goals.Goal`."""
    parser.add_argument(
        "--goal",
        metavar="'OBJ in|on TARGET'",
        dest="goals",
        action="append",
        type=goal_text,
        default=[],
        help="a task goal checked on the final scene, e.g. 'green_apple in white_box' or 'cupcake on plate' "
        "(repeatable); the program's own expect(...) calls are checked too",
    )


# --- the LLM endpoint options shared by `run` and `studio` ----------------------------------------------------

# Seconds one LLM request may take in all: the library's deadline (llm.limits.DEFAULT_DEADLINE_S, not imported
# here so that building the parser stays cheap), enough for a local server that loads the model first.
_TIMEOUT_S = 300.0
# Seconds one network phase may take within it before the request is retried: a first request to a local
# server waits while the model loads.
_PHASE_TIMEOUT_S = 120.0
# Tokens per reply: llm.limits.DEFAULT_MAX_TOKENS (not imported here, to keep building the parser cheap).
_MAX_TOKENS = 1024


def add_llm_options(p: argparse.ArgumentParser) -> None:
    """``--base-url --model --api-key-env --timeout --max-tokens --idle-timeout --no-stream`` (read by
    :func:`llm_api_key` and :func:`llm_client`)."""
    p.add_argument("--base-url", metavar="URL", help="OpenAI-compatible endpoint (default: $ROBOCRITICS_BASE_URL)")
    p.add_argument("--model", metavar="NAME", help="chat model (default: $ROBOCRITICS_MODEL)")
    p.add_argument(
        "--api-key-env",
        metavar="VAR",
        help="name of the environment variable holding the API key (default: ROBOCRITICS_API_KEY, then OPENAI_API_KEY)",
    )
    p.add_argument(
        "--timeout",
        metavar="S",
        type=bounded_float(0.1, 24 * 3600.0, "s"),
        default=_TIMEOUT_S,
        help=f"seconds one LLM request may take in all, retries included (default {_TIMEOUT_S:g})",
    )
    p.add_argument(
        "--max-tokens",
        metavar="N",
        type=positive_int,
        default=_MAX_TOKENS,
        help=f"most tokens per model reply (default {_MAX_TOKENS}); a reply cut there is sent back as "
        "'your reply was cut; send a shorter program'",
    )
    p.add_argument(
        "--idle-timeout",
        metavar="S",
        type=bounded_float(0.1, 24 * 3600.0, "s"),
        default=None,
        help="seconds a streamed reply may stay silent before the request ends (default: min(--timeout, 120))",
    )
    p.add_argument("--no-stream", action="store_true", help="ask for whole replies instead of streamed ones")


def llm_api_key(args: argparse.Namespace) -> str | None:
    """The API key from the variable ``--api-key-env`` names (None without the option); UsageError if unset."""
    import os

    if not getattr(args, "api_key_env", None):
        return None
    api_key = os.environ.get(args.api_key_env)
    if not api_key:
        raise UsageError(f"the environment variable {args.api_key_env} (from --api-key-env) is not set")
    return api_key


def llm_client(args: argparse.Namespace, api_key: str | None, *, embedding_model: str | None = None):
    """The :class:`~robocritics.llm.providers.openai_compatible.OpenAICompatible` the options of :func:`add_llm_options` describe;
    UsageError when no endpoint or model is configured (or the endpoint is unusable)."""
    from ..errors import LLMError
    from ..llm.providers import provider

    try:
        return provider()(
            base_url=args.base_url,
            model=args.model,
            api_key=api_key,
            embedding_model=embedding_model,
            timeout_s=min(args.timeout, _PHASE_TIMEOUT_S),
            deadline_s=args.timeout,
            max_tokens=getattr(args, "max_tokens", _MAX_TOKENS),
            stream=not getattr(args, "no_stream", False),
            idle_timeout_s=min(args.idle_timeout, args.timeout) if getattr(args, "idle_timeout", None) else None,
        )
    except LLMError as exc:
        raise UsageError(f"{exc} (or use --base-url / --model)" if "configured" in str(exc) else str(exc)) from None


#: The arms ``--robot NAME`` names (the bundled models).


def base_pose(text: str) -> tuple[float, ...]:
    """``x,y,z,roll,pitch,yaw``: where a URDF arm's base stands in the world (m, rad; finite)."""
    parts = text.split(",")
    if len(parts) != 6:
        raise argparse.ArgumentTypeError(f"{shown(text)} is not six numbers x,y,z,roll,pitch,yaw (m, rad)")
    try:
        values = tuple(float(v) for v in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{shown(text)} is not six numbers x,y,z,roll,pitch,yaw (m, rad)") from None
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"{shown(text)}: every number must be finite")
    return values


def add_robot_options(p: argparse.ArgumentParser) -> None:
    """``--robot NAME|PATH.urdf``, ``--tool NAME|PATH.urdf``, ``--tip LINK`` and ``--base-pose`` (see
    :func:`robot_for`)."""
    p.add_argument(
        "--robot",
        metavar="NAME|PATH.urdf",
        help=f"the arm: a bundled one ({', '.join(BUNDLED_ARM_NAMES)}) or a vendor URDF file, loaded as shipped (meshes "
        "enclosed by fitted capsules; docs/robots.md); default: the scene's \"robot\", else ur3e",
    )
    p.add_argument(
        "--tool",
        metavar="NAME|PATH.urdf",
        help="the tool on a URDF arm's flange: robotiq_2f85, robotiq_hande, franka_hand, none, or a tool URDF; "
        "default: the file's own robocritics gripper, else none",
    )
    p.add_argument("--tip", metavar="LINK", help="the URDF arm's flange link (needed where its chain branches)")
    p.add_argument(
        "--base-pose",
        type=base_pose,
        metavar="X,Y,Z,ROLL,PITCH,YAW",
        help="where a URDF arm's base stands in the scene (m, rad; pedestal, wall, ceiling); default: at the origin",
    )


def robot_for(args: argparse.Namespace, scene):
    """The robot of ``--robot``/``--tool``/``--tip``, else the bundled arm the scene names (``"robot"``), else None
    (the default UR3e). A URDF's errors are :class:`~robocritics.errors.RobotModelError` naming file and line."""
    name = getattr(args, "robot", None) or scene.robot or None
    tool, tip, pose = getattr(args, "tool", None), getattr(args, "tip", None), getattr(args, "base_pose", None)
    if name is None:
        if tool or tip:
            raise UsageError("--tool and --tip need --robot PATH.urdf (the bundled arms carry their own gripper)")
        if pose is not None:
            raise UsageError("--base-pose needs --robot PATH.urdf (the bundled arms stand at the origin)")
        return None  # the default arm, loaded where the work is done (a batch parent never needs Pinocchio)
    from ..robot.model import Robot

    if name in BUNDLED_ARM_NAMES and not name.endswith(".urdf"):
        if tool or tip:
            raise UsageError(f"--robot {name} carries its own gripper; --tool and --tip are for --robot PATH.urdf")
        if pose is not None:
            raise UsageError(f"--robot {name} stands at the origin; --base-pose is for --robot PATH.urdf")
        return Robot.bundled(name)
    if not name.lower().endswith(".urdf"):
        raise UsageError(f"--robot {shown(name)}: not a bundled arm ({', '.join(BUNDLED_ARM_NAMES)}) nor a .urdf file")
    return Robot.from_urdf(name, tool=tool, tip=tip, base_pose=pose)
