"""What Pinocchio reads from a URDF, as the plain tables :class:`~robocritics.robot.model.Robot` computes with.

Pinocchio parses a URDF into a model; the robot's vectorised forward kinematics needs only a few of its facts:
each joint's fixed placement (4x4, in its parent joint's frame, m), parent and motion (a rotation about, or a
translation along, a unit axis), each link (body frame) with the joint it hangs on and its placement there,
and the joint limits (rad or m, rad/s or m/s). :meth:`KinematicTables.of_model` takes them from a Pinocchio
model.

The bundled arms' files do not change between runs, so what Pinocchio reads from them is stored beside them
(``robot/models/<arm>.tables.json``, written by ``python -m robocritics.robot.kinematic_tables``):
:func:`stored_tables` returns that copy only when it was written from exactly the text Pinocchio would be
given now (its SHA-256), so a check with a bundled arm does not load Pinocchio (its import is ~30-60 ms of
the CPU of a cold ``robocritics check``); any other file, or a stored copy that no longer matches its URDF, is
read by Pinocchio. ``tests/test_kinematic_tables.py`` compares every stored copy with what Pinocchio reads from
its URDF now. Floats are stored as JSON numbers (``repr``), which read back as the same float64.

Two of Pinocchio's computations are here too, in its own order of floating-point operations, so that they give
its results to the last bit (the trajectories of the bundled examples are hashed, and an IK target one ulp off
moves a sample): :func:`pinocchio_rpy` (``pinocchio.rpy.rpyToMatrix``, through Eigen's quaternions) and
:func:`pinocchio_frame_pose` (``forwardKinematics`` + ``updateFramePlacement`` of one frame, for chains of
joints revolving about their z axis, every joint of the bundled arms). The tests compare both with Pinocchio,
bit for bit.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..errors import RobotModelError

__all__ = [
    "KinematicTables", "PinocchioModel", "build_model", "pinocchio_urdf", "urdf_digest", "stored_tables",
    "write_bundled", "pinocchio_rpy", "pinocchio_frame_pose", "rotation_angle", "CONTINUOUS_LIMIT_RAD",
]  # fmt: skip

#: Limits of a URDF ``continuous`` joint, read as revolute [rad].
CONTINUOUS_LIMIT_RAD = 2 * math.pi

#: Pinocchio's joint types and the motion each is: (kind, axis index in x, y, z, or None for "its own axis").
_MOTIONS = {
    "JointModelRX": ("revolute", 0), "JointModelRY": ("revolute", 1), "JointModelRZ": ("revolute", 2),
    "JointModelRevoluteUnaligned": ("revolute", None),
    "JointModelPX": ("prismatic", 0), "JointModelPY": ("prismatic", 1), "JointModelPZ": ("prismatic", 2),
    "JointModelPrismaticUnaligned": ("prismatic", None),
}  # fmt: skip

#: Version of the stored layout: a file of another version is not read.
_FORMAT = 1


class KinematicTables:
    """The facts of a Pinocchio model that forward kinematics and the limits need (see the module docstring).

    ``joint_placements[j]`` (4x4, m), ``joint_parents[j]`` and ``joint_motion[j]`` (``(kind, unit axis)``, kind
    ``"fixed"`` for the universe joint 0, ``"revolute"`` or ``"prismatic"``) for each of the model's joints;
    ``frame_names``, ``frame_parents`` (joint index) and ``frame_placements`` (4x4, m) for each body frame
    (link) but the universe; ``joint_names`` of the moving joints and their limits ``lower``/``upper`` (rad or
    m) and ``velocity`` (rad/s or m/s).
    """

    __slots__ = ("name", "joint_names", "lower", "upper", "velocity", "joint_placements", "joint_parents",
                 "joint_motion", "frame_names", "frame_parents", "frame_placements")  # fmt: skip

    def __init__(self, *, name, joint_names, lower, upper, velocity, joint_placements, joint_parents, joint_motion,
                 frame_names, frame_parents, frame_placements):  # fmt: skip
        self.name: str = str(name)
        self.joint_names: tuple[str, ...] = tuple(joint_names)
        self.lower = np.array(lower, dtype=float)
        self.upper = np.array(upper, dtype=float)
        self.velocity = np.array(velocity, dtype=float)
        self.joint_placements: list[np.ndarray] = [np.array(M, dtype=float) for M in joint_placements]
        self.joint_parents: list[int] = [int(p) for p in joint_parents]
        self.joint_motion: list[tuple[str, np.ndarray]] = [(str(k), np.array(a, dtype=float)) for k, a in joint_motion]
        self.frame_names: tuple[str, ...] = tuple(frame_names)
        self.frame_parents = np.array(frame_parents, dtype=int)
        self.frame_placements = np.array(frame_placements, dtype=float).reshape(-1, 4, 4)

    @classmethod
    def of_model(cls, model, path: Path | str) -> "KinematicTables":
        """The tables of Pinocchio ``model`` (read from the URDF at ``path``, which errors name)."""
        import pinocchio as pin

        if model.nq != model.nv:
            raise RobotModelError(f"{path}: spherical, planar or floating joints are not supported")
        motion: list[tuple[str, np.ndarray]] = [("fixed", np.zeros(3))]
        for j in range(1, model.njoints):
            short = model.joints[j].shortname()
            if short not in _MOTIONS:
                raise RobotModelError(f"{path}: joint {model.names[j]!r} of type {short} is not supported")
            kind, axis = _MOTIONS[short]
            motion.append((kind, np.eye(3)[axis] if axis is not None else np.array(model.joints[j].extract().axis)))
        body = [f for f in model.frames if f.type == pin.FrameType.BODY and f.name != "universe"]
        return cls(
            name=model.name,
            joint_names=model.names[1:],
            lower=model.lowerPositionLimit,
            upper=model.upperPositionLimit,
            velocity=model.velocityLimit,
            joint_placements=[model.jointPlacements[j].homogeneous for j in range(model.njoints)],
            joint_parents=[model.parents[j] for j in range(model.njoints)],
            joint_motion=motion,
            frame_names=[f.name for f in body],
            frame_parents=[f.parentJoint for f in body],
            frame_placements=[f.placement.homogeneous for f in body],
        )

    def to_json(self, digest: str) -> str:
        """The tables as JSON, keyed by ``digest`` (:func:`urdf_digest` of the text they were read from)."""
        stored = {
            "format": _FORMAT,
            "urdf_sha256": digest,
            "name": self.name,
            "joint_names": list(self.joint_names),
            "lower": self.lower.tolist(),
            "upper": self.upper.tolist(),
            "velocity": self.velocity.tolist(),
            "joint_placements": [M.tolist() for M in self.joint_placements],
            "joint_parents": self.joint_parents,
            "joint_motion": [[kind, axis.tolist()] for kind, axis in self.joint_motion],
            "frame_names": list(self.frame_names),
            "frame_parents": self.frame_parents.tolist(),
            "frame_placements": self.frame_placements.tolist(),
        }
        return json.dumps(stored, indent=1) + "\n"


def pinocchio_urdf(path: Path | str, root: ET.Element) -> str:
    """The text Pinocchio is given for the URDF tree ``root`` (read from ``path``): ``continuous`` joints as
    revolute +-:data:`CONTINUOUS_LIMIT_RAD`, and only the ``<link>`` and ``<joint>`` elements."""
    root = copy.deepcopy(root)
    for joint in [j for j in root.iter("joint") if j.get("type") == "continuous"]:
        # a continuous joint has no position limits; Pinocchio would model it as (cos, sin), which a
        # planner over joint angles cannot use, and one turn either way is all any plan needs
        joint.set("type", "revolute")
        limit = joint.find("limit")
        if limit is None:
            raise RobotModelError(f"{path}: continuous joint {joint.get('name')!r} needs <limit velocity=... effort=...>")
        limit.set("lower", repr(-CONTINUOUS_LIMIT_RAD))
        limit.set("upper", repr(CONTINUOUS_LIMIT_RAD))
    for element in [e for e in root if e.tag not in ("link", "joint")]:
        root.remove(element)  # robocritics' own elements (<gripper>), transmissions, plugins: not Pinocchio's
    return ET.tostring(root, encoding="unicode")


def build_model(text: str, path: Path):
    """The Pinocchio model of the URDF ``text`` (:func:`pinocchio_urdf` of the file at ``path``)."""
    import pinocchio as pin

    try:
        return pin.buildModelFromXML(text)
    except (RuntimeError, ValueError, OSError, MemoryError) as exc:
        raise RobotModelError(f"cannot load URDF {str(path)!r}: {exc}") from None


class PinocchioModel:
    """The Pinocchio model of one URDF text, built on first use and shared by the copies of a robot."""

    __slots__ = ("text", "path", "_model")

    def __init__(self, text: str, path: Path, model=None):
        self.text, self.path, self._model = text, path, model

    @property
    def model(self):
        if self._model is None:
            self._model = build_model(self.text, self.path)
        return self._model


def urdf_digest(text: str) -> str:
    """SHA-256 (hex) of the URDF ``text`` given to Pinocchio: what a stored copy of its tables is keyed by."""
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def stored_tables(file, text: str) -> KinematicTables | None:
    """The tables stored in ``file`` (a path or an ``importlib.resources`` file) if they were read by Pinocchio
    from exactly ``text`` (:func:`pinocchio_urdf`); None when there is no such file or it is of another text."""
    try:
        stored = json.loads(file.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(stored, dict) or stored.get("format") != _FORMAT or stored.get("urdf_sha256") != urdf_digest(text):
        return None
    del stored["format"], stored["urdf_sha256"]
    return KinematicTables(**stored)


def _quaternion(angle: float, axis: int) -> tuple[float, float, float, float]:
    """Eigen's quaternion ``(x, y, z, w)`` of the rotation by ``angle`` rad about the unit axis ``axis`` (0-2)."""
    half = 0.5 * angle
    s = math.sin(half)
    # sin(half) times the unit axis, as Eigen does: s * 0.0 is -0.0 for a negative s
    x, y, z = (s * (1.0 if k == axis else 0.0) for k in range(3))
    return (x, y, z, math.cos(half))


def _quaternion_product(a, b) -> tuple[float, float, float, float]:
    """The quaternion product ``a b`` (each ``(x, y, z, w)``) as Eigen's SSE2 kernel for doubles groups its sums
    (``quat_product`` in Eigen's Geometry_SIMD.h): the textbook order gives other signs of zero."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        (aw * bx + ay * bz) - (az * by - ax * bw),
        (aw * by + ay * bw) + (az * bx - ax * bz),
        (aw * bz - ay * bx) + (az * bw + ax * by),
        (aw * bw - ay * by) - (az * bz + ax * bx),
    )


def pinocchio_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """The rotation ``Rz(yaw) Ry(pitch) Rx(roll)`` (angles in rad) of a URDF ``rpy``, 3x3, as
    ``pinocchio.rpy.rpyToMatrix`` computes it: the product of the three axis quaternions, then Eigen's
    quaternion-to-matrix formula."""
    x, y, z, w = _quaternion_product(_quaternion_product(_quaternion(yaw, 2), _quaternion(pitch, 1)), _quaternion(roll, 0))
    tx, ty, tz = 2.0 * x, 2.0 * y, 2.0 * z
    twx, twy, twz = tx * w, ty * w, tz * w
    txx, txy, txz = tx * x, ty * x, tz * x
    tyy, tyz, tzz = ty * y, tz * y, tz * z
    return np.array([
        [1.0 - (tyy + tzz), txy - twz, txz + twy],
        [txy + twz, 1.0 - (txx + tzz), tyz - twx],
        [txz - twy, tyz + twx, 1.0 - (txx + tyy)],
    ])  # fmt: skip


def _rotation_product(A, B) -> tuple:
    """The 3x3 product ``A B`` (nested sequences of floats) summed in Eigen's order for a fixed-size 3x3 double
    product: rows 0 and 1 as one SSE packet (left to right), row 2 alone (its last two terms first). Written
    out on Python floats: one call, no per-entry function call (the planner makes one pose per move)."""
    (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = A
    (b00, b01, b02), (b10, b11, b12), (b20, b21, b22) = B
    return (
        ((a00 * b00 + a01 * b10) + a02 * b20, (a00 * b01 + a01 * b11) + a02 * b21, (a00 * b02 + a01 * b12) + a02 * b22),
        ((a10 * b00 + a11 * b10) + a12 * b20, (a10 * b01 + a11 * b11) + a12 * b21, (a10 * b02 + a11 * b12) + a12 * b22),
        (a20 * b00 + (a21 * b10 + a22 * b20), a20 * b01 + (a21 * b11 + a22 * b21), a20 * b02 + (a21 * b12 + a22 * b22)),
    )  # fmt: skip


def _rotate(A, v) -> tuple[float, float, float]:
    """``A v`` for a 3x3 ``A`` and a 3-vector ``v``, in :func:`_rotation_product`'s order."""
    (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = A
    v0, v1, v2 = v
    return (a00 * v0 + a01 * v1) + a02 * v2, (a10 * v0 + a11 * v1) + a12 * v2, a20 * v0 + (a21 * v1 + a22 * v2)


def pinocchio_frame_pose(joint_placements, joint_parents, frame_parent: int, frame_placement: np.ndarray, q) -> np.ndarray:
    """The pose (4x4, m) of one frame (on joint ``frame_parent`` at ``frame_placement``) at joint angles ``q``
    (rad), as Pinocchio's ``forwardKinematics`` and ``updateFramePlacement`` compute it, for a chain whose joints
    all revolve about their z axis: ``oMi[j] = oMi[parent(j)] (M_j Rz(q_j))``, then ``oMf = oMi[j] F``."""
    chain, j = [], frame_parent
    while j > 0:
        chain.append(j)
        j = joint_parents[j]
    R, p = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], [0.0, 0.0, 0.0]
    for depth, j in enumerate(reversed(chain)):
        c, s = math.cos(q[j - 1]), math.sin(q[j - 1])
        M = joint_placements[j]
        local = _rotation_product(M[:3, :3].tolist(), [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        if depth == 0:  # the base joint's parent is the universe (identity): oMi is its local placement
            R, p = local, M[:3, 3].tolist()
        else:
            x, y, z = _rotate(R, M[:3, 3].tolist())
            p = [p[0] + x, p[1] + y, p[2] + z]
            R = _rotation_product(R, local)
    x, y, z = _rotate(R, frame_placement[:3, 3].tolist())
    p = [p[0] + x, p[1] + y, p[2] + z]
    pose = np.eye(4)
    pose[:3, :3] = _rotation_product(R, frame_placement[:3, :3].tolist())
    pose[:3, 3] = p
    return pose


def rotation_angle(R: np.ndarray) -> float:
    """The angle (rad, 0 to pi) of rotation ``R`` (3x3): the norm of ``log3(R)``, from its sine and its cosine
    (``atan2``), accurate near 0 and near pi alike."""
    sine = 0.5 * math.hypot(R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1])
    return math.atan2(sine, 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0))


def bundled_text(name: str) -> tuple[Path, str]:
    """The path of bundled arm ``name``'s URDF and the text Pinocchio is given for it."""
    from .urdf import check_numbers, read_urdf

    urdf = Path(__file__).resolve().parent / "models" / f"{name}.urdf"
    doc = read_urdf(urdf)
    check_numbers(doc)
    return urdf, pinocchio_urdf(urdf, doc.root)


def write_bundled() -> list[Path]:
    """Write the stored tables of every bundled arm from what Pinocchio reads from its URDF now; the paths."""
    import pinocchio as pin

    from .arms import BUNDLED_ARM_NAMES

    written = []
    for name in BUNDLED_ARM_NAMES:
        urdf, text = bundled_text(name)
        tables = KinematicTables.of_model(pin.buildModelFromXML(text), urdf)
        out = urdf.with_name(f"{name}.tables.json")
        out.write_text(tables.to_json(urdf_digest(text)), encoding="utf-8")
        written.append(out)
    return written


if __name__ == "__main__":
    for path in write_bundled():
        print(path)
