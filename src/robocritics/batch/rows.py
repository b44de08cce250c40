"""Batch rows: checking an input row, evaluating one in-process, and the output row.

An input row is a mapping ``{"id", "scene", "program", "goal"?, "critics"?, "params"?, "robot"?}``:

* ``id`` — a non-empty string or an integer, unique within the batch;
* ``scene`` — a built-in scene name (``"sorting"``), a scene JSON file path, or an inline scene object;
* ``program`` — the program's source text;
* ``goal`` — optional: a goal string (``"green_apple in white_box"``) or a list of them, checked by the
  ``task_outcome`` critic on the final scene;
* ``critics`` — optional: critic names (a list or a comma-separated string), default every installed critic;
* ``params`` — optional: ``{critic: {field: value}}`` thresholds;
* ``robot`` — optional: a bundled arm's name (``"ur5e"``; :func:`bundled_arm_names`) that runs this row,
  instead of the batch's robot (a URDF arm is one robot for the whole batch: ``evaluate(robot=...)``).

An output row is ``{"id", "score", "flags", "passed", "duration_s", "samples", "error"}``: ``score`` the
0-10 program quality index (None on error), ``flags`` ``{critic: "OK"|"WARNING"|"ERROR"}``, ``passed``
whether every critic gave OK, ``duration_s`` the wall time the row took in its worker, s, ``samples`` the
trajectory's sample count, ``error`` None or ``{"type", "message", "line"}`` (``line`` the program line,
None when the error is not in the program).
"""

from __future__ import annotations

import json
import numbers
import pickle
import time
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = [
    "Job", "RowError", "bundled_arm_names", "check_row", "error_row", "evaluate_job", "SceneCache", "OUTPUT_KEYS",
    "MAX_MESSAGE_CHARS",
]  # fmt: skip

#: The keys of every output row, in this order.
OUTPUT_KEYS = ("id", "score", "flags", "passed", "duration_s", "samples", "error")
_INPUT_KEYS = {"id", "scene", "program", "goal", "critics", "params", "robot"}
#: Longest id accepted, characters (ids are echoed in every output row).
MAX_ID_CHARS = 200
#: Most digits of an integer id (as a JSON reader parses them; a 64-bit integer has 19 or 20).
MAX_ID_DIGITS = 20
#: Longest error message in an output row, characters: a plugin's exception (or any error quoting its input)
#: could carry megabytes, copied into every output row and the progress of a batch.
MAX_MESSAGE_CHARS = 2_000
#: Scenes a worker keeps loaded (most recently used first out last).
SCENE_CACHE_SIZE = 32


class RowError(Exception):
    """An input row that cannot be evaluated (missing id, wrong types, duplicate id); the message says which field."""


@dataclass(frozen=True)
class Job:
    """One checked input row, ready to send to a worker (plain data: it pickles)."""

    id: str | int
    scene: str | dict
    program: str
    goals: tuple[str, ...] | None = None
    critics: tuple[str, ...] | None = None
    params: dict | None = None
    robot: str | None = None


def bundled_arm_names() -> tuple[str, ...]:
    """The arms a row's ``"robot"`` may name: the bundled UR e-series arms and the Panda."""
    from ..robot.arms import BUNDLED_ARM_NAMES

    return BUNDLED_ARM_NAMES


#: The bundled arms a worker has loaded for rows that name one, by name (loaded once per worker process).
_ROW_ROBOTS: dict[str, Any] = {}


def _row_robot(name: str):
    robot = _ROW_ROBOTS.get(name)
    if robot is None:
        from ..robot.model import Robot

        robot = _ROW_ROBOTS[name] = Robot.bundled(name)
    return robot


def _bounded(message: str) -> str:
    """``message`` cut to :data:`MAX_MESSAGE_CHARS` (saying how long it was), as valid Unicode."""
    if len(message) > MAX_MESSAGE_CHARS:
        message = f"{message[: MAX_MESSAGE_CHARS - 60]}... (cut: the message was {len(message):,} characters)"
    return message if _is_text(message) else message.encode("utf-8", "backslashreplace").decode("utf-8")


def error_row(row_id: Any, kind: str, message: str, line: int | None = None, duration_s: float = 0.0) -> dict:
    """An output row for a row that could not be evaluated (``message`` bounded by :data:`MAX_MESSAGE_CHARS`)."""
    return {
        "id": row_id,
        "score": None,
        "flags": {},
        "passed": False,
        "duration_s": float(duration_s),
        "samples": 0,
        "error": {"type": kind, "message": _bounded(message), "line": line},
    }


def _strings(value: Any, field: str) -> tuple[str, ...]:
    """A row's ``goal`` or ``critics``: one string (``critics`` may be comma-separated) or a non-empty list of
    non-empty strings. An empty selection is an error, not "the default": omit the field for that."""
    items = value
    if isinstance(value, str):
        items = value.split(",") if field == "critics" else [value]
    if not isinstance(items, (list, tuple)) or not all(isinstance(v, str) for v in items):
        got = type(value).__name__ if not isinstance(value, (list, tuple)) else "a list holding a non-string"
        raise RowError(f"{field!r} must be a string or a list of non-empty strings, got {got}")
    if not items:
        raise RowError(f"{field!r} is an empty list; omit {field!r} for the default")
    if not all(v.strip() for v in items):
        raise RowError(f"{field!r} holds an empty name ({json.dumps(value)[:60]}); omit {field!r} for the default")
    return tuple(v.strip() for v in items)


def _is_text(value: str) -> bool:
    """``value`` is valid Unicode (no lone surrogates, which JSON escapes allow but UTF-8 and Parquet refuse)."""
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _plain(row_id: Any) -> Any:
    """``row_id`` as a plain ``int`` or ``str`` if it is an integer or text of another type (a NumPy integer
    from a DataFrame's records, a ``str`` subclass), which JSON and Parquet writers may not take; else as is."""
    if isinstance(row_id, numbers.Integral) and not isinstance(row_id, bool):
        return int(row_id)
    return str(row_id) if isinstance(row_id, str) else row_id


def plain_id(row_id: Any) -> str | int | None:
    """``row_id`` as a plain ``str`` or ``int`` if it can be a row's id (see :func:`check_row`), else None:
    an error row echoes no other id."""
    row_id = _plain(row_id)
    if isinstance(row_id, bool) or not isinstance(row_id, (str, int)) or row_id == "":
        return None
    if isinstance(row_id, int):
        return row_id if abs(row_id) < 10**MAX_ID_DIGITS else None
    return row_id if len(row_id) <= MAX_ID_CHARS and _is_text(row_id) else None


def check_row(row: Any) -> Job:
    """The :class:`Job` of input ``row``; :class:`RowError` naming the field if it is not a valid row."""
    if not isinstance(row, Mapping):
        raise RowError(f"a row must be an object with 'id', 'scene' and 'program', got {type(row).__name__}")
    if "id" not in row:
        raise RowError("the row has no 'id'")
    row_id = _plain(row["id"])
    if isinstance(row_id, bool) or not isinstance(row_id, (str, int)) or row_id == "":
        try:
            shown = json.dumps(row_id)
        except (TypeError, ValueError):  # e.g. the parser's marker for an integer of thousands of digits
            shown = repr(row_id)
        raise RowError(f"'id' must be a non-empty string or an integer, got {shown[:60]}")
    if isinstance(row_id, int) and abs(row_id) >= 10**MAX_ID_DIGITS:
        raise RowError(f"'id' is an integer of more than {MAX_ID_DIGITS} digits")
    if isinstance(row_id, str) and len(row_id) > MAX_ID_CHARS:
        raise RowError(f"'id' is longer than {MAX_ID_CHARS} characters")
    if isinstance(row_id, str) and not _is_text(row_id):
        raise RowError("'id' is not valid Unicode text (it holds a lone surrogate such as \\ud800)")
    unknown = sorted(set(map(str, row)) - _INPUT_KEYS)
    if unknown:
        raise RowError(f"unknown field {unknown[0]!r} (a row has {', '.join(sorted(_INPUT_KEYS))})")
    for field in ("scene", "program"):
        if field not in row:
            raise RowError(f"the row has no {field!r}")
    scene = row["scene"]
    if isinstance(scene, str) and not scene.strip():
        raise RowError("'scene' is an empty string; it must be a scene name, a scene file path or a scene object")
    if not isinstance(scene, (str, Mapping)):
        from ..scene import Scene

        if isinstance(scene, Scene):  # the Python API: a loaded scene travels as its JSON data
            scene = scene.model_dump(mode="json")
    if not isinstance(scene, (str, Mapping)):
        raise RowError(f"'scene' must be a scene name, a scene file path or a scene object, got {type(scene).__name__}")
    if not isinstance(row["program"], str):
        raise RowError(f"'program' must be the program's source text (a string), got {type(row['program']).__name__}")
    robot = row.get("robot")
    if robot is not None and (not isinstance(robot, str) or robot not in bundled_arm_names()):
        shown = json.dumps(robot)[:60] if isinstance(robot, (str, int, float, bool)) else type(robot).__name__
        raise RowError(f"'robot' must be a bundled arm's name ({', '.join(bundled_arm_names())}), got {shown}")
    params = row.get("params")
    if params is not None and not (isinstance(params, Mapping) and all(isinstance(v, Mapping) for v in params.values())):
        raise RowError("'params' must be an object {critic: {field: value}}")
    job = Job(
        id=row_id,
        scene=dict(scene) if isinstance(scene, Mapping) else scene.strip(),
        program=row["program"],
        goals=None if row.get("goal") in (None, []) else _strings(row["goal"], "goal"),  # []: no goals
        critics=None if row.get("critics") is None else _strings(row["critics"], "critics"),
        params=None if params is None else {str(k): dict(v) for k, v in params.items()},
        robot=robot,
    )
    for field, value in (("scene", job.scene), ("params", job.params)):
        if isinstance(value, dict):
            _check_picklable(value, field)
    return job


def _check_picklable(value: Any, field: str) -> None:
    """A RowError unless ``value`` can travel to a worker (pickled): from the Python API, a row may hold a
    function, an open file or a structure nested too deep, which would otherwise stop the whole batch."""
    try:
        pickle.dumps(value)
    except RecursionError:
        raise RowError(f"{field!r} is nested too deep to send to a worker") from None
    except Exception as exc:  # noqa: BLE001 - pickle raises PicklingError, TypeError, AttributeError, ...
        raise RowError(f"{field!r} holds something that is not data ({type(exc).__name__}: {str(exc)[:120]}); "
                       "use JSON-like values: objects, lists, strings, numbers, booleans, null") from None  # fmt: skip


class SceneCache:
    """Scenes loaded by a worker, keyed by their spec (name, path, or the inline object's JSON)."""

    def __init__(self, size: int = SCENE_CACHE_SIZE):
        self.size = size
        self._scenes: OrderedDict[str, Any] = OrderedDict()

    def get(self, spec: str | dict):
        from ..scene import Scene

        key = spec if isinstance(spec, str) else json.dumps(spec, sort_keys=True, default=str)
        if key in self._scenes:
            self._scenes.move_to_end(key)
            return self._scenes[key]
        if isinstance(spec, dict):
            scene = Scene.model_validate(spec)
        elif spec in Scene.builtin_names() or ("/" not in spec and not spec.endswith(".json") and not Path(spec).exists()):
            scene = Scene.builtin(spec)  # a name: an unknown one's error lists the built-in names
        else:
            scene = Scene.resolve(spec)
        self._scenes[key] = scene
        if len(self._scenes) > self.size:
            self._scenes.popitem(last=False)
        return scene


def _error_of(exc: BaseException) -> dict:
    line = getattr(exc, "line", None)
    return {
        "type": type(exc).__name__,
        "message": str(getattr(exc, "reason", None) or exc),
        "line": int(line) if isinstance(line, int) and line > 0 else None,
    }


def evaluate_job(job: Job, robot, scenes: SceneCache, sample_rate_hz: float = 125.0) -> dict:
    """Simulate and critique ``job`` in this process; every library error becomes the row's ``error``."""
    from ..errors import RoboCriticsError
    from ..pipeline import check

    started = time.perf_counter()
    try:
        scene = scenes.get(job.scene)
        robot = _row_robot(job.robot) if job.robot else robot
        checked = check(job.program, scene, robot=robot, sample_rate_hz=sample_rate_hz, params=job.params,
                        critics=list(job.critics) if job.critics else None,
                        goals=list(job.goals) if job.goals else None)  # fmt: skip
        if checked.error is not None:  # the program did not run: the row names its error and line
            raise checked.error
        report = checked.report
    except MemoryError:
        raise  # the worker's heap may be in any state: its engine replaces it
    except Exception as exc:  # noqa: BLE001 - a library error, or a plugin's bug: the row says which
        error = _error_of(exc)
        message = error["message"] if isinstance(exc, RoboCriticsError) else f"{type(exc).__name__}: {exc}"
        return error_row(job.id, error["type"], message, error["line"], time.perf_counter() - started)
    return {
        "id": job.id,
        "score": float(report.score),
        "flags": {v.critic: v.flag.value for v in report.verdicts},
        "passed": bool(report.passed),
        "duration_s": time.perf_counter() - started,
        "samples": int(report.samples),
        "error": None,
    }
