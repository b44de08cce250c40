"""Recorded and planned trajectories from other tools, read into one shape: :class:`Recording`.

* a **ur_rtde CSV recording** (``RTDEReceiveInterface.startFileRecording``): ``timestamp`` (s, controller
  clock) and ``actual_q_0`` … ``actual_q_5`` (rad), among its other columns;
* a **generic CSV**: a ``time`` column (s; also ``t``, ``time_s`` or ``timestamp``) and one column per joint,
  named in the header as the robot names its joints (``shoulder_pan_joint`` …); optional
  ``gripper_opening_m``;
* ``trajectory_msgs/JointTrajectory`` as **JSON** (``joint_names``, ``points[].positions``,
  ``points[].velocities`` optional, ``time_from_start`` ``{sec, nanosec}``);
* a MoveIt ``moveit_msgs/RobotTrajectory`` as **YAML** (its ``joint_trajectory``; also a
  ``DisplayTrajectory``'s first ``trajectory``, and ROS 1's ``secs``/``nsecs``).

A joint named ``gripper_opening_m`` (a column, or a joint of a message) is the finger gap in metres.
Every reader is bounded (rows, columns) and raises :class:`~robocritics.errors.TrajectoryError` naming the
file's row, field or column.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass

import numpy as np

from ..errors import TrajectoryError

__all__ = ["Recording", "read_csv", "read_joint_trajectory_json", "read_moveit_yaml", "joint_trajectory", "MAX_ROWS"]

MAX_ROWS = 2_000_000
GRIPPER_NAME = "gripper_opening_m"
_TIME_COLUMNS = ("time", "t", "time_s", "timestamp")


@dataclass
class Recording:
    """Joint samples from a file: ``names`` of the ``positions (T, k)`` columns (rad; empty: the robot's joints in
    order, as a ur_rtde recording has them), ``time (T,)`` s,
    optional ``velocities (T, k)`` rad/s (waypoints of a planned trajectory) and ``gripper (T,)`` m."""

    names: list[str]
    time: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None = None
    gripper: np.ndarray | None = None
    waypoints: bool = False  # planned waypoints (interpolated) rather than dense samples
    live: bool = False  # recorded from an arm (ur_rtde, JointState): its still lead-in and tail are not motion


def read_csv(text: str, what: str = "CSV") -> Recording:
    """A ur_rtde recording or a generic CSV (see the module docstring)."""
    reader = csv.reader(io.StringIO(text))
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        raise TrajectoryError(f"{what} is empty") from None
    rtde = [f"actual_q_{i}" for i in range(6)]
    if all(c in header for c in rtde) and "timestamp" in header:
        time_col, names, columns = "timestamp", [f"actual_q_{i}" for i in range(6)], rtde
    else:
        time_col = next((c for c in _TIME_COLUMNS if c in header), None)
        if time_col is None:
            raise TrajectoryError(
                f"{what}: no time column (one of {', '.join(_TIME_COLUMNS)}) in the header {', '.join(header)[:200]}"
            )
        columns = [c for c in header if c not in _TIME_COLUMNS and c != GRIPPER_NAME and c]
        names = columns
    index = {c: i for i, c in enumerate(header)}
    rows: list[list[float]] = []
    wanted = [index[time_col]] + [index[c] for c in columns] + ([index[GRIPPER_NAME]] if GRIPPER_NAME in index else [])
    for n, row in enumerate(reader, start=2):
        if not row or all(not cell.strip() for cell in row):
            continue
        if len(rows) >= MAX_ROWS:
            raise TrajectoryError(f"{what}: more than {MAX_ROWS:,} rows")
        try:
            rows.append([float(row[i]) for i in wanted])
        except IndexError:
            raise TrajectoryError(f"{what} row {n}: {len(row)} cells, the header has {len(header)}") from None
        except ValueError:
            bad = next(header[i] for i in wanted if not _is_float(row[i]))
            raise TrajectoryError(f"{what} row {n}, column {bad!r}: not a number") from None
    if not rows:
        raise TrajectoryError(f"{what} has a header but no rows")
    data = np.array(rows)
    if not np.all(np.isfinite(data)):
        r, c = np.argwhere(~np.isfinite(data))[0]
        raise TrajectoryError(f"{what} row {r + 2}, column {header[wanted[c]]!r}: not finite")
    gripper = data[:, -1] if GRIPPER_NAME in index else None
    if names == rtde:
        names = []  # positional: the UR's six joints in order
    return Recording(names, data[:, 0], data[:, 1 : 1 + len(columns)], gripper=gripper, live=not names)


def _is_float(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _seconds(stamp, where: str) -> float:
    if isinstance(stamp, (int, float)) and not isinstance(stamp, bool):
        return float(stamp)
    if isinstance(stamp, dict):
        sec = stamp.get("sec", stamp.get("secs", 0))
        nsec = stamp.get("nanosec", stamp.get("nsecs", 0))
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (sec, nsec)):
            return float(sec) + float(nsec) * 1e-9
    raise TrajectoryError(f"{where}: time_from_start must be {{sec, nanosec}} or seconds, got {str(stamp)[:80]}")


def joint_trajectory(message: dict, what: str) -> Recording:
    """A ``trajectory_msgs/JointTrajectory`` given as a dict (from JSON, YAML or a decoded message)."""
    if not isinstance(message, dict):
        raise TrajectoryError(f"{what}: a JointTrajectory is an object with joint_names and points")
    names = message.get("joint_names")
    points = message.get("points")
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names) or not names:
        raise TrajectoryError(f"{what}: joint_names must be a non-empty list of names")
    if not isinstance(points, list) or not points:
        raise TrajectoryError(f"{what}: points must be a non-empty list")
    if len(points) > MAX_ROWS:
        raise TrajectoryError(f"{what}: more than {MAX_ROWS:,} points")
    k = len(names)
    time = np.empty(len(points))
    positions = np.empty((len(points), k))
    velocities: np.ndarray | None = np.empty((len(points), k))
    for i, point in enumerate(points):
        where = f"{what} points[{i}]"
        if not isinstance(point, dict):
            raise TrajectoryError(f"{where}: a point is an object with positions and time_from_start")
        pos = point.get("positions")
        if not isinstance(pos, list) or len(pos) != k:
            raise TrajectoryError(f"{where}.positions: {k} numbers expected (one per joint name)")
        positions[i] = _numbers(pos, f"{where}.positions")
        vel = point.get("velocities") or []
        if velocities is not None and len(vel) == k:
            velocities[i] = _numbers(vel, f"{where}.velocities")
        else:
            velocities = None
        time[i] = _seconds(point.get("time_from_start", 0), f"{where}.time_from_start")
    gripper = None
    if GRIPPER_NAME in names:
        g = names.index(GRIPPER_NAME)
        gripper = positions[:, g].copy()
    return Recording(list(names), time, positions, velocities, gripper, waypoints=True)


def _numbers(values: list, where: str) -> list[float]:
    out = []
    for v in values:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise TrajectoryError(f"{where}: {str(v)[:40]} is not a finite number")
        out.append(float(v))
    return out


def read_joint_trajectory_json(text: str, what: str = "JointTrajectory JSON") -> Recording:
    try:
        data = json.loads(text)
    except (json.JSONDecodeError, RecursionError, ValueError) as exc:
        raise TrajectoryError(f"{what}: not valid JSON: {str(exc)[:200]}") from None
    if isinstance(data, dict) and "joint_trajectory" in data:
        data = data["joint_trajectory"]
    return joint_trajectory(data, what)


def read_moveit_yaml(text: str, what: str = "MoveIt YAML") -> Recording:
    try:
        import yaml
    except ImportError:  # pragma: no cover - an optional extra
        raise TrajectoryError("reading MoveIt YAML needs PyYAML: pip install 'robocritics[formats]'") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise TrajectoryError(f"{what}: not valid YAML: {str(exc)[:200]}") from None
    if isinstance(data, dict) and isinstance(data.get("trajectory"), list) and data["trajectory"]:
        data = data["trajectory"][0]  # a DisplayTrajectory
    if isinstance(data, dict) and "joint_trajectory" in data:
        data = data["joint_trajectory"]
    return joint_trajectory(data, what)
