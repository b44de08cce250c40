"""URScript's pose arithmetic: poses ``p[x, y, z, rx, ry, rz]`` (m, rotation vector in rad) as 4x4 transforms.

The functions follow the URScript manual's definitions: ``pose_trans(a, b)`` is the
transform product ``a · b``; ``pose_add(a, b)`` adds positions and composes rotations
``R_a · R_b``; ``pose_sub(a, b)`` subtracts positions and gives ``R_a · R_b^-1``;
``pose_inv`` the inverse; ``pose_dist`` the distance between the positions (m).
``rpy2rotvec``/``rotvec2rpy`` use roll-pitch-yaw about the fixed x, y, z axes
(``R = Rz(yaw) · Ry(pitch) · Rx(roll)``), as the manual does.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "Pose",
    "rotvec_to_matrix",
    "matrix_to_rotvec",
    "pose_matrix",
    "matrix_pose",
    "pose_trans",
    "pose_add",
    "pose_sub",
    "pose_inv",
    "pose_dist",
    "rpy2rotvec",
    "rotvec2rpy",
    "interpolate_pose",
]


class Pose(tuple):
    """A URScript pose value: six floats ``(x, y, z, rx, ry, rz)`` (m, rad). Immutable."""

    __slots__ = ()

    def __new__(cls, values):
        values = tuple(float(v) for v in values)
        if len(values) != 6:
            raise ValueError(f"a pose has 6 numbers, got {len(values)}")
        return super().__new__(cls, values)

    def __repr__(self) -> str:
        return "p[" + ", ".join(f"{v:.6g}" for v in self) + "]"


def rotvec_to_matrix(r) -> np.ndarray:
    """Rotation matrix of rotation vector ``r`` (axis × angle, rad) by Rodrigues' formula."""
    r = np.asarray(r, dtype=float)
    angle = math.sqrt(float(r @ r))
    if angle < 1e-12:
        return np.eye(3)
    k = r / angle
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


def matrix_to_rotvec(R) -> np.ndarray:
    """Rotation vector (rad) of rotation matrix ``R``; the angle in [0, pi]."""
    R = np.asarray(R, dtype=float)
    cos = max(-1.0, min(1.0, (np.trace(R) - 1.0) / 2.0))
    angle = math.acos(cos)
    if angle < 1e-9:
        return np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2.0
    if math.pi - angle < 1e-6:
        # near a half turn the skew part vanishes: the axis from the diagonal of R = 2kk^T - I
        k = np.sqrt(np.maximum((np.diag(R) + 1.0) / 2.0, 0.0))
        i = int(np.argmax(k))
        k[(i + 1) % 3] = math.copysign(k[(i + 1) % 3], R[i, (i + 1) % 3] + R[(i + 1) % 3, i])
        k[(i + 2) % 3] = math.copysign(k[(i + 2) % 3], R[i, (i + 2) % 3] + R[(i + 2) % 3, i])
        return k / np.linalg.norm(k) * angle
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / (2.0 * math.sin(angle))
    return axis * angle


def pose_matrix(pose) -> np.ndarray:
    """The 4x4 homogeneous transform of a pose."""
    T = np.eye(4)
    T[:3, :3] = rotvec_to_matrix(pose[3:6])
    T[:3, 3] = pose[0:3]
    return T


def matrix_pose(T) -> Pose:
    """The pose of a 4x4 homogeneous transform."""
    T = np.asarray(T, dtype=float)
    return Pose(list(T[:3, 3]) + list(matrix_to_rotvec(T[:3, :3])))


def pose_trans(p_from, p_from_to) -> Pose:
    return matrix_pose(pose_matrix(p_from) @ pose_matrix(p_from_to))


def pose_add(p1, p2) -> Pose:
    R = rotvec_to_matrix(p1[3:6]) @ rotvec_to_matrix(p2[3:6])
    return Pose([p1[i] + p2[i] for i in range(3)] + list(matrix_to_rotvec(R)))


def pose_sub(p_to, p_from) -> Pose:
    R = rotvec_to_matrix(p_to[3:6]) @ rotvec_to_matrix(p_from[3:6]).T
    return Pose([p_to[i] - p_from[i] for i in range(3)] + list(matrix_to_rotvec(R)))


def pose_inv(p) -> Pose:
    return matrix_pose(np.linalg.inv(pose_matrix(p)))


def pose_dist(p_from, p_to) -> float:
    return math.dist(p_from[:3], p_to[:3])


def rpy2rotvec(rpy) -> list[float]:
    roll, pitch, yaw = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    R = np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )
    return matrix_to_rotvec(R).tolist()


def rotvec2rpy(rotvec) -> list[float]:
    R = rotvec_to_matrix(rotvec)
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    if math.cos(pitch) < 1e-9:  # gimbal lock: yaw and roll share one axis; put it all in roll
        return [math.atan2(-R[1, 2], R[1, 1]), pitch, 0.0]
    return [math.atan2(R[2, 1], R[2, 2]), pitch, math.atan2(R[1, 0], R[0, 0])]


def slerp_rotations(Ra: np.ndarray, Rb: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``(m, 3, 3)`` rotations from ``Ra`` to ``Rb`` along the shortest arc at fractions ``s`` (m,)."""
    w = matrix_to_rotvec(Ra.T @ Rb)
    angle = float(np.linalg.norm(w))
    s = np.asarray(s, dtype=float)
    if angle < 1e-12:
        return np.broadcast_to(Ra, (len(s), 3, 3)).copy()
    k = w / angle
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    th = (s * angle)[:, None, None]
    steps = np.eye(3) + np.sin(th) * K + (1.0 - np.cos(th)) * (K @ K)
    return Ra @ steps


def interpolate_pose(p_from, p_to, alpha: float) -> Pose:
    Ta, Tb = pose_matrix(p_from), pose_matrix(p_to)
    T = np.eye(4)
    T[:3, :3] = slerp_rotations(Ta[:3, :3], Tb[:3, :3], np.array([alpha]))[0]
    T[:3, 3] = Ta[:3, 3] + alpha * (Tb[:3, 3] - Ta[:3, 3])
    return matrix_pose(T)
