"""The loopback controller's state: what it knows each control cycle, the RTDE fields it reads and writes,
the UR3e kinematics of ``actual_TCP_pose``, and the public records (:class:`SimEvent`, :class:`SimSnapshot`).

Part of :mod:`robocritics.testing.ursim` (see :mod:`~robocritics.testing.ursim.controller`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Sequence

from robocritics.deploy.rtde import DATA_TYPES, RobotMode, RuntimeState, SafetyMode
from robocritics.robot.arms import DH, UR3E
from robocritics.robot.ik import dh_forward

DT = UR3E.control_period_s
"""Control period [s]: one control cycle of the UR3e (``robocritics.robot.arms.UR3E``)."""

DEFAULT_ROBOT_MODE = "RUNNING"
"""Robot mode a new controller starts in (``URSim()`` and ``robocritics ursim``): powered, brakes released."""

CLOCKS = ("realtime", "stepped")
"""How the controller's time advances (see :class:`URSim`)."""

CONTROLLER_STOP_DECEL = 4.0
"""Deceleration when the controller stops a program (watchdog, dashboard stop) [rad/s²]."""
PROTECTIVE_STOP_DECEL = 10.0
"""Deceleration of a protective stop [rad/s²]."""

_JOINT_MODE = {RobotMode.POWER_OFF: 239, RobotMode.IDLE: 255, RobotMode.RUNNING: 253}
_SAFETY_STATUS_BIT = {1: 0, 2: 1, 3: 2, 4: 3, 5: 4, 6: 5, 7: 6, 8: 8, 9: 9}
"""safety_mode → its bit in ``safety_status_bits``."""



# ---------------------------------------------------------------------------- kinematics


def _rotvec(r: list[list[float]]) -> tuple[float, float, float]:
    tr = r[0][0] + r[1][1] + r[2][2]
    cos = max(-1.0, min(1.0, (tr - 1.0) / 2.0))
    angle = math.acos(cos)
    if angle < 1e-9:
        return (0.0, 0.0, 0.0)
    if math.pi - angle < 1e-6:
        # axis from the largest diagonal element of (R + I)/2
        xx, yy, zz = (r[0][0] + 1) / 2, (r[1][1] + 1) / 2, (r[2][2] + 1) / 2
        if xx >= yy and xx >= zz:
            x = math.sqrt(max(xx, 0.0))
            y, z = (r[0][1] + r[1][0]) / (4 * x), (r[0][2] + r[2][0]) / (4 * x)
        elif yy >= zz:
            y = math.sqrt(max(yy, 0.0))
            x, z = (r[0][1] + r[1][0]) / (4 * y), (r[1][2] + r[2][1]) / (4 * y)
        else:
            z = math.sqrt(max(zz, 0.0))
            x, y = (r[0][2] + r[2][0]) / (4 * z), (r[1][2] + r[2][1]) / (4 * z)
        return (x * angle, y * angle, z * angle)
    k = angle / (2 * math.sin(angle))
    return ((r[2][1] - r[1][2]) * k, (r[0][2] - r[2][0]) * k, (r[1][0] - r[0][1]) * k)


_ELBOW_DH = DH(d=(UR3E.dh.d[0],) + (0.0,) * 5, a=(0.0, UR3E.dh.a[1]) + (0.0,) * 4,
               alpha=(UR3E.dh.alpha[0],) + (0.0,) * 5, name="ur3e shoulder and upper arm")
"""The UR3e's first two DH links alone: its flange pose is the elbow frame ``T_02``."""


def ur3e_fk(q: Sequence[float]) -> tuple[tuple[float, ...], tuple[float, float, float]]:
    """UR3e forward kinematics by :func:`robocritics.robot.ik.dh_forward` (flange, no tool):
    ((x, y, z [m], rx, ry, rz [rad, rotation vector]), elbow xyz [m])."""
    t = dh_forward(UR3E.dh, q)
    elbow = dh_forward(_ELBOW_DH, (q[0], q[1], 0.0, 0.0, 0.0, 0.0))[:3, 3]
    return (*(float(v) for v in t[:3, 3]), *_rotvec(t[:3, :3].tolist())), (float(elbow[0]), float(elbow[1]), float(elbow[2]))


# ---------------------------------------------------------------------------- state


class _State:
    """Everything the controller knows; guarded by ``URSim._lock``."""

    def __init__(self, q: Sequence[float], robot_mode: int) -> None:
        self.tick = 0
        self.q = [float(v) for v in q]
        self.qd = [0.0] * 6
        self.target_q = list(self.q)
        self.target_qd = [0.0] * 6
        self.target_qdd = [0.0] * 6
        self.robot_mode = robot_mode
        self.safety_mode = SafetyMode.NORMAL
        self.runtime_state = RuntimeState.STOPPED
        self.in_int = [0] * 48
        self.in_double = [0.0] * 48
        self.in_bits = 0  # 128 bits
        self.out_int = [0] * 48
        self.out_double = [0.0] * 48
        self.out_bits = 0
        self.digital_out = 0  # bits 0-7 standard, 8-15 configurable, 16-17 tool
        self.analog_out = [0.0, 0.0]
        self.speed_slider_fraction = 1.0
        self.external_force_torque = (0.0,) * 6
        self.gripper_opening_m = 0.0
        self.extras: dict[str, Any] = {}
        self.input_update_tick: dict[str, int] = {}
        self.exec_time_ms = 0.0
        self._fk_tick = -1
        self._fk: tuple[tuple[float, ...], tuple[float, float, float]] = ((0.0,) * 6, (0.0, 0.0, 0.0))
        self._tfk_tick = -1
        self._tfk: tuple[float, ...] = (0.0,) * 6

    def fk(self) -> tuple[tuple[float, ...], tuple[float, float, float]]:
        if self._fk_tick != self.tick:
            self._fk = ur3e_fk(self.q)
            self._fk_tick = self.tick
        return self._fk

    def target_fk(self) -> tuple[float, ...]:
        if self._tfk_tick != self.tick:
            self._tfk = ur3e_fk(self.target_q)[0]
            self._tfk_tick = self.tick
        return self._tfk

    @property
    def powered(self) -> bool:
        return self.robot_mode >= RobotMode.POWER_ON

    def robot_status_bits(self) -> int:
        return (1 if self.powered else 0) | (2 if self.runtime_state == RuntimeState.PLAYING else 0)

    def safety_status_bits(self) -> int:
        bits = 1 << _SAFETY_STATUS_BIT.get(self.safety_mode, 0)
        if self.safety_mode in (SafetyMode.SYSTEM_EMERGENCY_STOP, SafetyMode.ROBOT_EMERGENCY_STOP):
            bits |= 1 << 7
        if self.safety_mode not in (SafetyMode.NORMAL, SafetyMode.REDUCED):
            bits |= 1 << 10
        return bits


_Z6 = (0.0,) * 6
_Getter = Callable[[_State], Any]
_Setter = Callable[[_State, Any, dict], None]


def _build_outputs() -> dict[str, tuple[str, _Getter]]:
    o: dict[str, tuple[str, _Getter]] = {
        "timestamp": ("DOUBLE", lambda s: s.tick * DT),
        "target_q": ("VECTOR6D", lambda s: s.target_q),
        "target_qd": ("VECTOR6D", lambda s: s.target_qd),
        "target_qdd": ("VECTOR6D", lambda s: s.target_qdd),
        "target_current": ("VECTOR6D", lambda s: _Z6),
        "target_moment": ("VECTOR6D", lambda s: _Z6),
        "actual_q": ("VECTOR6D", lambda s: s.q),
        "actual_qd": ("VECTOR6D", lambda s: s.qd),
        "actual_current": ("VECTOR6D", lambda s: _Z6),
        "actual_current_window": ("VECTOR6D", lambda s: _Z6),
        "actual_current_as_torque": ("VECTOR6D", lambda s: _Z6),
        "joint_control_output": ("VECTOR6D", lambda s: _Z6),
        "actual_TCP_pose": ("VECTOR6D", lambda s: s.fk()[0]),
        "actual_TCP_speed": ("VECTOR6D", lambda s: _Z6),
        "actual_TCP_force": ("VECTOR6D", lambda s: _Z6),
        "target_TCP_pose": ("VECTOR6D", lambda s: s.target_fk()),
        "target_TCP_speed": ("VECTOR6D", lambda s: _Z6),
        "actual_digital_input_bits": ("UINT64", lambda s: 0),
        "joint_temperatures": ("VECTOR6D", lambda s: (25.0,) * 6),
        "actual_execution_time": ("DOUBLE", lambda s: s.exec_time_ms),
        "robot_mode": ("INT32", lambda s: s.robot_mode),
        "joint_mode": ("VECTOR6INT32", lambda s: (_JOINT_MODE.get(s.robot_mode, 239),) * 6),
        "safety_mode": ("INT32", lambda s: s.safety_mode),
        "safety_status": ("INT32", lambda s: s.safety_mode),
        "actual_tool_accelerometer": ("VECTOR3D", lambda s: (0.0, 0.0, 9.81)),
        "speed_scaling": ("DOUBLE", lambda s: s.speed_slider_fraction),
        "target_speed_fraction": ("DOUBLE", lambda s: s.speed_slider_fraction),
        "actual_momentum": ("DOUBLE", lambda s: 0.0),
        "actual_main_voltage": ("DOUBLE", lambda s: 48.0),
        "actual_robot_voltage": ("DOUBLE", lambda s: 48.0 if s.powered else 0.0),
        "actual_robot_current": ("DOUBLE", lambda s: 0.4 if s.powered else 0.0),
        "actual_joint_voltage": ("VECTOR6D", lambda s: (48.0,) * 6 if s.powered else _Z6),
        "actual_digital_output_bits": ("UINT64", lambda s: s.digital_out),
        "runtime_state": ("UINT32", lambda s: s.runtime_state),
        "elbow_position": ("VECTOR3D", lambda s: s.fk()[1]),
        "elbow_velocity": ("VECTOR3D", lambda s: (0.0, 0.0, 0.0)),
        "robot_status_bits": ("UINT32", lambda s: s.robot_status_bits()),
        "safety_status_bits": ("UINT32", lambda s: s.safety_status_bits()),
        "joint_position_deviation_ratio": ("DOUBLE", lambda s: 0.0),
        "collision_detection_ratio": ("DOUBLE", lambda s: 0.0),
        "time_scale_source": ("INT32", lambda s: 0),
        "analog_io_types": ("UINT32", lambda s: 0),
        "standard_analog_input0": ("DOUBLE", lambda s: 0.0),
        "standard_analog_input1": ("DOUBLE", lambda s: 0.0),
        "standard_analog_output0": ("DOUBLE", lambda s: s.analog_out[0]),
        "standard_analog_output1": ("DOUBLE", lambda s: s.analog_out[1]),
        "io_current": ("DOUBLE", lambda s: 0.0),
        "euromap67_input_bits": ("UINT32", lambda s: 0),
        "euromap67_output_bits": ("UINT32", lambda s: 0),
        "euromap67_24V_voltage": ("DOUBLE", lambda s: 0.0),
        "euromap67_24V_current": ("DOUBLE", lambda s: 0.0),
        "tool_mode": ("UINT32", lambda s: 0),
        "tool_analog_input_types": ("UINT32", lambda s: 0),
        "tool_analog_input0": ("DOUBLE", lambda s: 0.0),
        "tool_analog_input1": ("DOUBLE", lambda s: 0.0),
        "tool_output_voltage": ("INT32", lambda s: 24 if s.powered else 0),
        "tool_output_current": ("DOUBLE", lambda s: 0.0),
        "tool_temperature": ("DOUBLE", lambda s: 30.0),
        "tcp_force_scalar": ("DOUBLE", lambda s: 0.0),
        "tool_output_mode": ("UINT8", lambda s: 0),
        "tool_digital_output0_mode": ("UINT8", lambda s: 1),
        "tool_digital_output1_mode": ("UINT8", lambda s: 1),
        "ft_raw_wrench": ("VECTOR6D", lambda s: _Z6),
        "payload": ("DOUBLE", lambda s: 0.0),
        "payload_cog": ("VECTOR3D", lambda s: (0.0, 0.0, 0.0)),
        "payload_inertia": ("VECTOR6D", lambda s: _Z6),
        "script_control_line": ("UINT32", lambda s: 0),
        "output_bit_registers0_to_31": ("UINT32", lambda s: s.out_bits & 0xFFFFFFFF),
        "output_bit_registers32_to_63": ("UINT32", lambda s: (s.out_bits >> 32) & 0xFFFFFFFF),
        "input_bit_registers0_to_31": ("UINT32", lambda s: s.in_bits & 0xFFFFFFFF),
        "input_bit_registers32_to_63": ("UINT32", lambda s: (s.in_bits >> 32) & 0xFFFFFFFF),
    }
    for n in range(64, 128):
        o[f"output_bit_register_{n}"] = ("BOOL", lambda s, n=n: bool((s.out_bits >> n) & 1))
        o[f"input_bit_register_{n}"] = ("BOOL", lambda s, n=n: bool((s.in_bits >> n) & 1))
    for n in range(48):
        o[f"output_int_register_{n}"] = ("INT32", lambda s, n=n: s.out_int[n])
        o[f"output_double_register_{n}"] = ("DOUBLE", lambda s, n=n: s.out_double[n])
        o[f"input_int_register_{n}"] = ("INT32", lambda s, n=n: s.in_int[n])
        o[f"input_double_register_{n}"] = ("DOUBLE", lambda s, n=n: s.in_double[n])
    return o


def _set_bits(s: _State, lo: int, width: int, value: int) -> None:
    mask = ((1 << width) - 1) << lo
    s.in_bits = (s.in_bits & ~mask) | ((int(value) << lo) & mask)


def _build_inputs() -> dict[str, tuple[str, _Setter]]:
    def pend(key: str) -> _Setter:
        return lambda s, v, p: p.__setitem__(key, v)

    i: dict[str, tuple[str, _Setter]] = {
        "speed_slider_mask": ("UINT32", pend("slider_mask")),
        "speed_slider_fraction": ("DOUBLE", pend("slider_fraction")),
        "standard_digital_output_mask": ("UINT8", pend("std_mask")),
        "standard_digital_output": ("UINT8", pend("std")),
        "configurable_digital_output_mask": ("UINT8", pend("conf_mask")),
        "configurable_digital_output": ("UINT8", pend("conf")),
        "tool_digital_output_mask": ("UINT8", pend("tool_mask")),
        "tool_digital_output": ("UINT8", pend("tool")),
        "standard_analog_output_mask": ("UINT8", pend("ao_mask")),
        "standard_analog_output_type": ("UINT8", pend("ao_type")),
        "standard_analog_output_0": ("DOUBLE", pend("ao0")),
        "standard_analog_output_1": ("DOUBLE", pend("ao1")),
        "input_bit_registers0_to_31": ("UINT32", lambda s, v, p: _set_bits(s, 0, 32, v)),
        "input_bit_registers32_to_63": ("UINT32", lambda s, v, p: _set_bits(s, 32, 32, v)),
        "external_force_torque": ("VECTOR6D", lambda s, v, p: setattr(s, "external_force_torque", tuple(v))),
    }
    for n in range(64, 128):
        i[f"input_bit_register_{n}"] = ("BOOL", lambda s, v, p, n=n: _set_bits(s, n, 1, 1 if v else 0))
    for n in range(48):
        i[f"input_int_register_{n}"] = ("INT32", lambda s, v, p, n=n: s.in_int.__setitem__(n, v))
        i[f"input_double_register_{n}"] = ("DOUBLE", lambda s, v, p, n=n: s.in_double.__setitem__(n, v))
    return i


def _apply_pending(s: _State, p: dict) -> None:
    if not p:
        return
    if "slider_mask" in p and p["slider_mask"] & 1 and "slider_fraction" in p:
        s.speed_slider_fraction = min(1.0, max(0.0, float(p["slider_fraction"])))
    for key, lo in (("std", 0), ("conf", 8), ("tool", 16)):
        mask = p.get(key + "_mask", 0) & (0xFF if key != "tool" else 0x3)
        if mask:
            val = p.get(key, 0)
            s.digital_out = (s.digital_out & ~(mask << lo)) | ((val & mask) << lo)
    ao_mask = p.get("ao_mask", 0)
    if ao_mask & 1 and "ao0" in p:
        s.analog_out[0] = float(p["ao0"])
    if ao_mask & 2 and "ao1" in p:
        s.analog_out[1] = float(p["ao1"])


KNOWN_OUTPUTS: dict[str, tuple[str, _Getter]] = _build_outputs()
"""Output fields the loopback controller knows: name → (RTDE type, getter)."""
KNOWN_INPUTS: dict[str, tuple[str, _Setter]] = _build_inputs()
"""Input fields the loopback controller accepts: name → (RTDE type, setter)."""

FIELDBUS_FIELDS = frozenset(
    [f"input_int_register_{n}" for n in range(24)]
    + [f"input_double_register_{n}" for n in range(24)]
    + ["input_bit_registers0_to_31", "input_bit_registers32_to_63"]
)
"""Inputs a configured fieldbus (EtherNet/IP, PROFINET) owns: registers 0-23 and bit registers 0-63."""


# ---------------------------------------------------------------------------- public records


@dataclass(frozen=True)
class SimEvent:
    """Something that happened in the controller: ``time_s`` is controller time [s]."""

    time_s: float
    kind: str
    message: str


@dataclass(frozen=True)
class SimSnapshot:
    """A consistent copy of the controller state. Angles rad, speeds rad/s, time s."""

    time_s: float
    q: tuple[float, ...]
    qd: tuple[float, ...]
    target_q: tuple[float, ...]
    robot_mode: int
    safety_mode: int
    runtime_state: int
    program: str | None
    """Name of the running program, None if none runs."""
    program_state: int
    """output_int_register_25 (the streaming program's state)."""
    applied_seq: int
    """output_int_register_24 (last sequence number the program applied)."""
    gripper_opening_m: float
    digital_out: int
    program_time_s: float = 0.0
    """Controller time the running program has run [s] (0 if none runs)."""

    @property
    def robot_mode_name(self) -> str:
        return _enum_name(RobotMode, self.robot_mode)

    @property
    def safety_mode_name(self) -> str:
        return _enum_name(SafetyMode, self.safety_mode)

    @property
    def runtime_state_name(self) -> str:
        return _enum_name(RuntimeState, self.runtime_state)


def _enum_name(kind: type, value: int) -> str:
    """The name of ``value`` in the IntEnum ``kind`` (``"UNKNOWN"`` if it has none)."""
    try:
        return kind(value).name
    except ValueError:
        return "UNKNOWN"


def _extra_getter(name: str, t: str) -> _Getter:
    return lambda s: s.extras.get(name, _zero(t))


def _zero(t: str) -> Any:
    code, count = DATA_TYPES[t]
    one: Any = False if code == "?" else 0.0 if code == "d" else 0
    return (one,) * count if count > 1 else one
