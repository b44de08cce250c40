"""One function from a motion file to the :class:`~robocritics.execution.Execution` the critics read."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np

from ..errors import TrajectoryError

if TYPE_CHECKING:  # pragma: no cover
    from .files import Recording
    from ..robot.model import Robot, default_robot
    from ..scene import Scene
    from ..execution import Execution

__all__ = ["load_motion", "motion_kind", "recording_execution", "moving_span", "STILL_RAD", "MOTION_SUFFIXES", "URSCRIPT_SUFFIXES", "MAX_SAMPLES"]

URSCRIPT_SUFFIXES = (".script", ".urscript", ".urp.script")
MOTION_SUFFIXES = {
    ".script": "urscript", ".urscript": "urscript", ".csv": "csv", ".json": "jointtrajectory",
    ".yaml": "moveit", ".yml": "moveit", ".mcap": "rosbag", ".db3": "rosbag",
}  # fmt: skip
#: The most samples one imported motion may have after resampling (10 min at 125 Hz).
MAX_SAMPLES = 75_000
MAX_FILE_BYTES = 64 * 1024 * 1024


def motion_kind(path: str | Path) -> str | None:
    """``urscript``, ``csv``, ``jointtrajectory``, ``moveit`` or ``rosbag`` by the file's suffix (a rosbag2
    directory is ``rosbag``); None for anything else (a robot program)."""
    p = Path(path)
    if p.is_dir() and (p / "metadata.yaml").is_file():
        return "rosbag"
    return MOTION_SUFFIXES.get(p.suffix.lower())


def load_motion(
    path: str | Path,
    robot: "Robot | None" = None,
    scene: "Scene | None" = None,
    *,
    topic: str | None = None,
    rate_hz: float = 125.0,
    passes: int = 1,
    tcp: Sequence[float] | None = None,
    payload_kg: float = 0.0,
    start_q: Sequence[float] | None = None,
    gripper_io: int | None = None,
) -> "Execution":
    """The motion in ``path`` (URScript, ur_rtde or generic CSV, JointTrajectory JSON, MoveIt YAML, rosbag2) as
    an Execution of ``robot`` (default the UR3e) in ``scene`` (default an empty table), ``plan=None``,
    ``source`` naming the file.

    Recordings are resampled to ``rate_hz`` (Hz) and their joints matched by name (a ur_rtde recording's
    ``actual_q_0..5`` are the arm's joints in order); ``topic`` chooses a rosbag2 topic. URScript options:
    ``passes`` of an endless loop, the installation's ``tcp`` (pose, m and rad), ``payload_kg``, ``start_q``
    (rad, default the robot's home) and ``gripper_io`` (digital output that closes the gripper when high).
    Raises :class:`TrajectoryError` for a file that cannot be read (naming the row or field),
    :class:`~robocritics.formats.urscript.URScriptError`/``UnsupportedURScript`` for a script.
    """
    from ..planning.timing import check_sample_rate
    from ..robot.model import default_robot
    from ..scene import Scene

    rate_hz = check_sample_rate(rate_hz)
    robot = robot or default_robot()
    scene = robot.scene_for(scene if scene is not None else Scene())
    p = Path(path)
    kind = motion_kind(p)
    if kind is None:
        raise TrajectoryError(f"{p}: not a motion file robocritics reads (suffixes: {', '.join(MOTION_SUFFIXES)})")
    if kind == "rosbag":
        from .rosbag import read_rosbag

        return recording_execution(read_rosbag(p, topic), robot, scene, f"rosbag2 {p.name}" + (f" {topic}" if topic else ""), rate_hz)
    text = _read(p)
    if kind == "urscript":
        from .urscript import ArmOptions, run_urscript

        options = ArmOptions(
            tcp=None if tcp is None else tuple(float(v) for v in tcp),
            payload_kg=float(payload_kg),
            start_q=None if start_q is None else tuple(float(v) for v in start_q),
            gripper_io=gripper_io,
            rate_hz=rate_hz,
        )
        return run_urscript(text, robot, scene, options, passes=passes, name=p.name)
    from .files import read_csv, read_joint_trajectory_json, read_moveit_yaml  # here: a program's check needs
    # only motion_kind() of this module

    reader = {"csv": read_csv, "jointtrajectory": read_joint_trajectory_json, "moveit": read_moveit_yaml}[kind]
    label = {"csv": "CSV", "jointtrajectory": "JointTrajectory JSON", "moveit": "MoveIt trajectory"}[kind]
    recording = reader(text, f"{p.name}")
    if kind == "csv" and not recording.names:
        label = "ur_rtde recording"
    return recording_execution(recording, robot, scene, f"{label} {p.name}", rate_hz)


def _read(p: Path) -> str:
    try:
        size = p.stat().st_size
        if size > MAX_FILE_BYTES:
            raise TrajectoryError(f"{p}: {size:,} bytes; the limit is {MAX_FILE_BYTES:,}")
        return p.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise TrajectoryError(f"{p}: cannot read it: {exc.strerror or exc}") from None


def _columns(recording: Recording, robot: "Robot", what: str) -> list[int]:
    if not recording.names:
        if recording.positions.shape[1] != robot.n:
            raise TrajectoryError(f"{what}: {recording.positions.shape[1]} joints recorded, the {robot.name} has {robot.n}")
        return list(range(robot.n))
    missing = [j for j in robot.joint_names if j not in recording.names]
    if missing:
        raise TrajectoryError(
            f"{what}: no values for the {robot.name}'s joint(s) {', '.join(missing)}; it names {', '.join(recording.names)[:300]}"
        )
    return [recording.names.index(j) for j in robot.joint_names]


def _hermite(t: np.ndarray, times: np.ndarray, q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Cubic Hermite interpolation of waypoints ``q (k, n)`` with velocities ``v`` at ``times``, evaluated at ``t``."""
    i = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
    h = (times[i + 1] - times[i])[:, None]
    s = ((t - times[i])[:, None]) / h
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * q[i] + h10 * h * v[i] + h01 * q[i + 1] + h11 * h * v[i + 1]


#: A recording's lead-in and tail where no joint is farther than this from where it starts (ends) are the arm
#: waiting for the program or settling after it, rad: a servo-streamed motion's lag decays for ~0.1-0.2 s after
#: the last setpoint (lookahead 0.1 s), within 1e-3 rad of the end only the last ~40 ms of a planned stop lie.
STILL_RAD = 1e-3


def moving_span(q: np.ndarray, gripper: np.ndarray | None) -> tuple[int, int]:
    """First and last sample of the motion: the still lead-in and tail dropped (one still sample kept at each end)."""
    moved = np.abs(q - q[0]).max(axis=1) > STILL_RAD
    settled = np.abs(q - q[-1]).max(axis=1) > STILL_RAD
    if gripper is not None:
        moved |= np.abs(gripper - gripper[0]) > 1e-3
        settled |= np.abs(gripper - gripper[-1]) > 1e-3
    if not moved.any():
        return 0, len(q) - 1
    return max(0, int(np.argmax(moved)) - 1), min(len(q) - 1, len(q) - int(np.argmax(settled[::-1])))


def recording_execution(recording: Recording, robot: "Robot", scene: "Scene", source: str, rate_hz: float) -> "Execution":
    """The Execution of ``recording``: joints matched, a live recording's still lead-in and tail dropped
    (:data:`STILL_RAD`), resampled to ``rate_hz`` (linear between dense samples, cubic Hermite between waypoints
    that carry velocities), ``plan=None``."""
    from .grasps import imported_execution

    cols = _columns(recording, robot, source)
    time = np.asarray(recording.time, float)
    q = np.asarray(recording.positions, float)[:, cols]
    keep = np.concatenate([[True], np.diff(time) > 0])  # a repeated stamp is one sample recorded twice
    if np.any(np.diff(time) < 0):
        i = int(np.argmax(np.diff(time) < 0)) + 1
        raise TrajectoryError(f"{source}: time goes backwards at sample {i} ({time[i]:.6g} s after {time[i - 1]:.6g} s)")
    time, q = time[keep], q[keep]
    gripper = None if recording.gripper is None else np.asarray(recording.gripper, float)[keep]
    if recording.live:
        first, last = moving_span(q, gripper)
        time, q = time[first : last + 1], q[first : last + 1]
        gripper = None if gripper is None else gripper[first : last + 1]
    time = time - time[0]
    duration = float(time[-1])
    count = int(math.floor(duration * rate_hz + 1e-9)) + 1
    if count > MAX_SAMPLES:
        raise TrajectoryError(f"{source}: {duration:.1f} s at {rate_hz:g} Hz is {count:,} samples; the limit is {MAX_SAMPLES:,}")
    grid = np.arange(count) / rate_hz
    if duration - grid[-1] > 1e-9:
        grid = np.append(grid, duration)
    velocities = recording.velocities
    if recording.waypoints and velocities is not None and len(time) > 1:
        samples = _hermite(grid, time, q, np.asarray(velocities, float)[keep][:, cols])
    else:
        samples = np.column_stack([np.interp(grid, time, q[:, j]) for j in range(robot.n)])
    opening = None
    if gripper is not None:
        opening = np.clip(np.interp(grid, time, gripper), 0.0, robot.max_opening_m)
    return imported_execution(robot, scene, samples, grid, opening, source)
