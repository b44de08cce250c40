"""The RTDE wire format: package framing, types, recipes, text messages, mode tables, and the finite-number guard.

Shared by :class:`~robocritics.deploy.rtde.RTDEClient` and the loopback controller
(:mod:`robocritics.testing.ursim`); import the names from :mod:`robocritics.deploy.rtde`, which re-exports them.
See that module's docstring for the package layouts.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any, Iterable, Mapping, Sequence

from robocritics.errors import RTDEError
from robocritics.robot.arms import UR3E

RTDE_PORT = 30004
"""Default RTDE TCP port of a UR controller."""

MAX_FREQUENCY_HZ = UR3E.control_rate_hz
"""Highest output frequency of an e-series controller [Hz]: one package per control cycle (CB3: 125 Hz)."""

V1_FREQUENCY_HZ = 125.0
"""Output frequency of protocol version 1, which cannot choose one [Hz]."""

_HEADER = struct.Struct(">HB")

MAX_UNEXPECTED_PACKAGES = 1000
"""Packages nobody asked for (unknown types, unrequested replies, data for an unknown recipe, malformed text
messages) a connection tolerates; one more is a flood: the connection fails (:class:`RTDEFloodError`)."""

MESSAGE_CHARS = 500
"""Characters of a controller text message kept (stored and logged); the rest is cut with a note."""

LOGGED_MESSAGES_PER_KIND = 20
"""Text messages of one level and source logged per connection; the rest are counted, summarised on close."""


class RTDEValueError(RTDEError):
    """The controller sent a number that is not finite (NaN, +inf, -inf): nothing it says is trusted after it.

    ``field`` is the output field, ``index`` the element of a vector field (None for a scalar), ``value``
    the value, ``package`` the number of the data package (1 = the first of the connection).
    """

    def __init__(self, message: str, *, field: str, index: int | None, value: float, package: int):
        self.field = field
        self.index = index
        self.value = value
        self.package = package
        super().__init__(message, cause="non_finite")


class RTDEFloodError(RTDEError):
    """The controller sent more than :data:`MAX_UNEXPECTED_PACKAGES` packages nobody asked for."""

    def __init__(self, message: str):
        super().__init__(message, cause="controller_flood")


def first_non_finite(values: Mapping[str, Any]) -> tuple[str, int | None, float] | None:
    """The first value of ``values`` (RTDE output fields) that is a float but not finite: ``(field, index,
    value)`` with ``index`` the element of a vector (None for a scalar); None if every number is finite.

    The one guard on numbers read from the robot: the client applies it to every data package, the gate to
    the state it judges. Integers and booleans are always finite; anything else that is not a number (a
    string, None) counts as not finite too, element index included.
    """
    for name, v in values.items():
        if isinstance(v, (str, bytes)) or not hasattr(v, "__len__"):
            if not _finite(v):
                return name, None, v
            continue
        for i, x in enumerate(v):  # a vector field (a tuple from the wire; a list or an array from a caller)
            if not _finite(x):
                return name, i, x
    return None


def _finite(x: Any) -> bool:
    if isinstance(x, int):  # bool is an int
        return True
    try:
        return math.isfinite(x)
    except (TypeError, ValueError):  # not a number at all
        return False

class RobotMode(IntEnum):
    """Values of the ``robot_mode`` output; the dashboard's ``robotmode`` answers with the names."""

    NO_CONTROLLER = -1
    DISCONNECTED = 0
    CONFIRM_SAFETY = 1
    BOOTING = 2
    POWER_OFF = 3
    POWER_ON = 4
    IDLE = 5
    BACKDRIVE = 6
    RUNNING = 7
    UPDATING_FIRMWARE = 8


class SafetyMode(IntEnum):
    """Values of the ``safety_mode`` output; the dashboard's ``safetystatus`` answers with the names."""

    NORMAL = 1
    REDUCED = 2
    PROTECTIVE_STOP = 3
    RECOVERY = 4
    SAFEGUARD_STOP = 5
    SYSTEM_EMERGENCY_STOP = 6
    ROBOT_EMERGENCY_STOP = 7
    VIOLATION = 8
    FAULT = 9
    VALIDATE_JOINT_ID = 10
    UNDEFINED_SAFETY_MODE = 11
    AUTOMATIC_MODE_SAFEGUARD_STOP = 12
    SYSTEM_THREE_POSITION_ENABLING_STOP = 13


class RuntimeState(IntEnum):
    """Values of the ``runtime_state`` output (the dashboard's ``programState`` prints the names)."""

    STOPPING = 0
    STOPPED = 1
    PLAYING = 2
    PAUSING = 3
    PAUSED = 4
    RESUMING = 5


def mode_name(kind: type[IntEnum], value: Any) -> str:
    """``"RUNNING (7)"`` for ``mode_name(RobotMode, 7)``; ``"UNKNOWN (99)"``; ``"unknown"`` for None."""
    if value is None:
        return "unknown"
    try:
        return f"{kind(int(value)).name} ({int(value)})"
    except ValueError:
        return f"UNKNOWN ({int(value)})"


class Command:
    """RTDE package types (ASCII codes)."""

    REQUEST_PROTOCOL_VERSION = 86  # 'V'
    GET_URCONTROL_VERSION = 118  # 'v'
    TEXT_MESSAGE = 77  # 'M'
    DATA_PACKAGE = 85  # 'U'
    CONTROL_PACKAGE_SETUP_OUTPUTS = 79  # 'O'
    CONTROL_PACKAGE_SETUP_INPUTS = 73  # 'I'
    CONTROL_PACKAGE_START = 83  # 'S'
    CONTROL_PACKAGE_PAUSE = 80  # 'P'


_COMMAND_NAMES = {
    Command.REQUEST_PROTOCOL_VERSION: "'V' (request protocol version)",
    Command.GET_URCONTROL_VERSION: "'v' (get controller version)",
    Command.TEXT_MESSAGE: "'M' (text message)",
    Command.DATA_PACKAGE: "'U' (data package)",
    Command.CONTROL_PACKAGE_SETUP_OUTPUTS: "'O' (setup outputs)",
    Command.CONTROL_PACKAGE_SETUP_INPUTS: "'I' (setup inputs)",
    Command.CONTROL_PACKAGE_START: "'S' (start)",
    Command.CONTROL_PACKAGE_PAUSE: "'P' (pause)",
}


class MessageLevel:
    """Levels of an RTDE text message."""

    EXCEPTION = 0
    ERROR = 1
    WARNING = 2
    INFO = 3


DATA_TYPES: dict[str, tuple[str, int]] = {
    "BOOL": ("?", 1),
    "UINT8": ("B", 1),
    "UINT32": ("I", 1),
    "INT32": ("i", 1),
    "UINT64": ("Q", 1),
    "DOUBLE": ("d", 1),
    "VECTOR3D": ("d", 3),
    "VECTOR6D": ("d", 6),
    "VECTOR6INT32": ("i", 6),
    "VECTOR6UINT32": ("I", 6),
}
"""RTDE type name -> (struct code of one element, number of elements), big-endian."""


def pack_package(command: int, payload: bytes = b"") -> bytes:
    """Frame ``payload`` as one RTDE package: ``>HB`` size (header included), type."""
    size = _HEADER.size + len(payload)
    if size > 0xFFFF:
        raise RTDEError(f"RTDE package {_COMMAND_NAMES.get(command, command)} too large: {size} bytes > 65535")
    return _HEADER.pack(size, command) + payload


@dataclass(frozen=True)
class TextMessage:
    """An RTDE text message ('M'). ``level`` is a :class:`MessageLevel` value."""

    message: str
    source: str = ""
    level: int = MessageLevel.INFO

    @property
    def level_name(self) -> str:
        return {0: "EXCEPTION", 1: "ERROR", 2: "WARNING", 3: "INFO"}.get(self.level, str(self.level))


def encode_text_message(msg: TextMessage, protocol: int = 2) -> bytes:
    """Payload of an 'M' package (v2: ``>B%dsB%dsB`` message, source, level; v1: level + message)."""
    text = msg.message.encode("utf-8")
    if protocol == 1:
        return struct.pack(">B", msg.level) + text
    src = msg.source.encode("utf-8")[:255]
    text = text[:255]
    return struct.pack(f">B{len(text)}sB{len(src)}sB", len(text), text, len(src), src, msg.level)


def decode_text_message(payload: bytes, protocol: int = 2) -> TextMessage:
    """Parse the payload of an 'M' package; raises :class:`RTDEError` if it is truncated."""
    try:
        if protocol == 1:
            (level,) = struct.unpack_from(">B", payload, 0)
            return TextMessage(payload[1:].decode("utf-8", "replace"), "", level)
        n = payload[0]
        text = payload[1 : 1 + n]
        m = payload[1 + n]
        src = payload[2 + n : 2 + n + m]
        level = payload[2 + n + m]
        if len(text) != n or len(src) != m:
            raise IndexError
        return TextMessage(text.decode("utf-8", "replace"), src.decode("utf-8", "replace"), level)
    except (IndexError, struct.error):
        raise RTDEError(f"malformed RTDE text message ({len(payload)} bytes, protocol {protocol}): {payload[:40]!r}")


@dataclass
class Recipe:
    """A configured RTDE recipe: the field names, their types and the packing layout.

    ``recipe_id`` is the id the controller assigned (0 on protocol version 1 outputs,
    which carry none). Values are ``bool`` (BOOL), ``int`` (UINT8/UINT32/INT32/UINT64),
    ``float`` (DOUBLE) or a tuple of 3 or 6 numbers (VECTOR3D, VECTOR6D, VECTOR6INT32,
    VECTOR6UINT32), in the controller's units (rad, m, s, rad/s, …).
    """

    recipe_id: int
    names: tuple[str, ...]
    types: tuple[str, ...]
    _struct: struct.Struct = field(init=False, repr=False, compare=False)
    _layout: tuple[tuple[str, int, int], ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.names = tuple(self.names)
        self.types = tuple(self.types)
        if len(self.names) != len(self.types):
            raise RTDEError(
                f"RTDE recipe has {len(self.names)} names but the controller returned {len(self.types)} types: "
                f"{list(self.names)} / {list(self.types)}"
            )
        fmt = ">"
        layout = []
        pos = 0
        for name, typ in zip(self.names, self.types):
            if typ not in DATA_TYPES:
                raise RTDEError(f"RTDE field {name!r} has unknown type {typ!r} (known: {', '.join(DATA_TYPES)})")
            code, count = DATA_TYPES[typ]
            fmt += code * count
            layout.append((name, pos, count if count > 1 else 0))
            pos += count
        self._struct = struct.Struct(fmt)
        self._layout = tuple(layout)

    @property
    def size(self) -> int:
        """Size of the packed values in bytes (recipe id not included)."""
        return self._struct.size

    def unpack(self, data: bytes | memoryview, offset: int = 0) -> dict[str, Any]:
        """Decode the packed values starting at ``offset`` into ``{name: value}``."""
        if len(data) - offset != self._struct.size:
            raise RTDEError(
                f"RTDE data package for recipe {self.recipe_id} has {len(data) - offset} bytes of values, "
                f"expected {self._struct.size} for {list(self.types)}"
            )
        flat = self._struct.unpack_from(data, offset)
        out: dict[str, Any] = {}
        for name, pos, count in self._layout:
            out[name] = flat[pos : pos + count] if count else flat[pos]
        return out

    def pack_values(self, values: Sequence[Any]) -> bytes:
        """Encode values given in recipe order (vectors as sequences); no name checks, for hot loops."""
        flat: list[Any] = []
        for (_name, _pos, count), v in zip(self._layout, values):
            if count:
                flat.extend(v)
            else:
                flat.append(v)
        return self._struct.pack(*flat)

    def pack(self, values: Mapping[str, Any]) -> bytes:
        """Encode ``{name: value}`` (exactly this recipe's names) into packed values."""
        missing = [n for n in self.names if n not in values]
        extra = [n for n in values if n not in self.names]
        if missing or extra:
            parts = []
            if missing:
                parts.append(f"missing {missing}")
            if extra:
                parts.append(f"not in the recipe {extra}")
            raise RTDEError(f"values for RTDE recipe {self.recipe_id} {list(self.names)} do not match: {'; '.join(parts)}")
        flat: list[Any] = []
        for (name, _pos, count), typ in zip(self._layout, self.types):
            v = values[name]
            if count:
                try:
                    seq = list(v)
                except TypeError:
                    raise RTDEError(f"RTDE field {name!r} ({typ}) needs {count} numbers, got {v!r}") from None
                if len(seq) != count:
                    raise RTDEError(f"RTDE field {name!r} ({typ}) needs {count} numbers, got {len(seq)}")
                flat.extend(seq)
            else:
                flat.append(v)
        try:
            return self._struct.pack(*flat)
        except struct.error as exc:
            bad = _find_bad_value(self, values)
            raise RTDEError(f"cannot encode RTDE values: {bad or exc}") from None


def _find_bad_value(recipe: Recipe, values: Mapping[str, Any]) -> str:
    for name, typ in zip(recipe.names, recipe.types):
        code, count = DATA_TYPES[typ]
        v = values[name]
        try:
            struct.pack(">" + code * count, *(list(v) if count > 1 else [v]))
        except (struct.error, TypeError) as exc:
            return f"field {name!r} ({typ}) value {v!r}: {exc}"
    return ""


class OutputRecipe(Recipe):
    """An output recipe (controller → client) and its output frequency [Hz]."""

    frequency_hz: float = 0.0


class InputRecipe(Recipe):
    """An input recipe (client → controller); pass values to :meth:`RTDEClient.send`."""


def _names_arg(names: Iterable[str] | str) -> list[str]:
    if isinstance(names, str):
        names = names.split(",")
    out = [n.strip() for n in names]
    if not out or any(not n for n in out):
        raise RTDEError(f"RTDE recipe needs non-empty field names, got {list(out)}")
    dup = sorted({n for n in out if out.count(n) > 1})
    if dup:
        raise RTDEError(f"RTDE recipe lists field(s) {dup} more than once")
    return out


