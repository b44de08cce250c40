"""The simulated arm a URScript program commands: motion, gripper, TCP, and the state queries.

:class:`Arm` answers the interpreter's calls of motion built-ins (``movej``, ``movel``, ``movep``,
``servoj``, ``stopj``/``stopl``, ``sleep``, ``sync``), of the gripper (Robotiq ``rq_*``, and
``set_*digital_out`` on the ``--gripper-io`` output: high closes), of ``set_tcp``/``set_payload`` and of the
queries (``get_actual_joint_positions``, ``get_actual_tcp_pose``, ``get_forward_kin``, ``get_inverse_kin``
...), which read the simulated state: where the arm is when the previous command has finished.

Every command that takes time becomes a :class:`~.timeline.Segment` whose samples name a
:class:`~robocritics.trajectory.Step` (the command and its source line), so a critic's evidence names lines.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ...errors import PlanningError
from ...trajectory import Step
from . import poses as P
from .builtins import BuiltinError
from .syntax import URScriptError
from .timeline import MAX_MOTION_S, Segment, Timeline
from .timing import profile_for, trapezoid_fraction

__all__ = ["Arm", "ArmOptions", "CONTROL_PERIOD_S", "GRIPPER_STROKE_S"]

CONTROL_PERIOD_S = 0.002  # the e-series controller's cycle (robot/arms.py: UR3E.control_period_s)
#: Full stroke of a Robotiq 2F-85 at its default speed, s (the planner's gripper time).
GRIPPER_STROKE_S = 0.5
#: servoj keeps pulling towards its last target after the stream ends until within this (rad), at most 2 s.
SERVO_SETTLED_RAD = 1e-4

_GRIPPER_CALLS = {
    "rq_open": 0.0, "rq_open_and_wait": 0.0, "rq_close": 255.0, "rq_close_and_wait": 255.0,
}  # fmt: skip
_GRIPPER_POSITION_CALLS = ("rq_move", "rq_move_and_wait", "rq_move_norm", "rq_move_and_wait_norm")
_GRIPPER_MM_CALLS = ("rq_move_mm", "rq_move_and_wait_mm")
_DIGITAL_OUTS = ("set_digital_out", "set_standard_digital_out", "set_tool_digital_out", "set_configurable_digital_out")


@dataclass(frozen=True)
class ArmOptions:
    """What lives in the robot's installation, not the file: TCP (flange to TCP, a pose), payload, start, I/O."""

    tcp: tuple[float, ...] | None = None  # default: the robot model's TCP (its gripper's fingertips)
    payload_kg: float = 0.0
    start_q: tuple[float, ...] | None = None  # default: the robot's home
    gripper_io: int | None = None
    rate_hz: float = 125.0


class Arm:
    """The simulated UR arm: state, the timeline of commanded motion, and the steps (command + line)."""

    def __init__(self, robot, options: ArmOptions, source_lines: list[str]):
        dh = getattr(robot, "dh", None)
        if dh is None or not getattr(dh, "is_ur_like", False) or robot.tcp_in_flange is None:
            raise URScriptError(f"URScript runs on UR arms; the robot {robot.name!r} has no UR kinematics (use --robot ur3e, ur5e, ...)")
        if getattr(robot, "dh_base_inverse", None) is not None:  # URScript poses are in UR's base frame, not the file's
            raise URScriptError(f"URScript runs on UR arms in UR's base frame; the robot {robot.name!r} is a UR chain in "
                                "another base convention (a ROS description): use --robot ur3e, ur5e, ...")
        self.robot = robot
        self.options = options
        self.lines = source_lines
        self.robot_tcp = np.asarray(robot.tcp_in_flange)
        self.tcp = self.robot_tcp.copy() if options.tcp is None else P.pose_matrix(options.tcp)
        self.payload_kg = options.payload_kg
        q0 = robot.home_q if options.start_q is None else robot.joint_vector(options.start_q, "--start-q", URScriptError)
        self.max_opening = float(robot.max_opening_m)
        start = np.append(np.asarray(q0, float), self.max_opening)
        self.timeline = Timeline(start, lambda q: robot.tcp_pose(q)[..., :3, 3])
        self.steps: list[Step] = []
        self._step_index: dict[tuple[str, int], int] = {}
        self.servo: list[tuple[np.ndarray, float, float, int]] = []  # (target, t, tau, step) of a running stream
        self.servo_side: list[tuple[int, Segment]] = []  # (cycle, segment) started beside the stream
        self._servo_s = 0.0  # duration of the running stream, s
        self.line = 0
        self._handlers: dict[str, Callable[..., Any]] = {
            "movej": self.movej, "movel": self.movel, "movep": self.movep, "movec": self.movec, "servoj": self.servoj,
            "stopj": self.stop, "stopl": self.stop, "sleep": self.sleep, "sync": self.sync,
            "set_tcp": self.set_tcp, "set_payload": self.set_payload,
            "get_actual_joint_positions": self.joints, "get_target_joint_positions": self.joints,
            "get_actual_tcp_pose": self.tcp_pose, "get_target_tcp_pose": self.tcp_pose,
            "get_forward_kin": self.forward_kin, "get_inverse_kin": self.inverse_kin,
            "get_inverse_kin_has_solution": self.has_inverse_kin, "get_tcp_offset": self.tcp_offset,
            "get_actual_joint_speeds": self.zeros, "get_target_joint_speeds": self.zeros,
            "get_actual_tcp_speed": self.zeros, "get_target_tcp_speed": self.zeros,
            "get_target_payload": lambda: self.payload_kg,
        }  # fmt: skip
        for name, position in _GRIPPER_CALLS.items():
            self._handlers[name] = self._gripper_call(name, position)
        for name in _GRIPPER_POSITION_CALLS + _GRIPPER_MM_CALLS:
            self._handlers[name] = self._gripper_move(name)
        if options.gripper_io is not None:
            for name in _DIGITAL_OUTS:
                self._handlers[name] = self._digital_out(name)

    # ------------------------------------------------------------------ plumbing
    def handler(self, name: str) -> Callable[..., Any] | None:
        return self._handlers.get(name)

    def at(self, line: int) -> "Arm":
        self.line = line
        return self

    @property
    def q(self) -> np.ndarray:
        if self.servo:
            return self.servo[-1][0]
        return self.timeline.end[:-1]

    @property
    def opening(self) -> float:
        return float(self.timeline.end[-1]) + sum(float(seg.values[-1, -1] - seg.values[0, -1]) for _, seg in self.servo_side)

    def step(self, skill: str) -> int:
        key = (skill, self.line)
        index = self._step_index.get(key)
        if index is None:
            text = self.lines[self.line - 1].strip()[:120] if 0 < self.line <= len(self.lines) else ""
            index = self._step_index[key] = len(self.steps)
            self.steps.append(Step(skill=skill, line=self.line, args=text))
        return index

    def add(
        self, times: np.ndarray, q: np.ndarray, opening: np.ndarray, skill: str, blend_m: float = 0.0,
        moves: bool = True, parallel: bool = False,
    ) -> None:  # fmt: skip
        values = np.column_stack([q, opening])
        steps = np.full(len(times), self.step(skill), dtype=np.int64)
        segment = Segment(times, values, steps, blend_m, moves, parallel=parallel)
        if parallel and self.servo:  # beside a servo stream: starts where the stream has got to
            self.servo_side.append((sum(max(1, int(round(t / CONTROL_PERIOD_S))) for _, t, _, _ in self.servo), segment))
            return
        self.flush_servo()
        self.timeline.add(segment, self.line)

    def local_times(self, duration: float) -> np.ndarray:
        if not duration <= MAX_MOTION_S - self.timeline.end_time:  # before any sample is made (NaN fails too)
            raise BuiltinError(
                f"this command ({duration:.4g} s) takes the motion beyond the {MAX_MOTION_S:.0f} s one check may hold"
            )
        n = max(1, int(math.ceil(duration * self.options.rate_hz - 1e-9)))
        return np.linspace(0.0, duration, n + 1)

    # ------------------------------------------------------------------ conversions
    def flange(self, tcp_pose: np.ndarray) -> np.ndarray:
        return tcp_pose @ np.linalg.inv(self.tcp)

    def pose_of(self, q, tcp: np.ndarray | None = None) -> np.ndarray:
        """The script TCP's 4x4 pose (m, base frame) at joints ``q``."""
        flange = self.robot.tcp_pose(np.asarray(q, float)) @ np.linalg.inv(self.robot_tcp)
        return flange @ (self.tcp if tcp is None else tcp)

    def ik(self, tcp_pose: np.ndarray, seed, tcp: np.ndarray | None = None) -> np.ndarray:
        from ...robot.ik import ur_ik

        flange = tcp_pose @ np.linalg.inv(self.tcp if tcp is None else tcp)
        try:
            return ur_ik(self.robot.dh, flange, np.asarray(seed, float), self.robot.lower, self.robot.upper)
        except PlanningError as exc:
            raise PlanningError(f"{exc.reason}", line=self.line) from None

    def joint_target(self, target: Any, what: str) -> np.ndarray:
        if isinstance(target, P.Pose):
            return self.ik(P.pose_matrix(target), self.q)
        if isinstance(target, list) and len(target) == self.robot.n and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in target
        ):
            if not all(math.isfinite(v) and abs(v) < 100.0 for v in target):
                raise BuiltinError(f"{what} must be finite joint angles in rad, got {_short(target)}")
            try:  # within the joint limits, as the controller requires
                return self.robot.joint_vector(target, what, BuiltinError)
            except BuiltinError:
                raise
            except Exception as exc:  # pragma: no cover - joint_vector raises the error given
                raise BuiltinError(str(exc)) from None
        raise BuiltinError(f"{what} must be {self.robot.n} joint angles [rad] or a pose, got {target!r}"[:200])

    def pose_target(self, target: Any, what: str) -> np.ndarray:
        if isinstance(target, P.Pose):
            return P.pose_matrix(target)
        return self.pose_of(self.joint_target(target, what))

    # ------------------------------------------------------------------ motion
    def movej(self, q, a: float = 1.4, v: float = 1.05, t: float = 0.0, r: float = 0.0) -> None:
        a, v, t, r = _positive(a, "a"), _positive(v, "v"), _non_negative(t, "t"), _non_negative(r, "r")
        self.flush_servo()
        start, goal = self.q.copy(), self.joint_target(q, "movej's q")
        delta = goal - start
        lead = float(np.max(np.abs(delta)))
        T, peak, acc = profile_for(lead, v, a, t)
        times = self.local_times(T)
        s = trapezoid_fraction(times, T, peak, acc, lead)
        self.add(times, start + s[:, None] * delta, np.full(len(times), self.opening), "movej", r)

    def movel(self, pose, a: float = 1.2, v: float = 0.25, t: float = 0.0, r: float = 0.0, _skill: str = "movel") -> None:
        a, v, t, r = _positive(a, "a"), _positive(v, "v"), _non_negative(t, "t"), _non_negative(r, "r")
        self.flush_servo()
        start, goal = self.pose_of(self.q), self.pose_target(pose, f"{_skill}'s pose")
        length = float(np.linalg.norm(goal[:3, 3] - start[:3, 3]))
        self.tool_path(start, goal, length, lambda s: start[:3, 3] + s[:, None] * (goal[:3, 3] - start[:3, 3]), a, v, t, r, _skill)

    def movec(self, pose_via, pose_to, a: float = 1.2, v: float = 0.25, r: float = 0.0, mode: int = 0) -> None:
        """The arc from here through ``pose_via`` to ``pose_to``, trapezoidal along the arc; the orientation is
        interpolated from start to end (mode 0, the default; the other modes are timed the same)."""
        a, v, r = _positive(a, "a"), _positive(v, "v"), _non_negative(r, "r")
        self.flush_servo()
        start = self.pose_of(self.q)
        via, goal = self.pose_target(pose_via, "movec's pose_via"), self.pose_target(pose_to, "movec's pose_to")
        p1, p2, p3 = start[:3, 3], via[:3, 3], goal[:3, 3]
        normal = np.cross(p2 - p1, p3 - p1)
        if np.linalg.norm(normal) < 1e-9:
            raise BuiltinError("movec: the start, via and end points lie on one line, so they define no circle")
        system = np.array([2 * (p2 - p1), 2 * (p3 - p1), normal])
        centre = np.linalg.solve(system, [p2 @ p2 - p1 @ p1, p3 @ p3 - p1 @ p1, normal @ p1])
        radius = float(np.linalg.norm(p1 - centre))
        u = (p1 - centre) / radius
        w = np.cross(normal / np.linalg.norm(normal), u)
        end = (p3 - centre) / radius
        sweep = float(np.arctan2(end @ w, end @ u)) % (2 * math.pi) or 2 * math.pi
        arc = lambda s: centre + radius * (np.cos(s * sweep)[:, None] * u + np.sin(s * sweep)[:, None] * w)  # noqa: E731
        self.tool_path(start, goal, radius * sweep, arc, a, v, 0.0, r, "movec")

    def tool_path(self, start, goal, length: float, position, a: float, v: float, t: float, r: float, skill: str) -> None:
        """The tool from ``start`` to ``goal`` (4x4) along ``position(s)`` (s in [0, 1] -> m), trapezoidal in
        ``length`` (m) or in the turn (rad, same numbers) when that takes longer; orientation slerped; IK per sample."""
        from ...robot.ik import ur_ik_line

        seed = self.q.copy()
        angle = float(np.linalg.norm(P.matrix_to_rotvec(start[:3, :3].T @ goal[:3, :3])))
        lead = max((length, angle), key=lambda d: profile_for(d, v, a, t)[0])
        T, peak, acc = profile_for(lead, v, a, t)
        times = self.local_times(T)
        s = trapezoid_fraction(times, T, peak, acc, lead)
        path = np.empty((len(s), 4, 4))
        path[:] = np.eye(4)
        path[:, :3, :3] = P.slerp_rotations(start[:3, :3], goal[:3, :3], s)
        path[:, :3, 3] = position(s)
        flanges = path[1:] @ np.linalg.inv(self.tcp)
        q, error = ur_ik_line(self.robot.dh, flanges, seed, self.robot.lower, self.robot.upper)
        if error is not None:
            where = float(times[1 + len(q)])
            raise PlanningError(f"{skill}: the tool path leaves the arm's reach {where:.2f} s into the move: {error.reason}", line=self.line)
        self.add(times, np.vstack([seed[None, :], q]), np.full(len(times), self.opening), skill, r)

    def movep(self, pose, a: float = 1.2, v: float = 0.25, r: float = 0.0) -> None:
        self.movel(pose, a, v, 0.0, r, _skill="movep")

    def servoj(self, q, a: float = 0.0, v: float = 0.0, t: float = 0.002, lookahead_time: float = 0.1, gain: float = 300) -> None:
        t, lookahead, gain = _positive(t, "t"), _non_negative(lookahead_time, "lookahead_time"), _positive(gain, "gain")
        if not 0.03 <= lookahead <= 0.2 or not 100 <= gain <= 2000:
            raise BuiltinError(f"servoj: lookahead_time must lie in [0.03, 0.2] s and gain in [100, 2000], got {lookahead}, {gain}")
        target = self.joint_target(q, "servoj's q")
        tau = max(CONTROL_PERIOD_S, lookahead * 300.0 / gain)
        streamed = self._servo_s if self.servo else 0.0
        if not t + streamed <= MAX_MOTION_S - self.timeline.end_time:
            raise BuiltinError(f"the servo stream lasts more than the {MAX_MOTION_S:.0f} s of motion one check may hold")
        self._servo_s = streamed + t
        self.servo.append((target, t, tau, self.step("servoj")))

    def flush_servo(self) -> None:
        """The running servoj stream as one segment: the loopback controller's tracking model, cycle by cycle.

        Per 2 ms cycle: joint velocity = the stream's speed (target change / t) + (setpoint − q) / τ, the
        setpoint moving linearly from the previous target to this one over ``t``, with
        τ = lookahead_time × 300 / gain, clipped to the joint speed limits; after the last target the arm keeps
        pulling towards it until within :data:`SERVO_SETTLED_RAD`.
        """
        if not self.servo:
            return
        stream, self.servo, self._servo_s = self.servo, [], 0.0
        q = self.timeline.end[:-1].copy()
        previous = q.copy()
        limit = np.asarray(self.robot.velocity_limits, float)
        out_q, out_step = [q.copy()], [stream[0][3]]
        for target, t, tau, step in stream:
            cycles = max(1, int(round(t / CONTROL_PERIOD_S)))
            ff = (target - previous) / (cycles * CONTROL_PERIOD_S)
            for c in range(cycles):
                setpoint = previous + (target - previous) * (c / cycles)  # the controller interpolates over t
                q = q + np.clip(ff + (setpoint - q) / tau, -limit, limit) * CONTROL_PERIOD_S
                out_q.append(q)
                out_step.append(step)
            previous = target
        target, _, tau, step = stream[-1]
        for _ in range(int(2.0 / CONTROL_PERIOD_S)):
            if float(np.max(np.abs(target - q))) <= SERVO_SETTLED_RAD:
                break
            q = q + np.clip((target - q) / tau, -limit, limit) * CONTROL_PERIOD_S
            out_q.append(q)
            out_step.append(step)
        out_q[-1] = target.copy()  # within SERVO_SETTLED_RAD of it: the arm is there
        times = np.arange(len(out_q)) * CONTROL_PERIOD_S
        values = np.column_stack([np.array(out_q), np.zeros(len(out_q))])
        side, self.servo_side = self.servo_side, []
        start = self.timeline.end_time
        self.timeline.add(Segment(times, values, np.array(out_step, dtype=np.int64)), self.line)
        for cycle, segment in side:
            self.timeline.add(segment, self.line, delay_s=start + cycle * CONTROL_PERIOD_S - self.timeline.end_time)

    def stop(self, a: float = 1.0, *_: Any) -> None:
        self.flush_servo()  # every other move here ends at rest, so there is nothing to decelerate

    def hold(self, duration: float, skill: str) -> None:
        times = self.local_times(duration) if duration > 0 else np.array([0.0])
        self.add(times, np.repeat(self.q[None, :], len(times), axis=0), np.full(len(times), self.opening), skill, moves=False)

    def sleep(self, t) -> None:
        self.hold(_non_negative(t, "t"), "sleep")

    def sync(self) -> None:
        if self.servo:  # inside a servo loop sync() is the cycle the stream already counts
            return
        self.hold(CONTROL_PERIOD_S, "sync")

    # ------------------------------------------------------------------ gripper
    def grip(self, opening: float, skill: str) -> None:
        """The fingers to ``opening`` (m) at the gripper's speed; the program waits for a ``*_and_wait`` call,
        for ``rq_open``/``rq_close`` (PolyScope's gripper node waits) and for a digital output, and runs on
        beside a plain ``rq_move``/``rq_move_mm`` (which return at once)."""
        opening = min(max(opening, 0.0), self.max_opening)
        change = abs(opening - self.opening)
        if change < 1e-9:
            return
        duration = max(CONTROL_PERIOD_S, GRIPPER_STROKE_S * change / self.max_opening)
        times = self.local_times(duration)
        q = np.repeat(self.q[None, :], len(times), axis=0)
        waits = not skill.startswith(("rq_move", "rq_move_mm")) or "wait" in skill
        self.add(times, q, self.opening + (opening - self.opening) * times / duration, skill, moves=False, parallel=not waits)

    def _gripper_call(self, name: str, position: float) -> Callable[..., None]:
        return lambda *_, **__: self.grip(self.max_opening * (1.0 - position / 255.0), name)

    def _gripper_move(self, name: str) -> Callable[..., None]:
        def move(pos, *_, **__):
            value = _number(pos, "position")
            if name in _GRIPPER_MM_CALLS:
                opening = value / 1000.0
            elif name.endswith("_norm"):
                opening = self.max_opening * (1.0 - value / 100.0)
            else:
                opening = self.max_opening * (1.0 - value / 255.0)
            self.grip(opening, name)

        return move

    def _digital_out(self, name: str) -> Callable[..., None]:
        def set_out(n, b, *_):
            if int(_number(n, "output")) == self.options.gripper_io:
                self.grip(0.0 if b else self.max_opening, f"{name}({self.options.gripper_io})")

        return set_out

    # ------------------------------------------------------------------ settings and queries
    def set_tcp(self, pose) -> None:
        if not isinstance(pose, P.Pose):
            raise BuiltinError(f"set_tcp takes a pose, got {pose!r}"[:120])
        if not all(math.isfinite(v) for v in pose) or math.dist(pose[:3], (0, 0, 0)) > 2.0:
            raise BuiltinError(f"set_tcp: the TCP must lie within 2 m of the flange, got {pose!r}"[:160])
        self.tcp = P.pose_matrix(pose)

    def set_payload(self, m, cog=None, inertia=None) -> None:
        self.payload_kg = _non_negative(m, "mass")

    def joints(self) -> list[float]:
        return [float(v) for v in self.q]

    def tcp_pose(self) -> P.Pose:
        return P.matrix_pose(self.pose_of(self.q))

    def tcp_offset(self) -> P.Pose:
        return P.matrix_pose(self.tcp)

    def zeros(self) -> list[float]:
        return [0.0] * 6

    def forward_kin(self, q=None, tcp=None) -> P.Pose:
        joints = self.q if q is None else self.joint_target(q, "get_forward_kin's q")
        return P.matrix_pose(self.pose_of(joints, None if tcp is None else P.pose_matrix(tcp)))

    def inverse_kin(self, x, qnear=None, maxPositionError=1e-10, maxOrientationError=1e-10, tcp=None) -> list[float]:
        seed = self.q if qnear is None else self.joint_target(qnear, "qnear")
        target = self.pose_target(x, "get_inverse_kin's x")
        return [float(v) for v in self.ik(target, seed, None if tcp is None else P.pose_matrix(tcp))]

    def has_inverse_kin(self, pose, qnear=None, *_) -> bool:
        try:
            self.inverse_kin(pose, qnear)
        except PlanningError:
            return False
        return True


def _short(values: list) -> str:
    return "[" + ", ".join(f"{v:.4g}" for v in values) + "]"


def _number(x: Any, what: str) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
        raise BuiltinError(f"{what} must be a finite number, got {x!r}"[:120])
    return float(x)


def _positive(x: Any, what: str) -> float:
    value = _number(x, what)
    if value <= 0:
        raise BuiltinError(f"{what} must be positive, got {value}")
    return value


def _non_negative(x: Any, what: str) -> float:
    value = _number(x, what)
    if value < 0:
        raise BuiltinError(f"{what} must not be negative, got {value}")
    return value
