"""rosbag2 recordings (``.mcap`` or ``.db3`` with their ``metadata.yaml``) read with ``rosbags``.

The topic is a ``trajectory_msgs/msg/JointTrajectory`` (its points, timed from the message's
``time_from_start``; the first such message unless another is chosen) or a ``sensor_msgs/msg/JointState``
stream (every message a sample, timed by its header stamp, else by the bag's receive time). With no
``topic`` the one topic of either type is used; several are an error naming them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import TrajectoryError
from .files import GRIPPER_NAME, MAX_ROWS, Recording, joint_trajectory

__all__ = ["read_rosbag", "JOINT_STATE", "JOINT_TRAJECTORY"]

JOINT_STATE = "sensor_msgs/msg/JointState"
JOINT_TRAJECTORY = "trajectory_msgs/msg/JointTrajectory"


def bag_directory(path: Path) -> Path:
    """The rosbag2 directory of ``path`` (the directory itself, or the one holding the storage file)."""
    directory = path if path.is_dir() else path.parent
    if not (directory / "metadata.yaml").is_file():
        raise TrajectoryError(f"{path}: a rosbag2 recording needs its metadata.yaml beside the storage file")
    return directory


def read_rosbag(path: str | Path, topic: str | None = None) -> Recording:
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:  # pragma: no cover - an optional extra
        raise TrajectoryError("reading rosbag2 needs rosbags: pip install 'robocritics[formats]'") from None
    directory = bag_directory(Path(path))
    try:
        with AnyReader([directory], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            usable = [c for c in reader.connections if c.msgtype in (JOINT_STATE, JOINT_TRAJECTORY)]
            chosen = [c for c in usable if topic is None or c.topic == topic]
            if not chosen:
                have = ", ".join(f"{c.topic} ({c.msgtype})" for c in reader.connections) or "none"
                wanted = f"topic {topic!r}" if topic else "a JointState or JointTrajectory topic"
                raise TrajectoryError(f"{path}: no {wanted} of a usable type; topics: {have}")
            if len({c.topic for c in chosen}) > 1:
                raise TrajectoryError(f"{path}: several joint topics ({', '.join(sorted({c.topic for c in chosen}))}); choose one with --topic")
            if chosen[0].msgtype == JOINT_TRAJECTORY:
                for conn, _, raw in reader.messages(connections=chosen):
                    return joint_trajectory(_trajectory_dict(reader.deserialize(raw, conn.msgtype)), f"{path} {conn.topic}")
            return _joint_states(reader, chosen, str(path))
    except TrajectoryError:
        raise
    except Exception as exc:  # rosbags raises its own errors for damaged files
        raise TrajectoryError(f"{path}: not a readable rosbag2 recording: {type(exc).__name__}: {str(exc)[:200]}") from None
    raise TrajectoryError(f"{path}: the topic has no messages")


def _trajectory_dict(msg) -> dict:
    return {
        "joint_names": list(msg.joint_names),
        "points": [
            {
                "positions": [float(v) for v in p.positions],
                "velocities": [float(v) for v in p.velocities],
                "time_from_start": {"sec": int(p.time_from_start.sec), "nanosec": int(p.time_from_start.nanosec)},
            }
            for p in msg.points
        ],
    }


def _joint_states(reader, connections, what: str) -> Recording:
    names: list[str] | None = None
    times: list[float] = []
    rows: list[np.ndarray] = []
    for conn, received_ns, raw in reader.messages(connections=connections):
        msg = reader.deserialize(raw, conn.msgtype)
        these = list(msg.name)
        if names is None:
            names = these
        elif these != names:
            raise TrajectoryError(f"{what}: JointState message {len(rows)} names other joints ({', '.join(these)[:120]})")
        stamp = msg.header.stamp
        t = stamp.sec + stamp.nanosec * 1e-9 if (stamp.sec or stamp.nanosec) else received_ns * 1e-9
        times.append(t)
        rows.append(np.asarray(msg.position, dtype=float))
        if len(rows) > MAX_ROWS:
            raise TrajectoryError(f"{what}: more than {MAX_ROWS:,} JointState messages")
    if not rows or names is None:
        raise TrajectoryError(f"{what}: the topic has no messages")
    positions = np.array(rows)
    gripper = positions[:, names.index(GRIPPER_NAME)].copy() if GRIPPER_NAME in names else None
    return Recording(names, np.array(times), positions, gripper=gripper, live=True)
