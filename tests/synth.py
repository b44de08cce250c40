"""Hand-built trajectories for critic tests and benchmarks (no planner needed).

* :func:`make_trajectory` wraps arrays into a valid :class:`Trajectory` with sensible defaults;
* :func:`frames_from` builds ``(T, L, 4, 4)`` poses from positions and (optionally) finger directions;
* :func:`line_motion` moves one point along a straight line at a known speed;
* :func:`realistic_trajectory` synthesises a pick-and-place-like UR3e motion
  (the UR3e model's forward kinematics, 12 frames, ~60 tagged proximity pairs,
  steps with lines, an attached object) at any sample rate.
"""

from __future__ import annotations

import math

import numpy as np

from robocritics.robot.model import Robot
from robocritics.trajectory import Pair, RobotLimits, Step, Trajectory

_UR3E = Robot.ur3e()
FRAME_NAMES = _UR3E.frame_names  # base_link ... wrist_3_link, tool0, gripper_body, left/right_finger, tcp


def limits(n: int = 6, velocity=None) -> RobotLimits:
    """The UR3e's joint limits for 6 joints (``velocity`` rad/s overrides its speed limits), generic ones otherwise."""
    if n == 6:
        ur3e = _UR3E.limits
        return ur3e if velocity is None else ur3e.model_copy(update={"velocity_rad_s": tuple(velocity)})
    return RobotLimits(
        joint_names=tuple(f"joint_{i}" for i in range(n)),
        lower_rad=(-2 * math.pi,) * n,
        upper_rad=(2 * math.pi,) * n,
        velocity_rad_s=tuple(velocity) if velocity is not None else (math.pi,) * n,
        acceleration_rad_s2=(10.0,) * n,
    )


def rotation_with_z(z: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` whose column 2 is the unit vector ``z (..., 3)``."""
    z = np.asarray(z, float)
    z = z / np.linalg.norm(z, axis=-1, keepdims=True)
    helper = np.where(np.abs(z[..., :1]) < 0.9, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
    x = np.cross(helper, z)
    x /= np.linalg.norm(x, axis=-1, keepdims=True)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=-1)


def frames_from(positions: np.ndarray, z_axes: np.ndarray | None = None) -> np.ndarray:
    """``(T, L, 4, 4)`` poses at ``positions (T, L, 3)``; z axes ``(T, L, 3)`` or ``(3,)`` (default straight down)."""
    positions = np.asarray(positions, float)
    T, L, _ = positions.shape
    F = np.zeros((T, L, 4, 4))
    F[..., 3, 3] = 1.0
    F[..., :3, 3] = positions
    if z_axes is None:
        z_axes = np.array([0.0, 0.0, -1.0])
    F[..., :3, :3] = rotation_with_z(np.broadcast_to(np.asarray(z_axes, float), (T, L, 3)))
    return F


def make_trajectory(
    time,
    positions=None,
    *,
    frames=None,
    frame_names=None,
    z_axes=None,
    proximity=None,
    pairs=(),
    q=None,
    steps=None,
    step=None,
    attached=None,
    gripper=None,
    robot_limits=None,
) -> Trajectory:
    time = np.asarray(time, float)
    T = len(time)
    if frames is None:
        frames = frames_from(positions if positions is not None else np.zeros((T, 1, 3)), z_axes)
    frames = np.asarray(frames, float)
    L = frames.shape[1]
    if frame_names is None:
        frame_names = FRAME_NAMES if L == len(FRAME_NAMES) else (("tcp",) if L == 1 else tuple(f"link_{i}" for i in range(L - 1)) + ("tcp",))
    if q is None:
        q = np.zeros((T, 6))
    q = np.asarray(q, float)
    pairs = list(pairs)
    if proximity is None:
        proximity = np.ones((T, len(pairs)))
    if steps is None:
        steps = [Step(skill="move_to", line=1)]
    if step is None:
        step = np.zeros(T, dtype=np.int64)
    if attached is None:
        attached = [""] * T
    if gripper is None:
        gripper = np.full(T, 0.085)
    return Trajectory(
        q=q,
        time=time,
        frames=frames,
        frame_names=frame_names,
        proximity=proximity,
        pairs=pairs,
        gripper_opening_m=gripper,
        attached=attached,
        step=step,
        steps=steps,
        limits=robot_limits or limits(q.shape[1]),
    )


def line_motion(speed_m_s: float, direction=(1.0, 0.0, 0.0), rate_hz: float = 125.0, duration_s: float = 1.0, start=(0.2, 0.0, 0.3)):
    """``(time (T,), positions (T, 1, 3))`` of a point moving at constant ``speed_m_s`` along ``direction``."""
    T = int(round(duration_s * rate_hz)) + 1
    time = np.arange(T) / rate_hz
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    pos = np.asarray(start, float) + speed_m_s * time[:, None] * d
    return time, pos[:, None, :]


def self_pair(a: str, b: str, group_b: str = "arm") -> Pair:
    return Pair(name=f"{a}|{b}", kind="self", a=a, b=b, group_a="arm", group_b=group_b)


def env_pair(a: str, b: str, group_a: str = "gripper", group_b: str = "object", entity: str | None = None) -> Pair:
    return Pair(name=f"{a}|{b}", kind="environment", a=a, b=b, group_a=group_a, group_b=group_b, b_entity=entity if entity is not None else b)


# --- a realistic motion ----------------------------------------------------------------


def realistic_trajectory(duration_s: float = 60.0, rate_hz: float = 500.0, seed: int = 0, n_waypoints: int = 16) -> Trajectory:
    """A pick-and-place-like UR3e motion: minimum-jerk moves between random joint waypoints,
    12 frames, 18 self pairs and 42 environment pairs (60), steps with lines, an attached object."""
    rng = np.random.default_rng(seed)
    T = int(round(duration_s * rate_hz))
    time = np.arange(T) / rate_hz
    wp = rng.uniform([-1.5, -2.0, 0.6, -2.2, -1.7, -1.0], [1.5, -1.0, 2.0, -0.9, -1.4, 1.0], (n_waypoints, 6))
    knots = np.linspace(0.0, time[-1], n_waypoints)
    seg = np.clip(np.searchsorted(knots, time, side="right") - 1, 0, n_waypoints - 2)
    s = (time - knots[seg]) / (knots[seg + 1] - knots[seg])
    s = 10 * s**3 - 15 * s**4 + 6 * s**5
    q = wp[seg] + (wp[seg + 1] - wp[seg]) * s[:, None]
    frames = _UR3E.forward(q)
    pos = frames[:, :, :3, 3]

    arm = ["upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link", "wrist_3_link"]
    gripper = ["gripper_body", "left_finger", "right_finger"]
    idx = {n: i for i, n in enumerate(FRAME_NAMES)}
    pairs: list[Pair] = []
    cols: list[np.ndarray] = []
    for i, a in enumerate(arm):
        for b in arm[i + 2 :]:
            pairs.append(self_pair(a, b))
            cols.append(np.linalg.norm(pos[:, idx[a]] - pos[:, idx[b]], axis=1) - 0.05)
    for a in ["upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link"]:
        for b in gripper:
            pairs.append(self_pair(a, b, group_b="gripper"))
            cols.append(np.linalg.norm(pos[:, idx[a]] - pos[:, idx[b]], axis=1) - 0.04)
    objects = {
        "red_apple": ((0.3, 0.06, 0.035), 0.035, "object"),
        "green_apple": ((0.38, 0.0, 0.035), 0.035, "object"),
        "white_box": ((0.18, 0.27, 0.04), 0.08, "container"),
        "brown_box": ((0.18, -0.27, 0.04), 0.08, "container"),
        "table": ((0.0, 0.0, -0.02), 0.02, "table"),
    }
    movers = [("forearm_link", "arm"), ("wrist_1_link", "arm"), ("wrist_2_link", "arm"), ("wrist_3_link", "arm")] + [
        (g, "gripper") for g in gripper
    ] + [("tcp", "attached")]
    for a, ga in movers:
        for b, (c, r, gb) in objects.items():
            if b == "table":
                d = pos[:, idx[a], 2] - 0.0 - 0.03
            else:
                d = np.linalg.norm(pos[:, idx[a]] - np.asarray(c), axis=1) - r - 0.03
            pairs.append(env_pair("red_apple" if ga == "attached" else a, b, group_a=ga, group_b=gb, entity=b))
            cols.append(d)
    for a, ga in [("upper_arm_link", "arm")]:
        for b in ("white_box", "brown_box"):
            c, r, gb = objects[b]
            pairs.append(env_pair(a, b, group_a=ga, group_b=gb))
            cols.append(np.linalg.norm(pos[:, idx[a]] - np.asarray(c), axis=1) - r - 0.03)
    proximity = np.stack(cols, axis=1)

    skills = ["move_to", "move_down", "close_gripper", "move_up", "move_to", "move_down", "open_gripper", "move_up"]
    steps = [
        Step(skill=skills[i % len(skills)], line=3 + i, contacts=("red_apple",) if skills[i % len(skills)] == "close_gripper" else ())
        for i in range(n_waypoints - 1)
    ]
    step = seg.astype(np.int64)
    held = (step % len(skills) >= 2) & (step % len(skills) < 6)
    attached = np.where(held, "red_apple", "")
    return Trajectory(
        q=q,
        time=time,
        frames=frames,
        frame_names=FRAME_NAMES,
        proximity=proximity,
        pairs=pairs,
        gripper_opening_m=np.where(held, 0.07, 0.085),
        attached=attached,
        step=step,
        steps=steps,
        limits=limits(6),
        robot_name="synthetic-ur3e",
    )
