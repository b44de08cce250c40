"""A robot arm: kinematics (Pinocchio model, vectorised FK), capsule geometry, gripper, IK.

Conventions
-----------
* Joint angles in rad, lengths in m, all poses 4x4 homogeneous transforms in the
  robot base frame.
* The ``tcp`` frame sits at the fingertip centre; its **+z axis is the finger
  direction** (the way the fingers point) and the fingers close along its y axis.
  "Fingers straight down" is the rotation ``Rz(yaw) @ Rx(pi)``.
* Collision geometry: each ``<cylinder>`` collision element of the URDF is read
  as the segment of a **capsule** of the same radius (URDF has no capsule
  primitive). The two finger capsules are declared at full opening and slide
  along the tcp y axis with the gripper opening.

Forward kinematics over a whole trajectory is vectorised: with ``oMi`` the joint
placements, ``oMi[j] = oMi[parent(j)] @ M_j @ X_j(q_j)`` where ``M_j`` is the
joint's fixed placement and ``X_j`` its motion (a rotation about, or translation
along, its axis). All ``T`` samples are one batched matrix product per joint.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import cached_property
from importlib import resources
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..errors import PlanningError, RobotModelError
from ..trajectory import RobotLimits

__all__ = ["Robot", "Capsule", "fingers_down"]


def fingers_down(yaw_rad: float = 0.0) -> np.ndarray:
    """Rotation with the finger direction (tcp +z) pointing straight down, turned by ``yaw_rad`` about z."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    # Rz(yaw) @ Rx(pi)
    return np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])


@dataclass(frozen=True)
class Capsule:
    """A collision capsule: segment ``p0``-``p1`` (m, in the frame ``frame``) and ``radius_m``."""

    name: str
    frame: str
    group: str  # "arm" or "gripper"
    p0: tuple[float, float, float]
    p1: tuple[float, float, float]
    radius_m: float


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    return pin.rpy.rpyToMatrix(r, p, y)


def _read_only(values) -> np.ndarray:
    """An own float copy of ``values`` that cannot be written in place (robots share nothing mutable)."""
    arr = np.array(values, dtype=float)
    arr.flags.writeable = False
    return arr


#: Joint angles this far outside a limit [rad] are rounding (IK, a controller's reading), not a violation.
LIMIT_TOLERANCE_RAD = 1e-9

# Capsule pairs closer than this (m) with the arm stretched out (q = 0) are parts of one
# housing (the compact UR wrist, base and shoulder column), not a pinch point to check.
_SAME_HOUSING_GAP_M = 0.06


def _axis_rotations(q: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """``(T, 3, 3)`` rotations by angles ``q`` (rad) about the unit ``axis`` (Rodrigues)."""
    k = axis / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    s, c = np.sin(q)[:, None, None], np.cos(q)[:, None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


class Robot:
    """Kinematic and collision model of an arm with a two-finger gripper.

    Use :meth:`ur3e` for the bundled UR3e, or :meth:`from_urdf` for other arms.

    A robot's facts are immutable: its arrays (``lower``, ``upper``, the
    velocity/acceleration/jerk limits, ``home_q``, ...) are read-only and its
    pair lists are tuples, so robots can share them. To change the home pose,
    assign a new one (``robot.home_q = q``, checked against the limits); that
    changes this robot only. The Pinocchio ``model`` is shared between copies
    and must be treated as read-only; ``data`` is each robot's own scratch space.
    """

    def __init__(
        self,
        urdf_path: str | Path,
        *,
        tcp_frame: str = "tcp",
        name: str | None = None,
        dh=None,
        acceleration_limits: np.ndarray | None = None,
        jerk_limits: np.ndarray | None = None,
        home: np.ndarray | None = None,
        self_pairs: list[tuple[str, str]] | None = None,
        fixed_links: tuple[str, ...] = ("base_link", "shoulder_link"),
    ):
        self.urdf_path = Path(urdf_path)
        try:
            self.model = pin.buildModelFromUrdf(str(self.urdf_path))
        except (RuntimeError, ValueError, OSError) as exc:
            raise RobotModelError(f"cannot load URDF {str(self.urdf_path)!r}: {exc}") from None
        if self.model.nq != self.model.nv:
            raise RobotModelError(f"{self.urdf_path}: continuous or spherical joints are not supported")
        self.name = name or self.model.name
        self.data = self.model.createData()
        self.dh = dh
        self.n = self.model.nq
        self.joint_names = tuple(self.model.names[1:])
        self.lower = _read_only(self.model.lowerPositionLimit)
        self.upper = _read_only(self.model.upperPositionLimit)
        self.velocity_limits = _read_only(self.model.velocityLimit)
        if np.any(self.velocity_limits <= 0):
            raise RobotModelError(f"{self.urdf_path}: every joint needs a positive <limit velocity=...>")
        # URDF has no acceleration or jerk limits. Unless given (robot/arms.py has the UR3e's):
        # 1.6 x the speed limit per second, reached in a 0.1 s jerk ramp
        self.acceleration_limits = _read_only(
            acceleration_limits if acceleration_limits is not None else 1.6 * self.velocity_limits
        )
        self.jerk_limits = _read_only(jerk_limits if jerk_limits is not None else 10.0 * self.acceleration_limits)
        if not self.model.existFrame(tcp_frame, pin.FrameType.BODY):
            raise RobotModelError(
                f"{self.urdf_path}: no link {tcp_frame!r} for the TCP; links are "
                + ", ".join(f.name for f in self.model.frames if f.type == pin.FrameType.BODY)
            )
        self.tcp_frame = tcp_frame
        self._tcp_frame_id = self.model.getFrameId(tcp_frame, pin.FrameType.BODY)
        self._parse_urdf_extras()
        self.fixed_links = tuple(fixed_links)
        self._build_fk_tables()
        self.home_q = home if home is not None else np.clip(np.zeros(self.n), self.lower, self.upper)
        self.self_pairs: tuple[tuple[str, str], ...] = (
            self._default_self_pairs() if self_pairs is None else tuple((str(a), str(b)) for a, b in self_pairs)
        )

    # --- construction -----------------------------------------------------------------

    @classmethod
    def ur3e(cls) -> "Robot":
        """The bundled UR3e (e-series DH) with a Robotiq 2F-85-sized gripper; TCP at the fingertips.

        Each call returns an independent robot (the URDF is parsed once and its
        immutable parts shared).
        """
        return _ur3e_cached().copy()

    @classmethod
    def from_urdf(cls, path: str | Path, tcp_frame: str = "tcp", **kwargs) -> "Robot":
        """Load another arm; IK falls back to Pinocchio damped least squares."""
        return cls(path, tcp_frame=tcp_frame, **kwargs)

    def copy(self) -> "Robot":
        """An independent robot: the immutable facts are shared, Pinocchio ``data`` is new."""
        other = object.__new__(Robot)
        other.__dict__.update(self.__dict__)
        other.data = self.model.createData()
        return other

    @property
    def home_q(self) -> np.ndarray:
        """Home configuration ``(n,)`` rad (read-only; assign a new one to change it)."""
        return self._home_q

    @home_q.setter
    def home_q(self, q) -> None:
        self._home_q = _read_only(self.joint_vector(q, "home_q"))

    def joint_vector(self, q, what: str, error: type[Exception] = RobotModelError) -> np.ndarray:
        """``q`` as a float array ``(n,)`` [rad], finite and within the joint limits.

        Anything else raises ``error`` whose message starts with ``what`` (the argument's name)
        and names the offending joint.
        """
        try:
            vector = np.array(q, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise error(f"{what} must be {self.n} joint angles in rad, got {q!r}") from None
        if vector.shape != (self.n,):
            raise error(f"{what} must be {self.n} joint angles in rad, got {vector.size}")
        for j, (v, lo, hi) in enumerate(zip(vector, self.lower, self.upper)):
            if not (math.isfinite(v) and lo - LIMIT_TOLERANCE_RAD <= v <= hi + LIMIT_TOLERANCE_RAD):
                raise error(
                    f"{what} joint {j} ({self.joint_names[j]}) = {v:.4f} rad is outside its limits "
                    f"[{lo:.4f}, {hi:.4f}] rad"
                )
        return vector

    def _parse_urdf_extras(self) -> None:
        root = ET.parse(self.urdf_path).getroot()
        capsules: list[Capsule] = []
        gripper = root.find("gripper")
        finger_links = gripper.get("fingers", "").split() if gripper is not None else []
        self.max_opening_m = float(gripper.get("max_opening", "0.085")) if gripper is not None else 0.0
        self.finger_links = tuple(finger_links)
        gripper_links = {"gripper_body", *finger_links}
        for link in root.findall("link"):
            lname = link.get("name")
            for k, col in enumerate(link.findall("collision")):
                cyl = col.find("geometry/cylinder")
                if cyl is None:
                    continue
                origin = col.find("origin")
                xyz = np.array([float(v) for v in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()])
                rpy = [float(v) for v in (origin.get("rpy", "0 0 0") if origin is not None else "0 0 0").split()]
                axis = _rpy(*rpy)[:, 2]
                half = float(cyl.get("length")) / 2
                suffix = f"#{k}" if k else ""
                capsules.append(
                    Capsule(
                        name=f"{lname}{suffix}",
                        frame=lname,
                        group="gripper" if lname in gripper_links else "arm",
                        p0=tuple(xyz - half * axis),
                        p1=tuple(xyz + half * axis),
                        radius_m=float(cyl.get("radius")),
                    )
                )
        if not capsules:
            raise RobotModelError(f"{self.urdf_path}: no <cylinder> collision elements (read as capsules) found")
        self.capsules = tuple(capsules)

    def _build_fk_tables(self) -> None:
        model = self.model
        self._joint_placements = [np.array(model.jointPlacements[j].homogeneous) for j in range(model.njoints)]
        self._joint_parents = [int(model.parents[j]) for j in range(model.njoints)]
        self._joint_motion: list[tuple[str, np.ndarray]] = [("fixed", np.zeros(3))]
        for j in range(1, model.njoints):
            short = model.joints[j].shortname()
            if short in ("JointModelRX", "JointModelRY", "JointModelRZ"):
                axis = np.eye(3)["XYZ".index(short[-1])]
                self._joint_motion.append(("revolute", axis))
            elif short == "JointModelRevoluteUnaligned":
                self._joint_motion.append(("revolute", np.array(model.joints[j].extract().axis)))
            elif short in ("JointModelPX", "JointModelPY", "JointModelPZ"):
                self._joint_motion.append(("prismatic", np.eye(3)["XYZ".index(short[-1])]))
            elif short == "JointModelPrismaticUnaligned":
                self._joint_motion.append(("prismatic", np.array(model.joints[j].extract().axis)))
            else:
                raise RobotModelError(f"{self.urdf_path}: joint {model.names[j]!r} of type {short} is not supported")
        body_frames = [f for f in model.frames if f.type == pin.FrameType.BODY and f.name != "universe"]
        self.frame_names = tuple(f.name for f in body_frames)
        self._frame_parent = np.array([f.parentJoint for f in body_frames])
        self._frame_placement = np.array([f.placement.homogeneous for f in body_frames])
        self._frame_index = {n: i for i, n in enumerate(self.frame_names)}
        self.tcp_index = self._frame_index[self.tcp_frame]
        tcp_in_flange = None
        if "tool0" in self._frame_index:
            fk = self._forward_static(np.zeros(self.n))
            tcp_in_flange = np.linalg.inv(fk[self._frame_index["tool0"]]) @ fk[self.tcp_index]
        self.tcp_in_flange = None if tcp_in_flange is None else _read_only(tcp_in_flange)
        self._flange_in_tcp = None if tcp_in_flange is None else _read_only(np.linalg.inv(tcp_in_flange))
        self._capsule_frame = np.array([self._frame_index[c.frame] for c in self.capsules])
        self._capsule_p0 = _read_only([c.p0 for c in self.capsules])
        self._capsule_p1 = _read_only([c.p1 for c in self.capsules])
        self.capsule_radii = _read_only([c.radius_m for c in self.capsules])
        self.capsule_names = tuple(c.name for c in self.capsules)
        self.capsule_groups = tuple(c.group for c in self.capsules)
        self._finger_sign = np.array(
            [(1.0 if c.frame == self.finger_links[0] else -1.0) if c.frame in self.finger_links else 0.0 for c in self.capsules]
        )

    def _forward_static(self, q: np.ndarray) -> np.ndarray:
        return self.forward(q[None, :])[0]

    # --- limits ---------------------------------------------------------------------

    @cached_property
    def limits(self) -> RobotLimits:
        return RobotLimits(
            joint_names=self.joint_names,
            lower_rad=tuple(self.lower),
            upper_rad=tuple(self.upper),
            velocity_rad_s=tuple(self.velocity_limits),
            acceleration_rad_s2=tuple(self.acceleration_limits),
        )

    # --- kinematics -----------------------------------------------------------------

    def forward(self, q: np.ndarray, gripper_opening_m: np.ndarray | float | None = None) -> np.ndarray:
        """Poses of every body frame (``frame_names``) for joint samples ``q``.

        ``q`` is ``(T, n)`` (or ``(n,)``) rad; returns ``(T, L, 4, 4)`` (or ``(L, 4, 4)``).
        Finger frames slide along the tcp y axis with ``gripper_opening_m`` (m,
        default fully open).
        """
        q = np.asarray(q, dtype=float)
        single = q.ndim == 1
        if single:
            q = q[None, :]
        if q.ndim != 2 or q.shape[1] != self.n:
            raise RobotModelError(f"q must have shape (T, {self.n}), got {q.shape}")
        T = q.shape[0]
        oMi = np.empty((self.model.njoints, T, 4, 4))
        oMi[0] = np.eye(4)
        for j in range(1, self.model.njoints):
            kind, axis = self._joint_motion[j]
            X = np.broadcast_to(np.eye(4), (T, 4, 4)).copy()
            if kind == "revolute":
                X[:, :3, :3] = _axis_rotations(q[:, j - 1], axis)
            else:
                X[:, :3, 3] = q[:, j - 1, None] * axis
            oMi[j] = (oMi[self._joint_parents[j]] @ self._joint_placements[j]) @ X
        frames = np.einsum("ftij,fjk->tfik", oMi[self._frame_parent], self._frame_placement, optimize=True)
        if self.finger_links and gripper_opening_m is not None:
            shift = (self.max_opening_m - np.broadcast_to(np.asarray(gripper_opening_m, float), (T,))) / 2
            y_axis = frames[:, self.tcp_index, :3, 1]
            for sign, link in zip((1.0, -1.0), self.finger_links):
                f = self._frame_index[link]
                frames[:, f, :3, 3] -= sign * shift[:, None] * y_axis
        return frames[0] if single else frames

    def tcp_pose(self, q: np.ndarray) -> np.ndarray:
        """TCP pose(s) ``(4, 4)`` or ``(T, 4, 4)`` for ``q``."""
        q = np.asarray(q, dtype=float)
        if q.shape == (self.n,):
            # one configuration: Pinocchio directly, far cheaper than the batched path
            pin.forwardKinematics(self.model, self.data, q)
            return pin.updateFramePlacement(self.model, self.data, self._tcp_frame_id).homogeneous.copy()
        frames = self.forward(q)
        return frames[..., self.tcp_index, :, :]

    def capsule_segments(self, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Capsule endpoints ``(T, C, 3)`` each, m in the base frame, from ``frames (T, L, 4, 4)``."""
        F = frames[:, self._capsule_frame]  # (T, C, 4, 4)
        R, t = F[..., :3, :3], F[..., :3, 3]
        p0 = np.einsum("tcij,cj->tci", R, self._capsule_p0) + t
        p1 = np.einsum("tcij,cj->tci", R, self._capsule_p1) + t
        return p0, p1

    def trajectory(self, q: np.ndarray, time: np.ndarray, scene, **kwargs):
        """The :class:`~robocritics.trajectory.Trajectory` of joint samples ``q`` at ``time`` in ``scene``.

        See :func:`robocritics.robot.trace.build_trajectory` for the optional arguments.
        """
        from .trace import build_trajectory

        return build_trajectory(self, scene, q, time, **kwargs)

    def in_limits(self, q: np.ndarray, tol: float = LIMIT_TOLERANCE_RAD) -> bool:
        """True when every joint of ``q`` (rad) is within its limits, up to ``tol`` rad."""
        q = np.asarray(q)
        return bool(np.all(q >= self.lower - tol) and np.all(q <= self.upper + tol))

    def ik(
        self,
        position,
        orientation: np.ndarray | None = None,
        seed: np.ndarray | None = None,
        *,
        yaw_rad: float = 0.0,
    ) -> np.ndarray:
        """Joint angles (rad) that put the TCP at ``position`` (m) with ``orientation``.

        ``orientation`` is a 3x3 rotation of the tcp frame (default: fingers straight
        down, turned by ``yaw_rad``). Among all solutions within the joint limits
        the one nearest ``seed`` (default: the home pose) is returned. UR arms use
        closed-form IK (all 8 branches); others Pinocchio damped least squares.
        Raises :class:`PlanningError` naming the target and why.
        """
        from . import ik as _ik

        p = np.asarray(position, dtype=float).reshape(3)
        if not np.all(np.isfinite(p)):
            raise PlanningError(f"target {p.tolist()} is not a finite position")
        R = fingers_down(yaw_rad) if orientation is None else np.asarray(orientation, float)
        target = np.eye(4)
        target[:3, :3], target[:3, 3] = R, p
        seed = self.home_q if seed is None else np.asarray(seed, float)
        try:
            if self.dh is not None and self.tcp_in_flange is not None:
                flange = target @ self._flange_in_tcp
                return _ik.ur_ik(self.dh, flange, seed, self.lower, self.upper)
            return _ik.numeric_ik(self.model, self.data, self._tcp_frame_id, target, seed, self.lower, self.upper)
        except PlanningError as exc:
            pose = "with the fingers down" if orientation is None else "in the requested orientation"
            raise PlanningError(
                f"cannot put the TCP at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m {pose}: {exc.reason}"
            ) from None

    # --- self-collision pairs ---------------------------------------------------------

    def _default_self_pairs(self) -> tuple[tuple[str, str], ...]:
        """Capsule pairs checked for pinch points.

        Adjacent links (sharing a joint) are never pairs. Beyond that we drop the
        pairs that are close *by construction*: those closer than
        ``_SAME_HOUSING_GAP_M`` (0.06 m) in the zero configuration with the links
        stretched out, i.e. parts of one housing (the compact UR wrist, base and
        shoulder column). What remains are non-adjacent arm links and arm links
        against the gripper, the pairs that can close on a hand.
        """
        from .proximity import capsule_capsule

        parent_of = {}
        for f in self.model.frames:
            if f.type == pin.FrameType.BODY:
                parent_of[f.name] = f.parentJoint
        frames = self.forward(np.zeros((1, self.n)))
        p0, p1 = self.capsule_segments(frames)
        pairs = []
        C = len(self.capsules)
        for i in range(C):
            for j in range(i + 1, C):
                ci, cj = self.capsules[i], self.capsules[j]
                if ci.group == "gripper" and cj.group == "gripper":
                    continue
                ji, jj = parent_of[ci.frame], parent_of[cj.frame]
                if ji == jj or self.model.parents[ji] == jj or self.model.parents[jj] == ji:
                    continue
                d = capsule_capsule(p0[:, i], p1[:, i], ci.radius_m, p0[:, j], p1[:, j], cj.radius_m)[0]
                if d < _SAME_HOUSING_GAP_M:
                    continue
                pairs.append((ci.name, cj.name))
        return tuple(pairs)

    def __repr__(self) -> str:
        return f"Robot({self.name!r}, {self.n} joints, tcp={self.tcp_frame!r}, {len(self.capsules)} capsules)"


_UR3E: Robot | None = None


def _ur3e_cached() -> Robot:
    global _UR3E
    if _UR3E is None:
        from .arms import UR3E

        path = resources.files("robocritics.robot") / "models" / "ur3e.urdf"
        robot = Robot(
            str(path),
            tcp_frame="tcp",
            name=UR3E.name,
            dh=UR3E.dh,
            acceleration_limits=np.array(UR3E.acceleration_rad_s2),
            jerk_limits=np.array(UR3E.jerk_rad_s3),
        )
        # home: TCP 0.25 m in front of the base and 0.25 m above the table, fingers down, elbow up
        upright = np.array([math.pi, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0])
        robot.home_q = robot.ik((0.25, 0.0, 0.25), seed=upright)
        _UR3E = robot
    return _UR3E
