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
  primitive), a ``<sphere>`` as a capsule of zero length; :meth:`Robot.from_urdf`
  encloses a vendor file's ``<mesh>`` and ``<box>`` geometry in fitted capsules
  (:mod:`robocritics.robot.fit`, :mod:`robocritics.robot.vendor`). The two
  finger capsules are declared at full opening and slide along the tcp y axis
  with the gripper opening.
* ``continuous`` joints are read as revolute joints limited to +-2 pi rad (one
  full turn either way, what a UR joint allows too).
* ``dh=`` is cross-checked against the URDF at load: the ``tool0`` (flange)
  frame of the URDF must be the DH chain's flange in several configurations.

The whole contract is in docs/robots.md.

Forward kinematics over a whole trajectory is vectorised: with ``oMi`` the joint
placements, ``oMi[j] = oMi[parent(j)] @ M_j @ X_j(q_j)`` where ``M_j`` is the
joint's fixed placement and ``X_j`` its motion (a rotation about, or translation
along, its axis). Every rotation column and origin is a ``(3, T)`` time series
(structure of arrays), so each product over all ``T`` samples is a few element-wise
multiply-adds; the capsule endpoints come from the same pass
(:meth:`Robot.forward_with_capsules`).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import cached_property
from importlib import resources
from pathlib import Path

import numpy as np

from ..errors import PlanningError, RobotModelError
from ..trajectory import RobotLimits
from .kinematic_tables import (
    CONTINUOUS_LIMIT_RAD,  # noqa: F401 - re-exported: where it lived before
    KinematicTables,
    PinocchioModel,
    build_model,
    pinocchio_frame_pose,
    pinocchio_rpy,
    pinocchio_urdf,
    stored_tables,
)
from .approach import approach_rotation, fingers_down

__all__ = ["Robot", "Capsule", "fingers_down", "DH_TOLERANCE_M", "default_robot", "default_workspace"]


@dataclass(frozen=True)
class Capsule:
    """A collision capsule: segment ``p0``-``p1`` (m, in the frame ``frame``) and ``radius_m``."""

    name: str
    frame: str
    group: str  # "arm" or "gripper"
    p0: tuple[float, float, float]
    p1: tuple[float, float, float]
    radius_m: float


def _read_only(values) -> np.ndarray:
    """An own float copy of ``values`` that cannot be written in place (robots share nothing mutable)."""
    arr = np.array(values, dtype=float)
    arr.flags.writeable = False
    return arr


#: Joint angles this far outside a limit [rad] are rounding (IK, a controller's reading), not a violation.
LIMIT_TOLERANCE_RAD = 1e-9

#: Largest flange position difference [m] (and rotation difference [rad]) between a URDF and the ``dh=``
#: given with it, over the check configurations, before the robot is refused.
DH_TOLERANCE_M = 1e-6

# Capsule pairs closer than this (m) with the arm stretched out (q = 0) are parts of one
# housing (the compact UR wrist, base and shoulder column), not a pinch point to check.
_SAME_HOUSING_GAP_M = 0.06


# A rotation in structure-of-arrays form is the tuple of its three columns, each ``(3, T)``: row i of column k
# is the time series of the entry (i, k), contiguous, so every product below is element-wise work on whole
# time series (no BLAS: OpenBLAS goes multi-threaded above ~8k samples and then costs 3-10x the CPU on a
# loaded 2-core machine). A column or origin constant over time is ``(3, 1)`` and broadcasts; an origin
# that is zero is ``None``. Results may alias their inputs: none of these arrays is ever written in place.
_Columns = tuple[np.ndarray, np.ndarray, np.ndarray]

#: The base (universe) frame: identity rotation as constant columns, origin zero.
_IDENTITY_COLUMNS: _Columns = tuple(_read_only(np.eye(3)[:, k : k + 1]) for k in range(3))  # type: ignore[assignment]


def _combine(columns: _Columns, weights: np.ndarray) -> np.ndarray | None:
    """``sum_m weights[m] * columns[m]``: a rotation ``[c0 c1 c2]`` (each ``(3, T)``) times the constant
    3-vector ``weights``, i.e. ``R @ w`` per sample; ``None`` when ``weights`` is zero.

    Exact zero weights are skipped and a lone weight of +-1 is the column itself (or its negation): the
    placements of URDF joints and links are mostly signed permutations, so most products are free, and
    the result equals the full sum (adding a product with 0 changes no value, multiplying by 1 neither).
    """
    total = None
    for w, col in zip(weights.tolist(), columns):
        if w == 0.0:
            continue
        if total is None:
            total = col if w == 1.0 else (np.negative(col) if w == -1.0 else col * w)
        else:
            total = total + col * w
    return total


def _add(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray | None:
    """``a + b`` where ``None`` is zero."""
    if a is None:
        return b
    return a if b is None else a + b


def _times_rotation(columns: _Columns, placement: np.ndarray) -> _Columns:
    """The columns of ``R @ placement[:3, :3]`` for a constant rotation ``placement``."""
    out = tuple(_combine(columns, placement[:3, k]) for k in range(3))
    if any(col is None for col in out):
        raise RobotModelError("a joint or link placement has a zero rotation column")
    return out  # type: ignore[return-value]


def _axis_rotations(q: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Rotations by angles ``q (T,)`` rad about the ``axis`` (any length), entry-major ``(3, 3, T)``:
    ``X = I + sin q K + (1 - cos q) K^2`` (Rodrigues), ``K`` the cross-product matrix of the unit axis."""
    k = axis / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    s, c = np.sin(q), np.cos(q)
    return np.eye(3)[:, :, None] + s * K[:, :, None] + (1 - c) * (K @ K)[:, :, None]


def _times_axis_rotations(columns: _Columns, X: np.ndarray) -> _Columns:
    """The columns of ``R_t @ X_t`` for per-sample rotations ``X (3, 3, T)``: column k is ``sum_m R[:, m] X[m, k]``."""
    return tuple(columns[0] * X[0, k] + columns[1] * X[1, k] + columns[2] * X[2, k] for k in range(3))  # type: ignore[return-value]


#: Samples per block when :func:`_frames_array` lays frames out per sample: both (16 L, block) buffers stay in
#: cache (1,500-3,000 measured best here). Not a power of two: the transposing copy reads all 16 L rows of the
#: block at once, and rows a power of two bytes apart share cache sets (2,048 was 5x slower than 2,000).
_FRAME_BLOCK = 2000


def _frames_array(poses: list[tuple[_Columns, np.ndarray | None]], T: int) -> np.ndarray:
    """The ``(T, L, 4, 4)`` homogeneous transforms of frame poses given as ``(columns, origin)`` time series."""
    # per block of samples: every entry as a contiguous time series (cheap row copies), then one transposing
    # copy into the block's rows of the output; 2-3x less CPU than writing each column straight into the
    # (T, L, 4, 4) array, which makes a pass over T rows 16 L entries apart per column
    L = len(poses)
    frames = np.empty((T, L * 16))
    block = max(1, min(T, _FRAME_BLOCK))  # T = 0: no blocks, an empty array
    series = np.empty((L, 4, 4, block))
    series[:, 3, :3] = 0.0
    series[:, 3, 3] = 1.0
    for start in range(0, T, block):
        stop = min(T, start + block)
        n = stop - start
        for f, (columns, origin) in enumerate(poses):
            for k, column in enumerate(columns):
                series[f, :3, k, :n] = column if column.shape[1] == 1 else column[:, start:stop]
            series[f, :3, 3, :n] = 0.0 if origin is None else (origin if origin.shape[1] == 1 else origin[:, start:stop])
        frames[start:stop] = series.reshape(L * 16, block)[:, :n].T
    return frames.reshape(T, L, 4, 4)


class Robot:
    """Kinematic and collision model of an arm with a two-finger gripper.

    Use :meth:`ur3e` for the bundled UR3e, or :meth:`from_urdf` for other arms.

    A robot's facts are immutable: its arrays (``lower``, ``upper``, the
    velocity/acceleration/jerk limits, ``home_q``, ...) are read-only and its
    pair lists are tuples, so robots can share them. To change the home pose,
    assign a new one (``robot.home_q = q``, checked against the limits); that
    changes this robot only. The Pinocchio ``model`` is shared between copies
    and must be treated as read-only; ``data`` is each robot's own scratch space.
    Both are made on first use: kinematics run on the tables Pinocchio reads from
    the URDF (:mod:`robocritics.robot.kinematic_tables`; for a bundled arm their
    stored copy), so a check with a bundled arm does not load Pinocchio.
    """

    #: Tilts of the fingers from straight down (rad, :mod:`robocritics.robot.approach`) the planner approaches at,
    #: the next where a target is out of reach at the current one: fingers down for the bundled arms.
    approach_tilts_rad: tuple[float, ...] = (0.0,)
    #: +1 / -1 when the first joint's axis is +z / -z, 0 when not vertical: how home turns to face a target.
    base_turn_sign: float = 1.0
    #: The fingers' yaw per rad of the last joint, fingers down (rad/rad): -1 on the UR arms and the Panda
    #: (the flange's z points down), +1 when it points up, 0 when the last joint is not the roll.
    wrist_yaw_per_rad: float = -1.0
    #: The inverse of the DH base's pose (4x4) in the robot's base frame, when ``dh`` was recognised in a vendor
    #: file whose base is not the DH base (:mod:`robocritics.robot.dh_chain`); None: the same frame.
    dh_base_inverse: np.ndarray | None = None

    def __init__(
        self,
        urdf_path: str | Path,
        *,
        tcp_frame: str = "tcp",
        name: str | None = None,
        dh=None,
        reach_m: float | None = None,
        acceleration_limits: np.ndarray | None = None,
        jerk_limits: np.ndarray | None = None,
        home: np.ndarray | None = None,
        self_pairs: list[tuple[str, str]] | None = None,
        fixed_links: tuple[str, ...] = ("base_link", "shoulder_link"),
        urdf_root: ET.Element | None = None,
        stored_tables_file=None,
    ):
        # stored_tables_file: a bundled arm's stored copy of what Pinocchio reads from this URDF
        # (robocritics.robot.kinematic_tables), used only if it was written from this very text
        self.urdf_path = Path(urdf_path)
        if urdf_root is None:
            urdf_root = _read_checked(self.urdf_path)
        text = pinocchio_urdf(self.urdf_path, urdf_root)
        tables = None if stored_tables_file is None else stored_tables(stored_tables_file, text)
        model = None
        if tables is None:
            model = build_model(text, self.urdf_path)
            tables = KinematicTables.of_model(model, self.urdf_path)
        self._pinocchio = PinocchioModel(text, self.urdf_path, model)
        self.name = name or tables.name
        self.dh = dh
        self.joint_names = tables.joint_names
        self.n = len(self.joint_names)
        self.lower = _read_only(tables.lower)
        self.upper = _read_only(tables.upper)
        self.velocity_limits = _read_only(tables.velocity)
        if np.any(self.velocity_limits <= 0):
            raise RobotModelError(f"{self.urdf_path}: every joint needs a positive <limit velocity=...>")
        # URDF has no acceleration or jerk limits. Unless given (robot/arms.py has the UR3e's):
        # 1.6 x the speed limit per second, reached in a 0.1 s jerk ramp
        self.acceleration_limits = _read_only(
            acceleration_limits if acceleration_limits is not None else 1.6 * self.velocity_limits
        )
        self.jerk_limits = _read_only(jerk_limits if jerk_limits is not None else 10.0 * self.acceleration_limits)
        self.tcp_frame = tcp_frame
        self.frame_names = tables.frame_names
        self._frame_index = {n: i for i, n in enumerate(self.frame_names)}
        self._check_link(tcp_frame, "the TCP")
        self._parse_urdf_extras(urdf_root)
        # per capsule, the piece of its link's collision mesh it encloses (robot.fit.Mesh, link frame), measured
        # instead of the capsule near contact (geometry.link_meshes); None: the capsule is the geometry itself
        self.capsule_meshes: tuple = (None,) * len(self.capsules)
        self.link_meshes: dict = {}  # link name -> its whole collision mesh (link frame), for containment tests
        self.fixed_links = tuple(fixed_links)
        self._build_fk_tables(tables)
        if dh is not None:
            self._check_dh(dh)
        self._set_reach(reach_m)
        self.home_q = home if home is not None else np.clip(np.zeros(self.n), self.lower, self.upper)
        self.self_pairs: tuple[tuple[str, str], ...] = (
            self._default_self_pairs(None) if self_pairs is None else tuple((str(a), str(b)) for a, b in self_pairs)
        )

    # --- construction -----------------------------------------------------------------

    @classmethod
    def ur3e(cls) -> "Robot":
        """The bundled UR3e (e-series DH) with a Robotiq 2F-85-sized gripper; TCP at the fingertips.

        Each call returns an independent robot (the URDF is parsed once and its
        immutable parts shared).
        """
        return _bundled("ur3e").copy()

    @classmethod
    def ur5e(cls) -> "Robot":
        """The bundled UR5e (e-series DH, 850 mm reach), same gripper and TCP as :meth:`ur3e`."""
        return _bundled("ur5e").copy()

    @classmethod
    def ur10e(cls) -> "Robot":
        """The bundled UR10e (e-series DH, 1300 mm reach), same gripper and TCP as :meth:`ur3e`."""
        return _bundled("ur10e").copy()

    @classmethod
    def ur16e(cls) -> "Robot":
        """The bundled UR16e (e-series DH, 900 mm reach), same gripper and TCP as :meth:`ur3e`."""
        return _bundled("ur16e").copy()

    @classmethod
    def panda(cls) -> "Robot":
        """The bundled Franka Emika Panda (7 joints, Franka's published kinematics and limits) with the
        Franka Hand; TCP at the fingertips, same TCP convention as the UR arms.

        IK is numeric (damped least squares). The one redundant degree of freedom is settled by the
        seed: the planner seeds every target with the home posture turned to face it
        (``Planner.posture_seed``), so the elbow stays up and out as at home and the fingers down.
        """
        return _bundled("panda").copy()

    @classmethod
    def bundled(cls, name: str) -> "Robot":
        """A bundled arm by name (:data:`~robocritics.robot.arms.BUNDLED_ARM_NAMES`): a UR e-series arm or the Panda."""
        return cls.panda() if name == "panda" else cls.ur(name)

    @classmethod
    def ur(cls, name: str) -> "Robot":
        """A bundled UR e-series arm by name: ``"ur3e"``, ``"ur5e"``, ``"ur10e"`` or ``"ur16e"``."""
        from .arms import ARMS

        if name not in ARMS:
            raise RobotModelError(
                f"no bundled UR arm {name!r}; the bundled UR arms are {', '.join(ARMS)} (and Robot.panda())"
            )
        return _bundled(name).copy()

    @classmethod
    def from_urdf(
        cls,
        path: str | Path,
        tcp_frame: str = "tcp",
        *,
        tool=None,
        tip: str | None = None,
        base_pose=None,
        home_q=None,
        reach_m: float | None = None,
        fixed_links=None,
        joint_limits: dict | None = None,
        name: str | None = None,
        package_paths=(),
        approach_tilts_rad=None,
        **kwargs,
    ) -> "Robot":
        """Load an arm from a URDF as its vendor ships it (docs/robots.md, "Bring your own arm").

        Meshes (STL, DAE, OBJ; ``package://``, ``file://`` or relative paths, searched in the file's own package,
        its directory, ``package_paths`` and ``ROS_PACKAGE_PATH``) and boxes are enclosed by fitted capsules
        (:mod:`robocritics.robot.fit`, with a tested error bound), the fast path; near contact the link's own
        mesh is measured (``capsule_meshes``, :mod:`robocritics.geometry.link_meshes`). Foreign-namespace
        attributes are ignored.

        ``tool``: a bundled tool name (:data:`robocritics.robot.tools.TOOLS`: ``"robotiq_2f85"``,
        ``"robotiq_hande"``, ``"franka_hand"``, ``"none"``), a tool URDF path, or None: the file's own
        robocritics ``<gripper>`` if it has one, else ``"none"``. ``tip``: the flange link the tool mounts on
        (default: inferred; required where the chain branches, e.g. a vendor hand's finger joints).
        ``base_pose``: where the base stands in the world (4x4, or ``(x, y, z[, roll, pitch, yaw])`` m, rad).
        ``home_q`` (rad), ``reach_m`` (m), ``fixed_links`` (links whose table distance is not reported):
        inferred unless given (a collision-free home inside the limits; the farthest sampled flange distance
        from the shoulder; the links whose height no joint changes). ``joint_limits``: ``{joint: (lower,
        upper)}`` or ``(lower, upper, velocity)`` overrides (rad or m, rad/s or m/s), applied before the
        file's limits are checked. ``approach_tilts_rad``: the tilts of the fingers from straight down (rad,
        one or several in [0, pi/2]) the planner approaches targets at, the first by default (inferred: the
        least that reaches a tabletop pick, then larger ones; :mod:`robocritics.robot.approach`). Other keywords as for the constructor (``dh=``, ``acceleration_limits=``,
        ``jerk_limits=``, ``self_pairs=``; ``home=`` is ``home_q``). Raises :class:`RobotModelError` naming
        the element, joint or link and the line.
        """
        from .vendor import arm_tree, infer

        path = Path(path)
        home_q = kwargs.pop("home", home_q)
        tree, facts = arm_tree(
            path, tool=tool, tip=tip, base_pose=base_pose, joint_limits=joint_limits,
            package_paths=tuple(Path(p) for p in package_paths), name=name, tcp_frame=tcp_frame,
        )
        self_pairs = kwargs.pop("self_pairs", None)
        robot = cls(path, tcp_frame=tcp_frame, name=name or tree.get("name"), reach_m=1.0,
                    urdf_root=tree, self_pairs=self_pairs or [], **kwargs)
        robot.tip_frame = facts["tip"]
        robot.tool_name = facts["tool"]
        robot.capsule_slack_m = _read_only([facts["slack_m"].get(c.name, 0.0) for c in robot.capsules])
        # a finger's capsule slides with the opening and its link frame does not: fingers stay capsules
        robot.capsule_meshes = tuple(None if c.frame in robot.finger_links else facts["mesh"].get(c.name) for c in robot.capsules)
        robot.link_meshes = dict(facts["link_mesh"])
        if robot.dh is None:
            robot._use_ur_chain(facts["tip"])
        infer(robot, tip=facts["tip"], reach_m=reach_m, home_q=home_q, fixed_links=fixed_links,
              approach_tilts_rad=approach_tilts_rad)
        if self_pairs is not None:
            robot.self_pairs = tuple((str(a), str(b)) for a, b in self_pairs)
        return robot

    def copy(self) -> "Robot":
        """An independent robot: the immutable facts (and the Pinocchio model) are shared, Pinocchio ``data``
        is its own."""
        other = object.__new__(Robot)
        other.__dict__.update(self.__dict__)
        other.__dict__.pop("_data", None)
        return other

    @property
    def model(self):
        """The Pinocchio model of the URDF (read-only; shared by copies), built on first use."""
        return self._pinocchio.model

    @property
    def data(self):
        """This robot's own Pinocchio ``data`` (scratch space for :attr:`model`), made on first use."""
        data = self.__dict__.get("_data")
        if data is None:
            data = self.__dict__["_data"] = self.model.createData()
        return data

    @cached_property
    def _tcp_frame_id(self) -> int:
        """Pinocchio's id of the TCP link in :attr:`model` (looked up once: a line's IK asks at every point)."""
        import pinocchio as pin

        return int(self.model.getFrameId(self.tcp_frame, pin.FrameType.BODY))

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
                shown = f"{v:.4f}" if abs(v) < 1e6 else f"{v:.4g}"  # 1e308 from a controller: not 310 digits
                raise error(
                    f"{what} joint {j} ({self.joint_names[j]}) = {shown} rad is outside its limits "
                    f"[{lo:.4f}, {hi:.4f}] rad"
                )
        return vector

    def _parse_urdf_extras(self, root: ET.Element) -> None:
        """Capsules (numbers already checked by :func:`~robocritics.robot.urdf.check_numbers`) and the gripper."""
        capsules: list[Capsule] = []
        gripper = root.find("gripper")
        finger_links = gripper.get("fingers", "").split() if gripper is not None else []
        self.max_opening_m = float(gripper.get("max_opening", "0.085")) if gripper is not None else 0.0
        if not (math.isfinite(self.max_opening_m) and 0 <= self.max_opening_m <= 1.0):
            raise RobotModelError(f"{self.urdf_path}: <gripper max_opening> must be 0-1 m, got {self.max_opening_m!r}")
        self.finger_links = tuple(finger_links)
        # the gripper's links are the tool's (its <gripper links=...>); robocritics' own files name them
        gripper_links = set(gripper.get("links", "gripper_body").split()) | set(finger_links) if gripper is not None else set()
        for link in root.findall("link"):
            lname = link.get("name")
            for k, col in enumerate(link.findall("collision")):
                cyl = col.find("geometry/cylinder")
                sphere = col.find("geometry/sphere")
                if cyl is None and sphere is None:
                    shapes = [g.tag for g in col.findall("geometry/*")] or ["no geometry"]
                    detail = "".join(f" filename={g.get('filename')!r}" for g in col.findall("geometry/mesh"))
                    raise RobotModelError(
                        f"{self.urdf_path}: link {lname!r} has a <{shapes[0]}>{detail} collision; a robocritics "
                        "model file needs capsules (<cylinder>s and <sphere>s): load the vendor file with "
                        "Robot.from_urdf, which fits capsules to meshes (see docs/robots.md)"
                    )
                origin = col.find("origin")
                xyz = np.array([float(v) for v in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()])
                rpy = [float(v) for v in (origin.get("rpy", "0 0 0") if origin is not None else "0 0 0").split()]
                axis = pinocchio_rpy(*rpy)[:, 2]
                half = float(cyl.get("length")) / 2 if cyl is not None else 0.0
                shape = cyl if cyl is not None else sphere
                suffix = f"#{k}" if k else ""
                capsules.append(
                    Capsule(
                        name=f"{lname}{suffix}",
                        frame=lname,
                        group="gripper" if lname in gripper_links else "arm",
                        p0=tuple(xyz - half * axis),
                        p1=tuple(xyz + half * axis),
                        radius_m=float(shape.get("radius")),
                    )
                )
        if not capsules:
            raise RobotModelError(
                f"{self.urdf_path}: no collision geometry (<cylinder>, <sphere>, <box> or <mesh>) on the arm's links; "
                "see docs/robots.md, 'Collision geometry'"
            )
        self.capsules = tuple(capsules)

    def _build_fk_tables(self, tables: KinematicTables) -> None:
        self._joint_placements = tables.joint_placements
        self._joint_parents = tables.joint_parents
        self._joint_motion: list[tuple[str, np.ndarray]] = tables.joint_motion
        self._frame_parent = tables.frame_parents
        self._frame_placement = tables.frame_placements
        self.tcp_index = self._frame_index[self.tcp_frame]
        # the TCP pose of one configuration in Pinocchio's own arithmetic, without Pinocchio, when every joint
        # from the base to the TCP revolves about its z axis (every bundled arm; see pinocchio_frame_pose)
        chain, j = [], int(self._frame_parent[self.tcp_index])
        while j > 0:
            chain.append(self._joint_motion[j])
            j = self._joint_parents[j]
        self._tcp_chain_about_z = all(kind == "revolute" and axis.tolist() == [0.0, 0.0, 1.0] for kind, axis in chain)
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

    def _check_link(self, name: str, role: str) -> int:
        """The index in :attr:`frame_names` of the link ``name`` (``role`` says what it is for in the error)."""
        if name not in self._frame_index:
            raise RobotModelError(f"{self.urdf_path}: no link {name!r} for {role}; links are " + ", ".join(self.frame_names))
        return self._frame_index[name]

    def _set_reach(self, reach_m: float | None) -> None:
        """``shoulder_m``: the origin of the second joint at q = 0 (on the base axis for UR-like arms);
        ``reach_m``: given, else the TCP's distance from it along the stretched-out chain (an upper bound)."""
        frames = self.forward(np.zeros(self.n))
        njoints = len(self._joint_placements)
        joint_origins = [None] * njoints
        for j in range(1, njoints):
            parent = self._joint_parents[j]
            base = np.eye(4) if parent == 0 else joint_origins[parent]
            joint_origins[j] = base @ self._joint_placements[j]  # q = 0: no joint motion
        shoulder = joint_origins[min(2, njoints - 1)][:3, 3]
        self.shoulder_m = _read_only(shoulder)
        if reach_m is None:
            # stretched out: the sum of the joint-to-joint steps from the shoulder to the TCP
            chain, j = [frames[self.tcp_index][:3, 3]], int(self._frame_parent[self.tcp_index])
            while j >= 2:
                chain.append(joint_origins[j][:3, 3])
                j = self._joint_parents[j]
            reach_m = float(sum(np.linalg.norm(a - b) for a, b in zip(chain, chain[1:])))
        if not (math.isfinite(reach_m) and reach_m > 0):
            raise RobotModelError(f"{self.urdf_path}: reach_m must be a positive length in m, got {reach_m!r}")
        self.reach_m = float(reach_m)

    @property
    def workspace(self):
        """The default allowed workspace for this robot: a :class:`~robocritics.scene.Workspace` sphere of
        radius ``reach_m`` around the shoulder (for the UR3e exactly :func:`default_workspace`)."""
        from ..scene import Workspace

        return Workspace(center=tuple(float(v) for v in self.shoulder_m), radius_m=self.reach_m)

    def scene_for(self, scene):
        """``scene`` with this robot's :attr:`workspace` unless the scene gives its own ``workspace``."""
        if scene.workspace is not None:
            return scene
        return scene.model_copy(update={"workspace": self.workspace})

    def _check_dh(self, dh) -> None:
        """Refuse ``dh`` unless the URDF's ``tool0`` is its flange (:func:`~robocritics.robot.dh_chain.check_dh`)."""
        from .dh_chain import check_dh

        check_dh(self, dh, DH_TOLERANCE_M)

    def _use_ur_chain(self, tip: str) -> None:
        """Closed-form IK when the URDF is a UR chain with its flange at ``tip`` (:mod:`.dh_chain`): ``dh``, the
        DH base and the TCP in DH frame 6 (``tcp_in_flange``) set from it; else nothing changes (numeric IK)."""
        from .dh_chain import recognise_ur_chain

        chain = recognise_ur_chain(self, tip, DH_TOLERANCE_M)
        if chain is None:
            return
        fk = self._forward_static(np.zeros(self.n))
        tcp_in_flange = chain.flange_in_dh @ np.linalg.inv(fk[self._frame_index[tip]]) @ fk[self.tcp_index]
        self.dh, self.dh_base_inverse = chain.dh, _read_only(np.linalg.inv(chain.base))
        self.tcp_in_flange, self._flange_in_tcp = _read_only(tcp_in_flange), _read_only(np.linalg.inv(tcp_in_flange))

    def _forward_static(self, q: np.ndarray) -> np.ndarray:
        return self.forward(q[None, :])[0]

    @cached_property
    def kinematic_hash(self) -> str:
        """A hash of what the joint angles mean: the flange pose (``tool0``, else the tip the tool mounts on,
        else the TCP) in the base frame at four fixed configurations (clipped to the limits), rounded to 1 um
        and 1 urad. Two models with the same chain and base convention share it whatever their names and link
        frames; a ROS-convention UR (base turned 180 deg) or other lengths do not. The deploy gate keys on it."""
        import hashlib

        flange = "tool0" if "tool0" in self._frame_index else getattr(self, "tip_frame", None) or self.tcp_frame
        index = self._frame_index[flange]
        pattern = np.array([0.0, 0.3, -1.2, 1.1, -0.7, 0.9, 0.4, -0.5, 0.8])
        probes = [np.zeros(self.n)] + [np.roll(pattern, k)[: self.n] * (1 + 0.5 * k) for k in range(3)]
        h = hashlib.sha256(f"{self.n}:".encode())
        for q in probes:
            pose = self._forward_static(np.clip(q, self.lower, self.upper))[index]
            h.update(np.round(pose[:3, :4], 6).astype("<f8").tobytes() + b";")
        return h.hexdigest()[:16]

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
        poses = self._frame_poses(q[None, :] if single else q, gripper_opening_m)
        frames = _frames_array(poses, q.shape[0] if not single else 1)
        return frames[0] if single else frames

    def forward_with_capsules(
        self, q: np.ndarray, gripper_opening_m: np.ndarray | float | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(frames, p0, p1)``: :meth:`forward` and :meth:`capsule_segments` of its frames, in one pass.

        ``q`` is ``(T, n)`` rad; ``frames`` ``(T, L, 4, 4)``, ``p0``/``p1`` ``(T, C, 3)`` m in the base frame
        (each a view of a ``(3, C, T)`` array: one contiguous time series per coordinate and capsule, the
        layout the proximity kernel works in). The endpoints come from the frame poses while they are still
        time series, with no second read of ``frames``.
        """
        q = np.asarray(q, dtype=float)
        poses = self._frame_poses(q, gripper_opening_m)
        p0, p1 = self._capsule_ends(poses, q.shape[0])
        return _frames_array(poses, q.shape[0]), p0, p1

    def _frame_poses(
        self, q: np.ndarray, gripper_opening_m: np.ndarray | float | None
    ) -> list[tuple[_Columns, np.ndarray | None]]:
        """Every body frame's pose for samples ``q (T, n)`` rad, as ``(columns, origin)`` time series.

        With ``oMi`` the joint placements, ``oMi[j] = oMi[parent(j)] @ M_j @ X_j(q_j)``, ``M_j`` the joint's
        fixed placement and ``X_j`` its motion: a rotation about, or a translation along, its axis. A rotation
        about +z (every UR and Panda joint) mixes two columns: ``c0' = c0 cos q + c1 sin q``,
        ``c1' = c1 cos q - c0 sin q``. Frame ``f`` on joint ``j`` is ``oMi[j] @ F_f``. Columns are ``(3, T)``
        (``(3, 1)`` when constant), origins ``(3, T)`` m (or ``(3, 1)``, or ``None`` for the base origin).
        """
        if q.ndim != 2 or q.shape[1] != self.n:
            raise RobotModelError(f"q must have shape (T, {self.n}), got {q.shape}")
        T = q.shape[0]
        joints: list[tuple[_Columns, np.ndarray | None]] = [(_IDENTITY_COLUMNS, None)]
        for j in range(1, len(self._joint_placements)):
            kind, axis = self._joint_motion[j]
            columns, origin = joints[self._joint_parents[j]]
            M = self._joint_placements[j]
            origin = _add(_combine(columns, M[:3, 3]), origin)
            columns = _times_rotation(columns, M)
            qj = q[:, j - 1]
            if kind != "revolute":
                step = _combine(columns, axis)
                origin = _add(origin, None if step is None else step * qj)
            elif axis[0] == 0.0 and axis[1] == 0.0 and axis[2] > 0.0:
                c, s = np.cos(qj), np.sin(qj)
                x, y, z = columns
                x_new = x * c
                x_new += y * s
                y_new = y * c
                y_new -= x * s
                columns = (x_new, y_new, z)
            else:
                columns = _times_axis_rotations(columns, _axis_rotations(qj, axis))
            joints.append((columns, origin))
        frames: list[tuple[_Columns, np.ndarray | None]] = []
        for parent, F in zip(self._frame_parent.tolist(), self._frame_placement):
            columns, origin = joints[parent]
            frames.append((_times_rotation(columns, F), _add(_combine(columns, F[:3, 3]), origin)))
        if self.finger_links and gripper_opening_m is not None:
            # each finger slides (max_opening - opening) / 2 m inwards along the tcp y axis
            shift = (self.max_opening_m - np.broadcast_to(np.asarray(gripper_opening_m, float), (T,))) / 2
            y_axis = frames[self.tcp_index][0][1]
            for sign, link in zip((1.0, -1.0), self.finger_links):
                f = self._frame_index[link]
                columns, origin = frames[f]
                slide = (sign * shift) * y_axis
                frames[f] = (columns, np.negative(slide) if origin is None else origin - slide)
        return frames

    def _capsule_ends(self, poses: list[tuple[_Columns, np.ndarray | None]], T: int) -> tuple[np.ndarray, np.ndarray]:
        """Capsule endpoints ``p = R x + t`` (m, base frame) of every capsule from its frame's pose ``(R, t)``
        in ``poses`` (:meth:`_frame_poses`); ``(T, C, 3)`` views of ``(3, C, T)`` arrays."""
        C = len(self.capsules)
        ends = np.empty((2, 3, C, T))
        for c, f in enumerate(self._capsule_frame.tolist()):
            columns, origin = poses[f]
            for e, local in enumerate((self._capsule_p0[c], self._capsule_p1[c])):
                point = _add(_combine(columns, local), origin)
                ends[e, :, c] = 0.0 if point is None else point
        return ends[0].transpose(2, 1, 0), ends[1].transpose(2, 1, 0)

    def tcp_pose(self, q: np.ndarray) -> np.ndarray:
        """TCP pose(s) ``(4, 4)`` or ``(T, 4, 4)`` for ``q``."""
        q = np.asarray(q, dtype=float)
        if q.shape == (self.n,):
            # one configuration: Pinocchio's own products (far cheaper than the batched path), without loading it
            # where its arithmetic is replicated bit for bit
            if self._tcp_chain_about_z:
                frame = self.tcp_index
                return pinocchio_frame_pose(
                    self._joint_placements, self._joint_parents, int(self._frame_parent[frame]), self._frame_placement[frame], q
                )
            import pinocchio as pin

            pin.forwardKinematics(self.model, self.data, q)
            return pin.updateFramePlacement(self.model, self.data, self._tcp_frame_id).homogeneous.copy()
        frames = self.forward(q)
        return frames[..., self.tcp_index, :, :]

    def capsule_segments(self, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Capsule endpoints ``(T, C, 3)`` each, m in the base frame, from ``frames (T, L, 4, 4)``.

        ``p = R x + t`` with ``[R t]`` the pose of the capsule's frame and ``x`` the endpoint in it. The
        results are views of ``(3, C, T)`` arrays (see :meth:`forward_with_capsules`).
        """
        frames = np.asarray(frames, dtype=float)
        T = frames.shape[0]
        used = sorted(set(self._capsule_frame.tolist()))
        # the capsule frames' [R t] as time series (F, 3, 4, T), one gather; other frames are never read
        series = np.ascontiguousarray(frames[:, used, :3, :].transpose(1, 2, 3, 0))
        poses: list = [None] * len(self.frame_names)
        for f, pose in zip(used, series):
            poses[f] = ((pose[:, 0], pose[:, 1], pose[:, 2]), pose[:, 3])
        return self._capsule_ends(poses, T)

    def trajectory(self, q: np.ndarray, time: np.ndarray, scene, **kwargs):
        """The :class:`~robocritics.trajectory.Trajectory` of joint samples ``q`` at ``time`` in ``scene``.

        See :func:`robocritics.planning.trace.build_trajectory` for the optional arguments.
        """
        from ..planning.trace import build_trajectory

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
        tilt_rad: float = 0.0,
        restarts: int = 20,
    ) -> np.ndarray:
        """Joint angles (rad) that put the TCP at ``position`` (m) with ``orientation``.

        ``orientation`` is a 3x3 rotation of the tcp frame (default: fingers straight
        down, turned by ``yaw_rad``, and leaning ``tilt_rad`` outwards from the shoulder:
        :func:`~robocritics.robot.approach.approach_rotation`). Among all solutions within the joint limits
        the one nearest ``seed`` (default: the home pose) is returned. An arm with fewer than six joints
        cannot choose the yaw as well, and a tilted approach (``tilt_rad`` > 0) does not ask it to: the finger axis
        is as asked and the turn about it what the wrist allows nearest the seed
        (:func:`~robocritics.robot.ik_numeric.pointing_ik`). UR arms use
        closed-form IK (all 8 branches); others Pinocchio damped least squares.
        ``restarts``: how many more attempts numeric IK makes after the seed's (the first four near it).
        Raises :class:`PlanningError` naming the target and why.
        """
        from . import ik as _ik

        p = np.asarray(position, dtype=float).reshape(3)
        if not np.all(np.isfinite(p)):
            raise PlanningError(f"target {p.tolist()} is not a finite position")
        R = approach_rotation(p, yaw_rad, tilt_rad, self.shoulder_m) if orientation is None else np.asarray(orientation, float)
        target = np.eye(4)
        target[:3, :3], target[:3, 3] = R, p
        seed = self.home_q if seed is None else np.asarray(seed, float)
        try:
            if orientation is None and (self.n < 6 or tilt_rad != 0.0):
                # fewer than six joints cannot also choose the yaw, and a tilted approach leaves it to the
                # wrist: the finger axis as asked, turned about it as the wrist allows nearest the seed
                from .ik_numeric import pointing_ik

                if self.n < 6 and tilt_rad != 0.0:  # its wrist leans in its own plane, not the shoulder's
                    return pointing_ik(self.model, self.data, self._tcp_frame_id, p, (0.0, 0.0, -1.0), seed,
                                       self.lower, self.upper, cone_rad=tilt_rad, restarts=restarts)
                return pointing_ik(self.model, self.data, self._tcp_frame_id, p, R[:, 2], seed, self.lower, self.upper,
                                   restarts=restarts)
            if self.dh is not None and self.tcp_in_flange is not None:
                flange = target @ self._flange_in_tcp
                if self.dh_base_inverse is not None:  # a vendor file's UR chain (robot.dh_chain): in its DH base
                    flange = self.dh_base_inverse @ flange
                return _ik.ur_ik(self.dh, flange, seed, self.lower, self.upper)
            from .ik_numeric import numeric_ik

            return numeric_ik(self.model, self.data, self._tcp_frame_id, target, seed, self.lower, self.upper,
                              restarts=restarts)
        except PlanningError as exc:
            pose = "in the requested orientation" if orientation is not None else (
                "with the fingers down" if tilt_rad == 0.0 else f"with the fingers {math.degrees(tilt_rad):.0f} deg from down")
            raise PlanningError(
                f"cannot put the TCP at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m {pose}: {exc.reason}"
            ) from None

    def ik_line(self, positions, seed: np.ndarray | None = None, *, yaw_rad: float = 0.0,
                tilt_rad=0.0) -> tuple[np.ndarray, PlanningError | None]:
        """:meth:`ik` with the fingers down (turned by ``yaw_rad``, tilted by ``tilt_rad``: one tilt, or one per
        position) at each of ``positions`` ``(n, 3)`` m in turn,
        each seeded by the previous solution (the first by ``seed``, default the home pose).

        Returns ``(q (m, 6) rad, error)``: row ``i`` is what ``ik(positions[i], seed=q[i - 1], yaw_rad=yaw_rad)``
        returns; ``m = n`` and ``error`` None when every position is solved, else the ``m`` solved rows and the
        :class:`PlanningError` :meth:`ik` raises for position ``m``. For UR arms the closed form runs without
        the per-call conversions (one stacked matmul for the flange poses); other arms track each point from the
        last (:func:`~robocritics.robot.ik_track.track_line`: :meth:`ik`'s solution to its solver tolerances,
        a few Newton steps instead of its general search).
        """
        from . import ik as _ik

        p = np.asarray(positions, dtype=float).reshape(-1, 3)
        seed = self.home_q if seed is None else np.asarray(seed, float)
        tilts = np.broadcast_to(np.asarray(tilt_rad, float), (len(p),))
        if self.dh is None or self.tcp_in_flange is None or tilts.any():
            from .ik_track import track_line  # each point tracked from the last, else solved by ik()

            return track_line(self, p, seed, yaw_rad, tilts)
        finite = np.isfinite(p).all(axis=1)
        n_ok = len(p) if finite.all() else int(np.argmin(finite))
        target = np.empty((n_ok, 4, 4))
        target[:] = np.eye(4)
        target[:, :3, :3], target[:, :3, 3] = fingers_down(yaw_rad), p[:n_ok]
        # the same per-pose products as ik()'s ``target @ self._flange_in_tcp`` (matmul per stacked slice)
        flanges = target @ self._flange_in_tcp
        if self.dh_base_inverse is not None:
            flanges = self.dh_base_inverse @ flanges
        q, exc = _ik.ur_ik_line(self.dh, flanges, seed, self.lower, self.upper)
        if exc is None and n_ok < len(p):
            exc = PlanningError(f"target {p[n_ok].tolist()} is not a finite position")
        elif exc is not None:
            x, y, z = p[len(q)]
            pose = "with the fingers down"
            exc = PlanningError(f"cannot put the TCP at ({x:.3f}, {y:.3f}, {z:.3f}) m {pose}: {exc.reason}")
        return q, exc

    # --- self-collision pairs ---------------------------------------------------------

    def _default_self_pairs(self, q: np.ndarray | None) -> tuple[tuple[str, str], ...]:
        """Capsule pairs checked for pinch points.

        Adjacent links (sharing a joint) are never pairs. Beyond that we drop the
        pairs that are close *by construction*: those closer than
        ``_SAME_HOUSING_GAP_M`` (0.06 m) at ``q`` (default: zeros clipped to the limits;
        a URDF loaded with :meth:`from_urdf` uses its home pose) with the links
        stretched out, i.e. parts of one housing (the compact UR wrist, base and
        shoulder column). What remains are non-adjacent arm links and arm links
        against the gripper, the pairs that can close on a hand.
        """
        from ..geometry.kernels import capsule_capsule

        parent_of = dict(zip(self.frame_names, self._frame_parent.tolist()))
        parents = self._joint_parents
        q = np.clip(np.zeros(self.n), self.lower, self.upper) if q is None else np.asarray(q, float)
        frames = self.forward(q[None, :])
        p0, p1 = self.capsule_segments(frames)
        candidates = []
        C = len(self.capsules)
        for i in range(C):
            for j in range(i + 1, C):
                ci, cj = self.capsules[i], self.capsules[j]
                if ci.group == "gripper" and cj.group == "gripper":
                    continue
                ji, jj = parent_of[ci.frame], parent_of[cj.frame]
                if ji == jj or parents[ji] == jj or parents[jj] == ji:
                    continue
                candidates.append((i, j))
        if not candidates:
            return ()
        # every candidate pair in one call (element-wise, so each distance is what a call per pair gives)
        i, j = np.array(candidates).T
        d = capsule_capsule(p0[0, i], p1[0, i], self.capsule_radii[i], p0[0, j], p1[0, j], self.capsule_radii[j])
        return tuple(
            (self.capsules[a].name, self.capsules[b].name) for (a, b), gap in zip(candidates, d) if not gap < _SAME_HOUSING_GAP_M
        )

    def __repr__(self) -> str:
        return f"Robot({self.name!r}, {self.n} joints, tcp={self.tcp_frame!r}, {len(self.capsules)} capsules)"


_BUNDLED: dict[str, Robot] = {}


def _panda() -> Robot:
    from .arms import PANDA, UR3E

    models = resources.files("robocritics.robot") / "models"
    robot = Robot(
        str(models / "panda.urdf"),
        stored_tables_file=models / "panda.tables.json",
        tcp_frame="tcp",
        name=PANDA.name,
        reach_m=PANDA.reach_m,
        acceleration_limits=np.array(PANDA.acceleration_rad_s2),
        jerk_limits=np.array(PANDA.jerk_rad_s3),
        fixed_links=("link0", "link1"),
    )
    # home: in front of the base and above the table, fingers down, as the UR arms' (scaled by reach),
    # reached from Franka's "ready" posture (elbow up, forearm folded, hand down)
    scale = PANDA.reach_m / UR3E.reach_m
    ready = np.array([0.0, -math.pi / 4, 0.0, -3 * math.pi / 4, 0.0, math.pi / 2, math.pi / 4])
    robot.home_q = robot.ik((0.25 * scale, 0.0, 0.25 * scale), seed=ready)
    return robot


def _read_checked(path: Path) -> ET.Element:
    """The root of the URDF at ``path``, read within robocritics' bounds with every number checked."""
    from .urdf import check_numbers, read_urdf

    doc = read_urdf(path)
    check_numbers(doc)
    return doc.root


def default_robot() -> Robot:
    """The arm a run uses when none is given: :data:`robocritics.robot.arms.DEFAULT_ARM` (the UR3e), a fresh copy."""
    from .arms import DEFAULT_ARM

    return _bundled(DEFAULT_ARM.name).copy()


def default_workspace():
    """The allowed workspace of a scene that gives none, judged without a robot: the reach sphere of
    :data:`~robocritics.robot.arms.DEFAULT_ARM` around its shoulder (what ``default_robot().workspace`` is,
    without loading the model)."""
    from ..scene import Workspace
    from .arms import DEFAULT_ARM

    return Workspace(center=(0.0, 0.0, DEFAULT_ARM.dh.d1), radius_m=DEFAULT_ARM.reach_m)


def _bundled(name: str) -> Robot:
    """The bundled arm ``name`` (a UR e-series arm or ``"panda"``), parsed once (callers copy it)."""
    robot = _BUNDLED.get(name)
    if robot is None and name == "panda":
        robot = _BUNDLED[name] = _panda()
    if robot is None:
        from .arms import ARMS, UR3E
        from .ik import ur_reach

        spec = ARMS[name]
        models = resources.files("robocritics.robot") / "models"
        robot = Robot(
            str(models / f"{name}.urdf"),
            stored_tables_file=models / f"{name}.tables.json",
            tcp_frame="tcp",
            name=spec.name,
            dh=spec.dh,
            reach_m=spec.reach_m,
            acceleration_limits=np.array(spec.acceleration_rad_s2),
            jerk_limits=np.array(spec.jerk_rad_s3),
        )
        # home: TCP in front of the base and above the table, fingers down, elbow up; 0.25 m and 0.25 m on
        # the UR3e, scaled by reach on the larger arms
        # (ur_reach grids 200k wrist angles, ~7 ms on first use: the UR3e's own ratio is 1 without it)
        scale = 1.0 if spec.dh == UR3E.dh else ur_reach(spec.dh) / ur_reach(UR3E.dh)
        upright = np.array([math.pi, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0])
        robot.home_q = robot.ik((0.25 * scale, 0.0, 0.25 * scale), seed=upright)
        _BUNDLED[name] = robot
    return robot
