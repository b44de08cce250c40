"""A checked trajectory for other tools: a URScript servo program a pendant runs, JointTrajectory JSON for
MoveIt/ros2_control, or CSV; each read back by :func:`robocritics.formats.load_motion` to the same motion.

The URScript program moves to the first sample with ``movej`` and then streams every sample with
``servoj(q, t=…, lookahead_time=…, gain=…)`` on a grid of whole 2 ms controller cycles (8 ms at the default
125 Hz), ending with ``stopj``; a gripper change becomes ``rq_move_mm`` (Robotiq URCap) where it starts.
"""

from __future__ import annotations

import json
import math

import numpy as np

from ..trajectory import Trajectory

__all__ = ["to_urscript", "to_joint_trajectory", "to_csv", "uniform_samples", "EXPORT_FORMATS"]

EXPORT_FORMATS = ("urscript", "jointtrajectory", "csv")
CYCLE_S = 0.002


def uniform_samples(trajectory: Trajectory, period_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(time, q, opening)`` of ``trajectory`` every ``period_s`` s (a whole number of 2 ms cycles), the last
    sample at its duration rounded to whole cycles."""
    t0 = trajectory.time - trajectory.time[0]
    cycles = max(1, int(round(period_s / CYCLE_S)))
    period = cycles * CYCLE_S
    end = round(float(t0[-1]) / CYCLE_S) * CYCLE_S
    grid = np.arange(int(math.floor(end / period + 1e-9)) + 1) * period
    if end - grid[-1] > 1e-9:
        grid = np.append(grid, end)
    sample_at = np.minimum(grid, t0[-1])
    q = np.column_stack([np.interp(sample_at, t0, trajectory.q[:, j]) for j in range(trajectory.q.shape[1])])
    opening = np.interp(sample_at, t0, trajectory.gripper_opening_m)
    return grid, q, opening


def _list(values) -> str:
    return "[" + ", ".join(f"{v:.6f}" for v in values) + "]"


def to_urscript(
    trajectory: Trajectory,
    *,
    name: str = "robocritics_motion",
    rate_hz: float = 125.0,
    lookahead_time_s: float = 0.1,
    gain: float = 300.0,
    comment: str = "",
) -> str:
    """The trajectory as a URScript program (``def name(): … end`` and the call): movej to the start, then a
    ``servoj`` per sample at ``rate_hz`` with the planned timing."""
    time, q, opening = uniform_samples(trajectory, 1.0 / rate_hz)
    out = [f"# {line}" for line in (comment.splitlines() or [])]
    out += [
        f"# {len(time)} samples, {time[-1]:.3f} s, exported by robocritics from trajectory {trajectory.content_hash()[:12]}",
        f"def {name}():",
        f"  movej({_list(q[0])}, a=1.4, v=1.05)",
    ]
    changes = np.flatnonzero(np.abs(np.diff(opening)) > 1e-6)
    gripper_starts = {int(i) for i in changes if i == 0 or abs(opening[i] - opening[i - 1]) <= 1e-6}
    for i in range(1, len(time)):
        if i - 1 in gripper_starts:
            run_end = i - 1
            while run_end + 1 < len(opening) and abs(opening[run_end + 1] - opening[run_end]) > 1e-6:
                run_end += 1
            out.append(f"  rq_move_mm({opening[run_end] * 1000.0:.1f})  # gripper opening, mm (Robotiq URCap)")
        dt = time[i] - time[i - 1]
        out.append(f"  servoj({_list(q[i])}, t={dt:.3f}, lookahead_time={lookahead_time_s:g}, gain={gain:g})")
    out += ["  stopj(2.0)", "end", f"{name}()", ""]
    return "\n".join(out)


def to_joint_trajectory(trajectory: Trajectory, *, rate_hz: float = 125.0) -> str:
    """``trajectory_msgs/JointTrajectory`` JSON: every sample at ``rate_hz`` with positions, velocities (central
    differences, rad/s) and ``time_from_start`` ``{sec, nanosec}``."""
    time, q, _ = uniform_samples(trajectory, 1.0 / rate_hz)
    qd = np.gradient(q, time, axis=0) if len(time) > 1 else np.zeros_like(q)
    qd[0] = qd[-1] = 0.0  # it starts and ends at rest
    points = []
    for t, pos, vel in zip(time.tolist(), q.tolist(), qd.tolist()):
        ns = int(round(t * 1e9))
        points.append({"positions": pos, "velocities": vel, "time_from_start": {"sec": ns // 10**9, "nanosec": ns % 10**9}})
    return json.dumps({"joint_names": list(trajectory.limits.joint_names), "points": points}, indent=1)


def to_csv(trajectory: Trajectory, *, rate_hz: float = 125.0) -> str:
    """CSV: ``time`` (s), one column per joint (rad) named as the robot names it, ``gripper_opening_m``."""
    time, q, opening = uniform_samples(trajectory, 1.0 / rate_hz)
    rows = [",".join(["time", *trajectory.limits.joint_names, "gripper_opening_m"])]
    for t, pos, g in zip(time.tolist(), q.tolist(), opening.tolist()):
        rows.append(",".join([f"{t:.6f}", *(f"{v:.9f}" for v in pos), f"{g:.6f}"]))
    return "\n".join(rows) + "\n"
