"""URScript's pure built-ins (math, lists, strings, pose arithmetic) and the calls that change nothing we judge.

Each pure built-in is a plain function of its argument values. :data:`NO_OPS` lists the calls a check can
ignore — messages, I/O, sockets, registers, installation settings that move nothing — each returning what the
controller would when nothing is connected (``False``/``0``/an empty string). :data:`INPUT_READS` are those that
read an input: a loop waiting on one is judged for the passes asked for (the input is assumed to arrive).
:data:`REFUSED` are the calls that change the motion in ways this model does not (force mode, free drive,
conveyor tracking, speed control): a script using one is refused with its line.
"""

from __future__ import annotations

import math
import random as _random
from typing import Any, Callable

from . import poses as P

__all__ = ["PURE", "NO_OPS", "INPUT_READS", "REFUSED", "MAX_LIST", "MAX_STRING", "BuiltinError"]

MAX_LIST = 10_000
MAX_STRING = 10_000


class BuiltinError(ValueError):
    """A built-in given arguments it cannot use; the interpreter adds the line."""


def _num(x: Any, what: str = "argument") -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        raise BuiltinError(f"{what} must be a number, got {type_name(x)}")
    return float(x)


def _pose(x: Any, what: str = "argument") -> P.Pose:
    if isinstance(x, P.Pose):
        return x
    raise BuiltinError(f"{what} must be a pose p[x, y, z, rx, ry, rz], got {type_name(x)}")


def _vector(x: Any, n: int | None = None, what: str = "argument") -> list[float]:
    if isinstance(x, (list, P.Pose)) and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in x):
        if n is None or len(x) == n:
            return [float(v) for v in x]
    raise BuiltinError(f"{what} must be a list of {n or 'some'} numbers, got {type_name(x)}")


def type_name(x: Any) -> str:
    if isinstance(x, P.Pose):
        return "a pose"
    if isinstance(x, bool):
        return "a boolean"
    if isinstance(x, (int, float)):
        return "a number"
    if isinstance(x, str):
        return "a string"
    if isinstance(x, list):
        return f"a list of {len(x)}"
    return type(x).__name__


def _str(x: Any) -> str:
    if isinstance(x, bool):
        return "True" if x else "False"
    if isinstance(x, float):
        return f"{x:.6g}"
    if isinstance(x, list):
        return "[" + ", ".join(_str(v) for v in x) + "]"
    return repr(x) if isinstance(x, P.Pose) else str(x)


def _str_cat(a: Any, b: Any) -> str:
    out = _str(a) + _str(b)
    if len(out) > MAX_STRING:
        raise BuiltinError(f"a string longer than {MAX_STRING:,} characters")
    return out


def _make_list(length: Any, initial: Any, capacity: Any = None) -> list:
    n = int(_num(length, "length"))
    if not 0 <= n <= MAX_LIST:
        raise BuiltinError(f"a list of {n} items; the limit is {MAX_LIST:,}")
    return [initial] * n


def _norm(x: Any) -> float:
    if isinstance(x, (int, float)) and not isinstance(x, bool):
        return abs(float(x))
    return math.sqrt(sum(v * v for v in _vector(x)))


def _normalize(x: Any) -> list[float]:
    v = _vector(x)
    n = math.sqrt(sum(c * c for c in v))
    if n == 0:
        raise BuiltinError("normalize() of a zero vector")
    return [c / n for c in v]


def _to_num(s: Any) -> float:
    try:
        return float(str(s))
    except ValueError:
        raise BuiltinError(f"to_num({str(s)[:40]!r}): not a number") from None


def _binary_list_to_integer(bits: Any) -> int:
    if not isinstance(bits, list) or len(bits) > 32:
        raise BuiltinError("binary_list_to_integer takes a list of at most 32 booleans")
    return sum(1 << i for i, b in enumerate(bits) if b)


def _safe(fn: Callable, *names: str) -> Callable:
    """A math function that reports a domain error as a BuiltinError."""

    def call(*args):
        try:
            return fn(*[_num(a, n) for a, n in zip(args, names)])
        except (ValueError, OverflowError, ZeroDivisionError) as exc:
            raise BuiltinError(f"{fn.__name__}{tuple(args)}: {exc}") from None

    return call


PURE: dict[str, Callable[..., Any]] = {
    "sin": _safe(math.sin, "x"), "cos": _safe(math.cos, "x"), "tan": _safe(math.tan, "x"),
    "asin": _safe(math.asin, "x"), "acos": _safe(math.acos, "x"), "atan": _safe(math.atan, "x"),
    "atan2": _safe(math.atan2, "y", "x"), "sqrt": _safe(math.sqrt, "x"), "log": _safe(math.log, "b", "f"),
    "pow": _safe(math.pow, "base", "exponent"),
    "floor": lambda x: int(math.floor(_num(x))), "ceil": lambda x: int(math.ceil(_num(x))),
    "round": lambda x: int(math.floor(_num(x) + 0.5)),
    "d2r": lambda x: math.radians(_num(x)), "r2d": lambda x: math.degrees(_num(x)),
    "norm": _norm, "normalize": _normalize, "length": lambda x: len(x) if isinstance(x, (list, str, P.Pose)) else 0,
    "get_list_length": lambda x: len(_vector(x)) if not isinstance(x, list) else len(x),
    "point_dist": lambda a, b: math.dist(_vector(a)[:3], _vector(b)[:3]),
    "pose_dist": lambda a, b: P.pose_dist(_pose(a), _pose(b)),
    "pose_trans": lambda a, b: P.pose_trans(_pose(a), _pose(b)),
    "pose_add": lambda a, b: P.pose_add(_pose(a), _pose(b)),
    "pose_sub": lambda a, b: P.pose_sub(_pose(a), _pose(b)),
    "pose_inv": lambda a: P.pose_inv(_pose(a)),
    "interpolate_pose": lambda a, b, alpha: P.interpolate_pose(_pose(a), _pose(b), _num(alpha, "alpha")),
    "rpy2rotvec": lambda rpy: P.rpy2rotvec(_vector(rpy, 3, "rpy")),
    "rotvec2rpy": lambda rv: P.rotvec2rpy(_vector(rv, 3, "rotation vector")),
    "to_str": _str, "str_cat": _str_cat, "str_len": lambda s: len(_str(s)), "str_empty": lambda s: _str(s) == "",
    "to_num": _to_num, "make_list": _make_list, "binary_list_to_integer": _binary_list_to_integer,
    "integer_to_binary_list": lambda x: [bool(int(_num(x)) >> i & 1) for i in range(32)],
    "is_nan": lambda x: isinstance(x, float) and math.isnan(x),
    "random": lambda: _random.Random(0).random(),  # deterministic: a check must not depend on chance
    # what the socket reads return when nothing answers: no values, an empty string
    "socket_read_ascii_float": lambda *a, **k: [0], "socket_read_binary_integer": lambda *a, **k: [0],
    "socket_read_byte_list": lambda *a, **k: [0], "socket_read_string": lambda *a, **k: "",
    "socket_read_line": lambda *a, **k: "",
    "is_within_safety_limits": lambda *a: True, "is_steady": lambda: True, "get_steptime": lambda: 0.002,
}  # fmt: skip

# calls that read an input: loops waiting on them are judged for the passes asked for
INPUT_READS = frozenset(
    "get_digital_in get_standard_digital_in get_tool_digital_in get_configurable_digital_in get_analog_in "
    "get_standard_analog_in get_tool_analog_in get_euromap_input read_input_boolean_register "
    "read_input_integer_register read_input_float_register socket_read_ascii_float socket_read_binary_integer "
    "socket_read_byte_list socket_read_line socket_read_string socket_get_var modbus_get_signal_status "
    "get_flag get_digital_out get_standard_digital_out get_tool_digital_out get_configurable_digital_out "
    "read_output_boolean_register read_output_integer_register read_output_float_register read_port_bit "
    "read_port_register get_euromap_output rpc_factory tool_contact".split()
)

NO_OPS = frozenset(
    "textmsg popup varmsg sync socket_open socket_close socket_send_string socket_send_line socket_send_byte "
    "socket_send_int socket_set_var set_digital_out set_standard_digital_out set_tool_digital_out "
    "set_configurable_digital_out set_analog_out set_standard_analog_out set_tool_voltage set_flag "
    "set_analog_inputrange set_analog_outputdomain set_standard_analog_input_domain set_tool_analog_input_domain "
    "set_input_actions_to_default set_gravity set_safety_mode_transition_hardness set_tool_communication "
    "set_tool_output_mode set_tool_digital_output_mode set_runstate_standard_digital_output_to_value "
    "set_runstate_tool_digital_output_to_value set_runstate_configurable_digital_output_to_value "
    "set_standard_digital_input_action set_tool_digital_input_action set_configurable_digital_input_action "
    "set_gp_boolean_input_action set_conveyor_tick_count set_euromap_output set_euromap_runstate_dependent_choice "
    "write_output_boolean_register write_output_integer_register write_output_float_register write_port_bit "
    "write_port_register modbus_add_signal modbus_delete_signal modbus_set_output_register "
    "modbus_set_output_signal modbus_set_runstate_dependent_choice modbus_set_signal_update_frequency "
    "modbus_send_custom_command rtde_set_watchdog set_payload_cog set_target_payload set_payload_mass "
    "set_tcp_offset zero_ftsensor stop_conveyor_tracking end_force_mode end_freedrive_mode end_teach_mode "
    "set_safety_mode_transition_hardness set_tool_communication set_tool_output_mode kill join "
    "enter_critical exit_critical get_controller_temp get_tool_accelerometer_reading".split()
) | INPUT_READS

#: Calls that steer the arm in ways this model does not simulate.
REFUSED = {
    "force_mode": "force control moves the arm by contact forces",
    "freedrive_mode": "free drive moves the arm by hand",
    "teach_mode": "teach mode moves the arm by hand",
    "speedj": "velocity control",
    "speedl": "velocity control",
    "servoc": "circular servoing",
    "track_conveyor_linear": "conveyor tracking",
    "track_conveyor_circular": "conveyor tracking",
    "position_deviation_warning": "",
    "path_offset_enable": "path offsets",
    "direct_torque": "torque control",
    "torque_command": "torque control",
    "set_external_force_torque": "force control",
    "screw_driving": "screwing",
}
