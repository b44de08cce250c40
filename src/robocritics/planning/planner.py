"""The motion planner: a :class:`~robocritics.program.plan.Plan` (skill calls with
source lines) to timed joint samples, with grasp and release bookkeeping.

Each call becomes motion:

* joint-space moves (``move_to``, ``move_above``, ``rotate_gripper``, ``home``)
  solve IK at the target (fingers down, current yaw, nearest the current joints)
  and are timed by ruckig; with obstacles declared by ``avoid_collision`` the
  move first rises to a safe height over them, crosses, then descends;
* Cartesian moves (``move_linear``, ``move_up``, ``move_down``) follow the
  straight line exactly (IK at every sample);
* the gripper takes 0.5 s to open or close; ``close_gripper`` grasps the
  graspable object whose centre lies between the fingers (it then moves with
  the TCP), ``open_gripper`` releases it and it settles on what is below it
  (a container floor, another object, or the table);
* ``reduce_speed``/``set_speed`` scale every later move's limits as a time
  stretch (see :mod:`robocritics.planning.timing`); the slowest speed is
  :data:`~robocritics.planning.timing.MIN_SPEED_FRACTION` (1 %).

The motion budget
-----------------
A legal program can still ask for impossible motion (``wait(10)`` a hundred
thousand times, everything at 1 % speed). Every piece of motion is timed first and
checked against the budget of :class:`PlannerSettings` *before* a sample is
made. The budget bounds the work and memory of a check, not how long the program
runs: the sample count (``max_samples``, 1,000,000: 33 min at 500 Hz, 2.2 h at
125 Hz), the estimated peak memory of simulating and judging them
(``max_trajectory_bytes``, 1 GB, see :func:`trajectory_bytes`: a long motion is
stored compactly and judged chunk by chunk, so it costs some 0.4 kB a sample) and
the planning work (``max_ik_solves``, counted before a straight line's grid is
solved). ``max_motion_s`` (24 h by default, so it never binds first at the allowed
sample rates) bounds the duration for callers who want that. A limit that is hit
raises :class:`MotionBudgetError` naming the program line, e.g. ``line 2:
wait(seconds=10): the trajectory needs more than 1,000,000 samples ...``. Past
``max_motion_s`` the rest of the program is only timed (no samples, at most
``_TIMING_WORK`` IK solves and profiles), so the message says how long the whole
motion would last ("at least ..." when timing stopped early).

Every sample records the index of the step that produced it, and each step its
source line and its *intended contacts*: the object being grasped or released
and the surface a carried object is set down on, which the collision critic
does not count as collisions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from ..errors import PlanningError
from ..program.plan import Plan, SkillCall
from ..scene import MAX_COORD_M, Container, Scene, rpy_matrix
from ..trajectory import CHUNK_SAMPLES, Step
from ..robot.approach import approach_rotation
from ..robot.model import Robot
from .spline import cubic_spline
from .world import World
from .timing import (
    JOINT_SPEED_MARGIN,
    MIN_SPEED_FRACTION,
    Limits,
    Segment,
    check_sample_rate,
    check_speed_fraction,
    profile_joint_move,
    profile_path_1d,
    sample_count,
    sample_times,
)

__all__ = [
    "Planner",
    "PlannerSettings",
    "MotionBudgetError",
    "Event",
    "plan_approach",
    "checked_start_q",
    "trajectory_bytes_per_sample",
    "trajectory_bytes",
]

# Numerical tolerances (the physical choices are in PlannerSettings; joint limits use
# robot.model.LIMIT_TOLERANCE_RAD):
#: Samples closer than this [s] are one instant: time must strictly increase, so a closing
#: sample this near the previous one replaces it instead of following it.
MIN_SAMPLE_GAP_S = 1e-6
#: A straight line shorter than this [m] is no move.
SAME_POINT_M = 1e-9
#: |dq/ds| floor [rad/m] on a Cartesian line: a joint that does not move imposes no speed cap.
_STILL_JOINT_RAD_PER_M = 1e-12
#: Longest straight line [m] worth solving IK along: the diagonal of the scene's coordinate bound. A longer one
#: cannot be reached by any arm a scene holds, and its dense-IK grid would be millions of points.
MAX_LINE_M = 2 * math.sqrt(3) * MAX_COORD_M

# Peak memory of building a trajectory, per sample [bytes] (see trajectory_bytes_per_sample). Measured with
# tracemalloc on the UR3e in the built-in scenes and in scenes of 0-80 objects, 0-80 containers, carrying or
# not (4.3 to 23 kB per sample), fitted as fixed + per kernel pair + per reported pair and rounded up, so the
# estimate stays 15-40 % above every measurement (tests/test_motion_budget.py checks it).
_BYTES_PER_SAMPLE_FIXED = 2_560  # q, time, opening, step, attached, planner bookkeeping
_BYTES_PER_FRAME = 16 * 8  # a 4x4 float64 link pose
_BYTES_PER_KERNEL_PAIR = 14  # the distance of one (capsule or carried object, shape) pair, with its temporaries (measured with every pair exact: tests/test_motion_budget.py)
_BYTES_PER_REPORTED_PAIR = 8  # one proximity column (a minimum over an entity's shapes)
_BYTES_PER_CARRIED_POSE = 2 * 16 * 8  # a carried object's 4x4 pose, and its temporary


#: Memory [bytes] a sample costs beyond a chunk (see trajectory_bytes): the planner's parts and their
#: concatenation (q, time, opening: 2 x 8 (n + 2)), the stored attached ids and steps, and what the critics keep per
#: sample (their per-sample series, the hull's points) — measured by benchmarks/bench_long.py, rounded up.
_BYTES_PER_COMPACT_SAMPLE = 400


def trajectory_bytes(robot: Robot, scene: Scene, samples: int, carried: int = 0) -> int:
    """Upper estimate of the peak memory [bytes] of simulating and judging ``samples`` samples: the whole build
    (:func:`trajectory_bytes_per_sample` each) up to :data:`~robocritics.trajectory.CHUNK_SAMPLES` samples; beyond,
    one chunk's build and :data:`_BYTES_PER_COMPACT_SAMPLE` per sample (the compact trajectory)."""
    return _estimate(trajectory_bytes_per_sample(robot, scene, carried), samples)


def _estimate(per_sample: int, samples: int) -> int:
    if samples <= CHUNK_SAMPLES:
        return samples * per_sample
    return CHUNK_SAMPLES * per_sample + samples * _BYTES_PER_COMPACT_SAMPLE


def trajectory_bytes_per_sample(robot: Robot, scene: Scene, carried: int = 0) -> int:
    """Upper estimate of the peak memory [bytes] one sample costs while :func:`robocritics.simulate` builds the
    trajectory: link frames (FK), the proximity kernel's distances of every self pair and (robot capsule, scene
    shape) pair, those of ``carried`` objects the gripper carries against every shape, the proximity columns
    (one per pair of entities) and the carried objects' poses.
    """
    return _bytes_per_sample(robot, len(scene.shapes()), len(scene.objects) + len(scene.containers) + 1, carried)


def _bytes_per_sample(robot: Robot, shapes: int, entities: int, carried: int) -> int:
    """:func:`trajectory_bytes_per_sample` for a scene of ``shapes`` shapes and ``entities`` entities (with the table)."""
    movers = len(robot.capsule_names) + carried
    return (
        _BYTES_PER_SAMPLE_FIXED
        + _BYTES_PER_FRAME * len(robot.frame_names)
        + _BYTES_PER_KERNEL_PAIR * (len(robot.self_pairs) + movers * shapes)
        + _BYTES_PER_REPORTED_PAIR * (len(robot.self_pairs) + movers * entities)
        + _BYTES_PER_CARRIED_POSE * carried
    )


class MotionBudgetError(PlanningError):
    """A program's motion exceeds the motion budget of :class:`PlannerSettings`.

    ``limit`` names the PlannerSettings field that was exceeded (``"max_motion_s"``,
    ``"max_samples"``, ``"max_trajectory_bytes"`` or ``"max_ik_solves"``); ``line`` is
    the program line of the call that passed it.
    """

    def __init__(self, message: str, line: int = 0, limit: str = ""):
        super().__init__(message, line)
        self.limit = limit

    def __reduce__(self) -> tuple:
        return (type(self), (self.reason, self.line, self.limit))


def format_duration(seconds: float) -> str:
    """A duration for people: ``42.5 s``, ``12.5 min``, ``5.6 h``."""
    if not math.isfinite(seconds):
        return f"{seconds} s"
    if seconds >= 7200:
        return f"{seconds / 3600:.1f} h"
    if seconds >= 120:
        return f"{seconds / 60:.3g} min"
    return f"{seconds:.3g} s"


def checked_start_q(robot: Robot, start_q) -> np.ndarray:
    """``start_q`` as a float array of the robot's joint count, finite and inside its limits [rad].

    Raises :class:`PlanningError` naming the joint that is wrong (:meth:`Robot.joint_vector`).
    """
    return robot.joint_vector(start_q, "start_q", PlanningError)


def plan_approach(
    robot: Robot,
    start_q,
    goal_q,
    *,
    speed_fraction: float = 0.1,
    sample_rate_hz: float = 125.0,
    settings: "PlannerSettings | None" = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A slow, jerk-limited joint move from ``start_q`` to ``goal_q`` (rest to rest).

    Returns ``(q (T, n) rad, time (T,) s)`` starting at 0 and ending exactly at
    ``goal_q``; the caller builds the trajectory (``robot.trajectory(...)``) and
    critiques it like any other motion. ``speed_fraction`` scales the robot's
    limits as in ``set_speed`` (velocity by f, acceleration by f², jerk by f³), in
    [MIN_SPEED_FRACTION, 1]; ``sample_rate_hz`` lies in the range of
    :func:`~robocritics.planning.timing.check_sample_rate`. The move must fit the
    motion budget of ``settings`` (default :class:`PlannerSettings`), checked before
    it is sampled (:class:`MotionBudgetError`).
    """
    speed_fraction = check_speed_fraction(speed_fraction, "speed_fraction")
    sample_rate_hz = check_sample_rate(sample_rate_hz)
    settings = settings or PlannerSettings()
    start, goal = checked_start_q(robot, start_q), checked_start_q(robot, goal_q)
    limits = Limits(robot.velocity_limits, robot.acceleration_limits, robot.jerk_limits)
    profile = profile_joint_move(start, goal, limits, speed_fraction)
    if not profile.duration_s <= settings.max_motion_s:
        raise MotionBudgetError(
            f"the approach lasts {format_duration(profile.duration_s)} at {speed_fraction * 100:g} % of full speed; "
            f"the limit is {format_duration(settings.max_motion_s)} (PlannerSettings.max_motion_s)",
            limit="max_motion_s",
        )
    samples = profile.samples_needed(sample_rate_hz) + 1
    if samples > settings.max_samples:
        raise MotionBudgetError(
            f"the approach needs {samples:,} samples at {sample_rate_hz:g} Hz; the limit is {settings.max_samples:,} "
            "(PlannerSettings.max_samples)",
            limit="max_samples",
        )
    seg = profile.sample(sample_rate_hz)
    # ruckig samples up to, not always at, the end: close the move on the goal itself
    # (no motion at all: the goal one sample period after the start)
    if seg.duration_s > 0 and seg.duration_s - float(seg.time[-1]) < MIN_SAMPLE_GAP_S:
        q, t = np.vstack([seg.q[:-1], goal]), np.append(seg.time[:-1], seg.duration_s)
    else:
        gap = 1.0 / sample_rate_hz if seg.duration_s == 0 else MIN_SAMPLE_GAP_S
        end_t = max(seg.duration_s, float(seg.time[-1]) + gap)
        q, t = np.vstack([seg.q, goal]), np.append(seg.time, end_t)
    return q, t


@dataclass(frozen=True)
class PlannerSettings:
    """Planner constants (SI units), each with the reason for its default.

    The motion budget (``max_*``) limits the work of one check, not the length of the program: ``max_samples``
    samples (33 min of motion at 500 Hz, 2.2 h at 125 Hz; simulating and judging costs some 10 us of CPU a
    sample), ``max_ik_solves`` IK solutions and ``max_trajectory_bytes`` of estimated peak memory. A motion of
    more than :data:`~robocritics.trajectory.CHUNK_SAMPLES` samples is stored compactly and simulated and judged
    chunk by chunk, so its memory grows by some 0.2-0.4 kB a sample (:func:`trajectory_bytes`), not 7 kB: a 30-minute
    program at 500 Hz takes well under 1.5 GB (``benchmarks/bench_long.py``). ``max_motion_s`` bounds the
    duration for callers who want that (24 h by default: at the allowed rates, >= 25 Hz, ``max_samples`` binds first).
    """

    linear_speed_mps: float = 1.0  # TCP speed of straight-line moves at speed fraction 1: the UR3e's typical TCP speed
    linear_accel_mps2: float = 4.0  # their TCP acceleration: full speed within 0.25 s
    linear_jerk_mps3: float = 40.0  # their jerk: 10x the acceleration (a 0.1 s ramp, as the joints' jerk limits)
    gripper_time_s: float = 0.5  # Robotiq 2F-85 full stroke at its default speed
    obstacle_clearance_m: float = 0.08  # how high above an avoided object's top the TCP crosses
    obstacle_margin_m: float = 0.08  # a path within this of an avoided object's footprint (m, in xy) crosses above it
    line_step_m: float = 0.005  # dense-IK spacing on straight lines (spline in between)
    line_max_joint_step_rad: float = 0.5  # a joint turning more between two line grid points is a singularity or branch flip
    grasp_region_m: float = 0.03  # how far an object's centre may sit from the finger axis to be grasped
    grasp_depth_m: float = 0.05  # how far behind the fingertips (into the hand) an object's centre may sit to be grasped
    grasp_tip_gap_m: float = 0.01  # how far short of an object's near face the fingertips may stop and still grasp it
    stack_footprint_fraction: float = 0.9  # a released object rests on another if its centre is within this share of the larger radius
    stack_gap_m: float = 0.02  # ...and the other's top is at most this above the released object's bottom
    # the motion budget (checked before any sample is made; see the module docstring). It bounds the work of a
    # check (the samples made, simulated and judged; the IK solved) and its memory, not how long the motion lasts
    max_motion_s: float = 86_400.0  # 24 h: never binds before max_samples at the allowed rates (>= 25 Hz)
    max_samples: int = 1_000_000  # samples simulated and judged: 33 min at 500 Hz, 2.2 h at 125 Hz (~10 us each)
    max_trajectory_bytes: int = 1_000_000_000  # estimated peak memory of simulating and judging (1 GB; see above)
    max_ik_solves: int = 100_000  # IK solutions planning may use (~12 us each): 500 m of straight lines

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
                raise ValueError(f"PlannerSettings.{f.name} must be a positive finite number, got {value!r}")


#: Pieces of motion timed (not sampled) after the motion budget is passed, to say how long the program would
#: last: each is an IK solve or a ruckig profile (~0.05 ms), so the estimate takes a fraction of a second.
_TIMING_WORK = 2_000


class _StopTiming(Exception):
    """The over-budget timing of the rest of a program used up _TIMING_WORK."""


#: Skills whose duration does not depend on the arm's pose or speed.
_FIXED_TIME_SKILLS = frozenset({"wait", "open_gripper", "close_gripper", "set_speed", "reduce_speed", "avoid_collision"})


@dataclass(frozen=True)
class Event:
    """Something that happened during the program: grasp, release, speed change, note."""

    kind: str
    time_s: float
    step: int
    line: int
    detail: str

class Planner:
    """Turns a plan's skill calls into timed joint samples; one instance per program run."""

    def __init__(
        self,
        scene: Scene,
        robot: Robot,
        sample_rate_hz: float,
        settings: PlannerSettings,
        start_q: np.ndarray | None = None,
    ):
        self.scene = scene
        self.robot = robot
        self.rate = check_sample_rate(sample_rate_hz)
        self.settings = settings
        self.limits = Limits(robot.velocity_limits, robot.acceleration_limits, robot.jerk_limits)
        self.q = robot.home_q.copy() if start_q is None else checked_start_q(robot, start_q)
        home_tcp = robot.tcp_pose(robot.home_q)[:3, 3]
        self.home_heading = math.atan2(home_tcp[1], home_tcp[0])
        self.yaw = 0.0
        self.tilt = robot.approach_tilts_rad[0]  # the fingers' tilt from straight down (robot.approach), rad
        self.speed = 1.0
        self.opening = robot.max_opening_m
        self.world = World(scene, robot, settings)  # the objects: held, resting, fallen
        self.obstacles: list[str] = []
        # accumulated samples
        self.q_parts: list[np.ndarray] = []
        self.t_parts: list[np.ndarray] = []
        self.open_parts: list[np.ndarray] = []
        # the attached object and the step are constant over a segment: one entry per segment, expanded by
        # finish() with one np.repeat each instead of an array per segment
        self.seg_lengths: list[int] = []
        self.seg_attached: list[str] = []
        self.seg_steps: list[int] = []
        self.t0 = 0.0
        self.steps: list[Step] = []
        self.events: list[Event] = []
        self.sample_count = 0
        # the call being planned (its line goes into budget errors)
        self.call: SkillCall | None = None
        # once the motion passes max_motion_s: (the call that passed it, the motion before it [s], the speed
        # fraction then); the rest of the program is then only timed, not sampled, to say how long it would last
        self.passed: tuple[SkillCall, float, float] | None = None
        self.timing_work = 0
        self.ik_solves = 0
        self.bytes_per_sample: dict[int, int] = {}  # by the number of objects carried so far
        self.scene_counts: tuple[int, int] | None = None  # (shapes, entities with the table), counted once
        self._tcp_cache: tuple[np.ndarray, np.ndarray] | None = None  # (self.q, its TCP pose)

    # --- the motion budget --------------------------------------------------------------

    def admit(self, duration_s: float, samples: int) -> bool:
        """Check the motion budget for ``samples`` more samples spanning ``duration_s`` more seconds.

        Called before those samples are made. Returns whether to make them: ``False`` once the motion is
        longer than ``max_motion_s`` (the rest of the program is then only timed, and :meth:`run` raises
        :class:`MotionBudgetError` at the end). The sample and memory limits raise at once, naming the
        call's line.
        """
        s, call = self.settings, self.call
        where = f"{call.describe()}: " if call else ""
        line = call.line if call else 0
        total_s = self.t0 + duration_s
        if not math.isfinite(total_s):
            raise MotionBudgetError(f"{where}the motion would last {duration_s} s, not a finite time", line, "max_motion_s")
        if self.passed is None and total_s > s.max_motion_s and call is not None:
            self.passed = (call, self.t0, self.speed)
        if self.passed is not None:
            self.count_timing_work()
            return False
        total_n = self.sample_count + samples + 1  # and the closing sample
        if total_n > s.max_samples:
            raise MotionBudgetError(
                f"{where}the trajectory needs more than {s.max_samples:,} samples ({total_n:,} by the end of this call, "
                f"{format_duration(total_s)} of motion at {self.rate:g} Hz); the limit is {s.max_samples:,} "
                "(PlannerSettings.max_samples). Shorten the motion or sample it more sparsely.",
                line,
                "max_samples",
            )
        carried = len({c[0] for c in self.world.carry})
        if carried not in self.bytes_per_sample:
            if self.scene_counts is None:
                self.scene_counts = (len(self.scene.shapes()), len(self.scene.objects) + len(self.scene.containers) + 1)
            self.bytes_per_sample[carried] = _bytes_per_sample(self.robot, *self.scene_counts, carried)
        per_sample = self.bytes_per_sample[carried]
        estimate = _estimate(per_sample, total_n)
        if estimate > s.max_trajectory_bytes:
            raise MotionBudgetError(
                f"{where}building the trajectory would take about {estimate / 1e6:,.0f} MB "
                f"({total_n:,} samples at {per_sample / 1e3:.1f} kB each for {len(self.scene.shapes())} scene shapes"
                f"{'' if total_n <= CHUNK_SAMPLES else f', {CHUNK_SAMPLES:,} at a time'}); "
                f"the limit is {s.max_trajectory_bytes / 1e6:,.0f} MB (PlannerSettings.max_trajectory_bytes). "
                "Shorten the motion, sample it more sparsely or simplify the scene.",
                line,
                "max_trajectory_bytes",
            )
        return True

    def count_timing_work(self, units: int = 1) -> None:
        """Units of over-budget timing work (IK solves, timed pieces); stop when there was enough."""
        self.timing_work += units
        if self.timing_work > _TIMING_WORK:
            raise _StopTiming

    def skip(self, duration_s: float) -> None:
        """Time passes without samples (the motion is over budget and only timed)."""
        self.t0 += duration_s

    def _too_long(self, plan: Plan, complete: bool) -> MotionBudgetError:
        """The error for a motion that passed ``max_motion_s``; ``complete``: every call was timed to the end."""
        call, before, speed = self.passed
        limit = self.settings.max_motion_s
        waits = sum(float(c.args["seconds"]) for c in plan.calls if c.skill == "wait")
        if call.skill not in _FIXED_TIME_SKILLS and speed < 1:
            hint = (
                f"The program moves at {speed * 100:.3g} % of full speed here: raise the speed "
                "(reduce_speed(100) is full speed) or make fewer moves."
            )
        elif waits > limit / 2:
            hint = f"Its waits alone add up to {format_duration(waits)}: wait less."
        else:
            hint = "Make fewer moves or waits (a loop that repeats too often?)."
        return MotionBudgetError(
            f"{call.describe()}: the program's motion lasts {'' if complete else 'at least '}"
            f"{format_duration(self.t0)}; the limit is {format_duration(limit)} (PlannerSettings.max_motion_s), "
            f"passed at this call, {format_duration(before)} into the motion. {hint}",
            call.line,
            "max_motion_s",
        )

    # --- geometry helpers ---------------------------------------------------------------

    def tcp(self, q=None) -> np.ndarray:
        """TCP pose ``(4, 4)`` at ``q`` (default: the current joints; a fresh copy the caller may change)."""
        if q is not None:
            return self.robot.tcp_pose(q)
        # a call asks for the current pose several times (its contacts, its start, its line): FK once per
        # configuration. The planner replaces self.q, never writes into it, so the same array is the same pose.
        if self._tcp_cache is None or self._tcp_cache[0] is not self.q:
            self._tcp_cache = (self.q, self.robot.tcp_pose(self.q))
        return self._tcp_cache[1].copy()

    def entity_top(self, entity_id: str) -> tuple[np.ndarray, float]:
        if entity_id in self.world.objects:
            o = self.world.objects[entity_id]
            return np.asarray(o.centre, float), o.top
        c = self.scene.entity(entity_id)
        return np.asarray(c.position, float), c.top

    def resolve_point(self, call: SkillCall) -> np.ndarray:
        if "object" in call.args:
            oid = call.args["object"]
            if oid in self.world.objects:
                return np.asarray(self.world.objects[oid].centre, float)
            entity = self.scene.entity(oid)
            return np.asarray(entity.position if isinstance(entity, Container) else entity.centre, float)
        return np.asarray(call.args["target"], float)

    def count_ik(self, call: SkillCall, solves: int = 1) -> None:
        """Count ``solves`` IK solutions against ``max_ik_solves`` (before solving them)."""
        if self.passed is not None:  # only timing the rest of an over-budget program
            self.count_timing_work(solves)
            return
        limit = self.settings.max_ik_solves
        if self.ik_solves + solves > limit:
            raise MotionBudgetError(
                f"{call.describe()}: planning the program's moves needs more than {limit:,} inverse-kinematics "
                f"solutions by this call ({self.ik_solves + solves:,}; straight lines are solved every "
                f"{self.settings.line_step_m * 1000:g} mm); the limit is {limit:,} (PlannerSettings.max_ik_solves). "
                "Make fewer or shorter straight-line moves (move_to is solved once per move).",
                call.line,
                "max_ik_solves",
            )
        self.ik_solves += solves

    def ik(self, point: np.ndarray, call: SkillCall, yaw: float | None = None, seed=None, counted: bool = False,
           tilt: float | None = None) -> np.ndarray:
        if not counted:
            self.count_ik(call)
        yaw_rad = self.yaw if yaw is None else yaw
        try:
            return self.robot.ik(point, seed=self.q if seed is None else seed, yaw_rad=yaw_rad,
                                 tilt_rad=self.tilt if tilt is None else tilt)
        except PlanningError as exc:
            err = PlanningError(f"{call.describe()}: {exc.reason}", line=call.line)
            # what could not be reached, for repairs that look for the nearest reachable point
            err.call, err.target_m, err.yaw_rad = call, tuple(float(v) for v in point), float(yaw_rad)
            raise err from None

    def later_tilts(self) -> tuple[float, ...]:
        """The robot's approach tilts after the current one: what a move tries when its target is out of reach."""
        tilts = self.robot.approach_tilts_rad
        return tilts[tilts.index(self.tilt) + 1:] if self.tilt in tilts else ()

    def tilted(self, tilt: float, call: SkillCall) -> None:
        """Approach at ``tilt`` from now on, and say so in the events (the critics judge the real fingers)."""
        self.tilt = tilt
        self.event("approach", max(len(self.steps) - 1, 0), call,
                   f"out of reach with the fingers at the last tilt: they now approach {math.degrees(tilt):.0f} deg from straight down")

    def approach_ik(self, point: np.ndarray, call: SkillCall, seed) -> np.ndarray:
        """:meth:`ik` at the current tilt, else at the first later tilt that reaches ``point`` (which then stays)."""
        try:
            return self.ik(point, call, seed=seed)
        except PlanningError as first:
            for tilt in self.later_tilts():
                try:
                    q = self.ik(point, call, seed=seed, tilt=tilt)
                except PlanningError:
                    continue
                self.tilted(tilt, call)
                return q
            raise first

    # --- sample bookkeeping ---------------------------------------------------------------

    def emit(self, seg: Segment, step: int, opening: np.ndarray | float | None = None) -> None:
        m = len(seg.time)
        self.q_parts.append(seg.q)
        self.t_parts.append(self.t0 + seg.time)
        if opening is None:
            self.open_parts.append(np.full(m, float(self.opening)))
        else:
            self.open_parts.append(np.array(np.broadcast_to(np.asarray(opening, float), (m,))))
        self.seg_lengths.append(m)
        self.seg_attached.append(self.world.attached)
        self.seg_steps.append(step)
        self.sample_count += m
        self.t0 += seg.duration_s

    def add_step(self, call: SkillCall, contacts: set[str] = frozenset()) -> int:
        self.steps.append(
            Step(
                skill=call.skill,
                line=call.line,
                args=call.describe(),
                contacts=tuple(sorted(contacts)),
                speed_fraction=self.speed,
            )
        )
        return len(self.steps) - 1

    def event(self, kind: str, step: int, call: SkillCall, detail: str) -> None:
        self.events.append(Event(kind, self.t0, step, call.line, detail))

    # --- intended contacts ---------------------------------------------------------------

    # --- moves ----------------------------------------------------------------------------

    def joint_move(self, goal: np.ndarray, step: int) -> None:
        profile = profile_joint_move(self.q, goal, self.limits, self.speed)
        if profile.duration_s > 0:
            if self.admit(profile.duration_s, profile.samples_needed(self.rate)):
                self.emit(profile.sample(self.rate), step)
            else:
                self.skip(profile.duration_s)
        self.q = np.asarray(goal, float)

    def routed_points(self, start: np.ndarray, goal: np.ndarray) -> list[np.ndarray]:
        """Via points over obstacles that the straight xy path from ``start`` to ``goal`` passes near."""
        if not self.obstacles:
            return [goal]
        a, b = start[:2], goal[:2]
        safe_z = -math.inf
        for oid in self.obstacles:
            centre, top = self.entity_top(oid)
            ent = self.world.objects.get(oid) or self.scene.entity(oid)
            reach = (max(ent.size[:2]) / 2 if isinstance(ent, Container) else ent.width / 2) + self.settings.obstacle_margin_m
            ab = b - a
            t = 0.0 if not ab.any() else float(np.clip(np.dot(centre[:2] - a, ab) / np.dot(ab, ab), 0, 1))
            if np.linalg.norm(a + t * ab - centre[:2]) <= reach:
                carried = 2 * self.world.objects[self.world.attached].half_height if self.world.attached else 0.0
                safe_z = max(safe_z, top + self.settings.obstacle_clearance_m + carried)
        if safe_z == -math.inf or (start[2] >= safe_z and goal[2] >= safe_z):
            return [goal]
        return [np.array([a[0], a[1], max(safe_z, start[2])]), np.array([b[0], b[1], max(safe_z, goal[2])]), goal]

    def posture_seed(self, point: np.ndarray, yaw: float | None = None, natural: bool = False) -> np.ndarray:
        """The home posture turned to face ``point``: an IK seed that keeps the arm in its
        natural branch (shoulder facing the target, elbow up, wrist down).

        Nearest-to-the-current-joints alone would let the arm lean back over itself for
        a target behind it, folding the gripper onto the upper arm. The seed's base
        angle is the equivalent (``+ 2 pi k``) closest to where the base is now; when
        that lies outside the base's limits, the closest branch may still be one that
        reaches back over the shoulder. ``natural`` (the ``posture="natural"`` of a
        move) takes the closest equivalent *within* the limits instead, so the natural
        branch always wins, however far the base has to turn.
        """
        home = self.robot.home_q
        seed = home.copy()
        turn = math.atan2(point[1], point[0]) - self.home_heading
        # the equivalent base angle closest to where the base is now
        seed[0] = home[0] + turn * self.robot.base_turn_sign  # (the sign is +-1, or 0 for a base that does not turn)
        seed[0] += 2 * math.pi * round((self.q[0] - seed[0]) / (2 * math.pi))
        if natural:
            seed[0] = self.turn_within_limits(seed[0], 0)
        # with the fingers down, turning the base by `turn` turns the fingers by +turn and the last joint
        # turns them by wrist_yaw_per_rad (-1 on a UR arm) times its angle: compensate both to keep the yaw
        k = -self.robot.wrist_yaw_per_rad
        seed[-1] = home[-1] + turn * k - (self.yaw if yaw is None else yaw) * k
        seed[-1] += 2 * math.pi * round((self.q[-1] - seed[-1]) / (2 * math.pi))
        if not self.robot.lower[-1] <= seed[-1] <= self.robot.upper[-1]:
            # a wrist with less than +-2 pi (an iiwa's +-175 deg): a seed past its limit has no solution
            # near it, and numeric IK then restarts at random and lands on another branch of the whole arm
            seed[-1] = self.turn_within_limits(seed[-1], -1)
        return seed

    def turn_within_limits(self, angle_rad: float, joint: int) -> float:
        """The equivalent of ``angle_rad`` (``+ 2 pi k``) within joint ``joint``'s limits closest to where the
        joint is now, or ``angle_rad`` itself where no equivalent is within them."""
        lo, hi = float(self.robot.lower[joint]), float(self.robot.upper[joint])
        inside = [angle_rad + 2 * math.pi * k for k in (-2, -1, 0, 1, 2) if lo <= angle_rad + 2 * math.pi * k <= hi]
        return min(inside, key=lambda a: abs(a - self.q[joint])) if inside else angle_rad

    def move_joint_to_point(self, point: np.ndarray, call: SkillCall, step: int) -> None:
        start = self.tcp()[:3, 3]
        natural = call.args.get("posture") == "natural"
        for via in self.routed_points(start, point):
            self.joint_move(self.approach_ik(via, call, self.posture_seed(via, natural=natural)), step)

    def line_move(self, goal: np.ndarray, call: SkillCall, step: int) -> None:
        start = self.tcp()[:3, 3]
        length = math.hypot(*(goal - start))  # no overflow for absurd targets
        if length < SAME_POINT_M:
            return
        if not length <= MAX_LINE_M:
            raise PlanningError(
                f"{call.describe()}: a straight line of {length:.4g} m is out of reach (the longest is {MAX_LINE_M:.3g} m)",
                line=call.line,
            )
        direction = (goal - start) / length
        # dense IK to bound |dq/ds| so the timed line respects every joint speed limit
        n_grid = max(2, int(math.ceil(length / self.settings.line_step_m)) + 1)
        grid = np.linspace(0.0, length, n_grid)
        points = start + grid[:, None] * direction
        q_grid, err = self.line_grid(points, goal, call, self.q, self.tilt)
        if err is not None:
            q_grid = self.retilted_line(points, goal, call, step, err)
        joint_steps = np.abs(np.diff(q_grid, axis=0))  # (n - 1, joints) rad between grid points
        dq_ds = joint_steps.max(axis=0) / (length / (n_grid - 1))
        joint_cap = np.min(JOINT_SPEED_MARGIN * self.limits.velocity / np.maximum(dq_ds, _STILL_JOINT_RAD_PER_M))
        f = self.speed
        v = min(self.settings.linear_speed_mps, joint_cap) * f
        a = self.settings.linear_accel_mps2 * f**2
        j = self.settings.linear_jerk_mps3 * f**3
        profile = profile_path_1d(length, v, a, j)
        if not self.admit(profile.duration_s, profile.samples_needed(self.rate)):
            self.skip(profile.duration_s)
            self.q = q_grid[-1]
            return
        path = profile.sample(self.rate)
        s, times, duration = path.q[:, 0], path.time, path.duration_s
        # q(s) between the dense-IK grid points by a cubic spline: its deviation from
        # the exact line shrinks as line_step_m^4
        q = cubic_spline(grid, q_grid, s)
        self.emit(Segment(q, times, duration), step)
        self.q = q_grid[-1]

    def line_grid(self, points: np.ndarray, goal: np.ndarray, call: SkillCall, seed: np.ndarray,
                  tilt) -> tuple[np.ndarray, PlanningError | None]:
        """IK at every grid point of a straight line, each seeded by the previous one's solution (the first by
        ``seed``), at ``tilt`` (rad: one, or one per point); and the error a point-by-point walk meets first (a joint jump before the first
        point that has no solution), or None."""
        self.count_ik(call, len(points))  # before solving any of them
        q_grid, failure = self.robot.ik_line(points, seed=seed, yaw_rad=self.yaw, tilt_rad=tilt)
        joint_steps = np.abs(np.diff(q_grid, axis=0))  # (n - 1, joints) rad between grid points
        jumps = np.flatnonzero(joint_steps.max(axis=1) > self.settings.line_max_joint_step_rad)
        if len(jumps):
            x, y, z = points[jumps[0] + 1]
            return q_grid, PlanningError(
                f"{call.describe()}: the straight line passes a singularity or a joint limit near "
                f"({x:.3f}, {y:.3f}, {z:.3f}) m; use move_to for this move",
                line=call.line,
            )
        if failure is not None:
            point = points[len(q_grid)]
            err = PlanningError(f"{call.describe()}: {failure.reason}", line=call.line)
            # what could not be reached, for repairs that look for the nearest reachable point
            err.call, err.target_m, err.yaw_rad = call, tuple(float(v) for v in point), float(self.yaw)
            err.goal_m = tuple(float(v) for v in goal)  # the line's end, beyond the point that failed
            return q_grid, err
        return q_grid, None

    def retilted_line(self, points: np.ndarray, goal: np.ndarray, call: SkillCall, step: int,
                      err: PlanningError) -> np.ndarray:
        """The line's IK grid with the tilt turning evenly along the line from the current one to the nearest
        of the robot's other tilts along which the whole line is solved (no tilt may reach both ends: a 5-joint
        arm with a long tool stands up above an object and leans less at its foot); else at the first later
        tilt along which the whole line is solved, after turning the fingers to it at the start (a joint
        move); raises ``err`` (the current tilt's) if none. Nearest first: the fingers turn the least, and
        each tilt that fails costs a failed IK search."""
        for tilt in sorted(self.robot.approach_tilts_rad, key=lambda t: abs(t - self.tilt)):
            if tilt == self.tilt:
                continue
            q_grid, failed = self.line_grid(points, goal, call, self.q, np.linspace(self.tilt, tilt, len(points)))
            if failed is None:
                self.tilted(tilt, call)
                return q_grid
        for tilt in self.later_tilts():
            try:
                start_q = self.ik(points[0], call, seed=self.q, tilt=tilt)
            except PlanningError:
                continue
            q_grid, failed = self.line_grid(points, goal, call, start_q, tilt)
            if failed is None:
                self.tilted(tilt, call)
                self.joint_move(start_q, step)
                return q_grid
        raise err

    def gripper_move(self, target_opening: float, step: int) -> None:
        if not self.admit(self.settings.gripper_time_s, sample_count(self.settings.gripper_time_s, self.rate)):
            self.skip(self.settings.gripper_time_s)
            self.opening = target_opening
            return
        times = sample_times(self.settings.gripper_time_s, self.rate)
        opening = self.opening + (target_opening - self.opening) * np.clip(times / self.settings.gripper_time_s, 0, 1)
        self.emit(Segment(np.repeat(self.q[None, :], len(times), axis=0), times, self.settings.gripper_time_s), step, opening)
        self.opening = target_opening

    def hold(self, seconds: float, step: int) -> None:
        if math.isnan(seconds):
            raise PlanningError(f"wait: seconds must be a number, got {seconds}", line=self.call.line if self.call else 0)
        if seconds <= 0:
            return
        if not self.admit(seconds, sample_count(seconds, self.rate)):
            self.skip(seconds)
            return
        times = sample_times(seconds, self.rate)
        self.emit(Segment(np.repeat(self.q[None, :], len(times), axis=0), times, seconds), step)

    # --- the skills ---------------------------------------------------------------------

    def run(self, plan: Plan) -> None:
        """Plan every call of ``plan``; :class:`MotionBudgetError` if its motion is longer than ``max_motion_s``."""
        try:
            for call in plan.calls:
                handler = getattr(self, f"do_{call.skill}", None)
                if handler is None:
                    raise PlanningError(f"the planner does not know the skill {call.skill!r}", line=call.line)
                self.call = call
                if self.world.pending_lift and call.skill not in _FIXED_TIME_SKILLS and call.skill != "expect":
                    self.drop_unsupported(self.world.pending_lift, call)
                handler(call)
        except (_StopTiming, PlanningError):  # _StopTiming only comes once the budget was passed
            if self.passed is None:
                raise
            # the motion was already over budget: that is the first problem, however much is left
            raise self._too_long(plan, complete=False) from None
        if self.passed is not None:
            raise self._too_long(plan, complete=True)

    def _move_contacts(self, goal_point: np.ndarray | None, call: SkillCall) -> set[str]:
        contacts = self.world.contacts_at(self.tcp())
        if goal_point is not None:
            goal_tcp = np.eye(4)
            goal_tcp[:3, :3] = approach_rotation(goal_point, self.yaw, self.tilt, self.robot.shoulder_m)
            goal_tcp[:3, 3] = goal_point
            contacts |= self.world.contacts_at(goal_tcp)
        return contacts

    def do_move_to(self, call: SkillCall) -> None:
        point = self.resolve_point(call)
        step = self.add_step(call, self._move_contacts(point, call))
        self.move_joint_to_point(point, call, step)

    def do_move_above(self, call: SkillCall) -> None:
        if "object" in call.args:
            centre, top = self.entity_top(call.args["object"])
            point = np.array([centre[0], centre[1], top + call.args["height"]])
        else:
            point = np.asarray(call.args["target"], float) + np.array([0, 0, call.args["height"]])
        step = self.add_step(call, self._move_contacts(point, call))
        self.move_joint_to_point(point, call, step)

    def do_move_linear(self, call: SkillCall) -> None:
        point = self.resolve_point(call)
        step = self.add_step(call, self._move_contacts(point, call))
        self.line_move(point, call, step)

    def _vertical(self, call: SkillCall, dz: float) -> None:
        point = self.tcp()[:3, 3] + np.array([0.0, 0.0, dz])
        step = self.add_step(call, self._move_contacts(point, call))
        self.line_move(point, call, step)

    def do_move_up(self, call: SkillCall) -> None:
        self._vertical(call, float(call.args["dz"]))

    def do_move_down(self, call: SkillCall) -> None:
        self._vertical(call, -float(call.args["dz"]))

    def do_rotate_gripper(self, call: SkillCall) -> None:
        step = self.add_step(call, self._move_contacts(None, call))
        angle = float(call.args["angle"])
        here = self.tcp()[:3, 3]
        self.joint_move(self.ik(here, call, yaw=angle, seed=self.posture_seed(here, angle)), step)
        self.yaw = angle

    def do_home(self, call: SkillCall) -> None:
        step = self.add_step(call, self._move_contacts(None, call))
        self.joint_move(self.robot.home_q, step)
        self.yaw = 0.0
        self.tilt = self.robot.approach_tilts_rad[0]

    def do_wait(self, call: SkillCall) -> None:
        step = self.add_step(call, self._move_contacts(None, call))
        self.hold(float(call.args["seconds"]), step)

    def do_set_speed(self, call: SkillCall) -> None:
        fraction = call.args["fraction"]
        try:
            self.speed = check_speed_fraction(fraction)
        except PlanningError as exc:
            if call.skill == "reduce_speed" and isinstance(fraction, (int, float)):
                reason = (
                    f"percent must lie in [{MIN_SPEED_FRACTION * 100:g}, 100], got {fraction * 100:g} "
                    f"(the slowest speed is {MIN_SPEED_FRACTION * 100:g} % of full speed)"
                )
            else:
                reason = exc.reason
            raise PlanningError(f"{call.describe()}: {reason}", line=call.line) from None
        step = self.add_step(call)
        self.event("speed", step, call, f"speed set to {self.speed * 100:.0f} % of full speed")

    do_reduce_speed = do_set_speed

    def do_avoid_collision(self, call: SkillCall) -> None:
        oid = call.args["object"]
        if oid not in self.obstacles:
            self.obstacles.append(oid)
        step = self.add_step(call)
        self.event("obstacle", step, call, f"{oid} is an obstacle; later moves cross above it")

    def drop_unsupported(self, lifted: str, call: SkillCall) -> None:
        """What rests on ``lifted`` falls as it is lifted (:meth:`World.drop_unsupported`), one event per object."""
        step = len(self.steps) - 1
        for oid, below, drop in self.world.drop_unsupported(lifted, self.sample_count):
            self.event("fall", step, call, f"{oid} fell onto {below} ({drop * 100:.1f} cm) as {lifted} was lifted")

    def do_expect(self, call: SkillCall) -> None:
        """A stated goal (checked by the task_outcome critic on the final scene): no motion, no step."""

    def do_close_gripper(self, call: SkillCall) -> None:
        tcp = self.tcp()
        cand = None if self.world.attached else self.world.grasp_candidate(tcp)
        step = self.add_step(call, self.world.contacts_at(tcp))
        if cand is None:
            self.gripper_move(0.0, step)
            if not self.world.attached:
                self.event("grasp_missed", step, call, "closed on nothing: no graspable object between the fingers")
            return
        obj = self.world.objects[cand]
        width = min(obj.width, self.robot.max_opening_m)
        self.gripper_move(width, step)
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = rpy_matrix(obj.rpy), obj.position
        self.world.grasp_offset = np.linalg.inv(tcp) @ pose
        self.world.attached = cand
        self.world.pending_lift = cand
        self.world.carry.append((cand, self.sample_count, -1, self.world.grasp_offset))
        self.event("grasp", step, call, f"grasped {cand}")

    def do_open_gripper(self, call: SkillCall) -> None:
        tcp = self.tcp()
        # the fingers open around the object they let go of
        step = self.add_step(call, self.world.contacts_at(tcp) | ({self.world.attached} if self.world.attached else set()))
        released = self.world.attached
        release_sample = self.sample_count
        if released:
            # the object leaves the fingers as they start to open
            oid, first, _, offset = self.world.carry[-1]
            self.world.carry[-1] = (oid, first, self.sample_count, offset)
            self.world.attached = ""
            if self.world.pending_lift == released:  # let go before lifting: what rests on it stays supported
                self.world.pending_lift = ""
        self.gripper_move(self.robot.max_opening_m, step)
        if released:
            obj = self.world.objects[released]
            pose = tcp @ self.world.grasp_offset
            support, z = self.world.support_below(released, pose[:3, 3], obj.half_height, obj.width / 2)
            drop = pose[2, 3] - obj.half_height - z
            settled = (pose[0, 3], pose[1, 3], z + obj.half_height)
            self.world.objects[released] = obj.moved_to(settled)
            self.world.resting_on[released] = support
            final_pose = np.eye(4)
            final_pose[:3, :3], final_pose[:3, 3] = rpy_matrix(obj.rpy), settled
            self.world.rest_changes.append((released, release_sample, final_pose))
            self.event("release", step, call, f"released {released} onto {support} (dropped {max(drop, 0) * 100:.1f} cm)")

    # --- assembly --------------------------------------------------------------------------

    def finish(self) -> tuple[np.ndarray, ...]:
        # every object carried is known now: the whole trajectory against the memory budget
        self.admit(0.0, 0)
        # the final configuration closes the trajectory
        self.q_parts.append(self.q[None, :])
        self.t_parts.append(np.array([self.t0]))
        self.open_parts.append(np.array([self.opening]))
        last_step = len(self.steps) - 1 if self.steps else 0
        self.seg_lengths.append(1)
        self.seg_attached.append(self.world.attached)
        self.seg_steps.append(max(last_step, 0))
        self.sample_count += 1
        q = np.concatenate(self.q_parts)
        t = np.concatenate(self.t_parts)
        return (
            q,
            t,
            np.concatenate(self.open_parts),
            np.repeat(np.array(self.seg_attached), self.seg_lengths),  # str ids: a '<U' array, no object detour
            np.repeat(np.array(self.seg_steps, dtype=int), self.seg_lengths),
        )
