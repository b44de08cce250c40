"""Shared pieces of the ``robocritics`` subcommands: the registry, input readers, argument types."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Callable

from ..errors import RoboCriticsError

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


def one_line(text: object) -> str:
    """``text`` with every run of whitespace (newlines included) folded to one space."""
    return " ".join(str(text).split())


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r} must be at least 1")
    return value


def positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"{text!r} must be a positive number")
    return value


def read_text(path: str, what: str) -> str:
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


def load_params(path: str | None) -> dict:
    if not path:
        return {}
    text = read_text(path, "params")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise UsageError(f"params file {path!r} is not valid JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}") from None
    if not isinstance(data, dict) or not all(isinstance(v, dict) for v in data.values()):
        raise UsageError(
            f'params file {path!r} must hold a JSON object of critic names to objects, e.g. {{"joint_speed": {{"warn_speed_m_s": 0.8}}}}'
        )
    return data


def scene_for(program_path: str, scene_arg: str | None):
    from ..scene import Scene

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
