"""A UR-shaped chain recognised in a URDF, so that a vendor file of a UR arm gets the closed-form IK. m, rad.

A UR arm's kinematics is the standard-DH chain of :meth:`~robocritics.robot.arms.DH.ur` (``d = (d1, 0, 0, d4,
d5, d6)``, ``a = (0, a2, a3, 0, 0, 0)``, ``alpha = (pi/2, 0, 0, pi/2, -pi/2, 0)``). A URDF of one (ROS's
``ur_description``, shipped by example-robot-data) describes the same chain in other frames: its base link is
turned 180 deg about z against UR's DH base, and its flange frame may differ from DH frame 6 by a fixed turn.
So the URDF's flange pose is ``F(q) = B D(q) C``, with ``D`` the DH flange pose, ``B`` the DH base in the URDF
base frame and ``C`` the URDF flange in DH frame 6. :func:`recognise_ur_chain` reads all of it from the joint
axes at ``q = 0`` (the URDF's zero must be the DH zero, as it is in every UR description):

* ``B``: origin at the base origin's foot on joint 1's axis, ``z0`` along joint 1's axis; ``alpha1 = pi/2``
  makes joint 2's axis ``z1 = -y0``, so ``y0`` is minus joint 2's axis and ``x0 = y0 x z0``;
* ``d1 = (p2 - o0) . z0`` (``p_j`` a point of joint j's axis), ``O1 = o0 + d1 z0``;
* ``a2 = (p3 - O1) . x0``, ``a3 = (p4 - O1) . x0 - a2`` (joints 2-4 are parallel, frames 1-3 lie in one plane);
* ``d4 = (p5 - O1) . z1`` (joint 5's axis is perpendicular to ``z1``), ``O4 = O1 + (a2 + a3) x0 + d4 z1``;
* ``d5 = (p6 - O4) . z4`` with ``z4`` joint 5's axis, ``O5 = O4 + d5 z4``; ``d6 = (f - O5) . z5`` with ``f``
  the flange origin and ``z5`` joint 6's axis; ``C = D(0)^-1 B^-1 F(0)``.

The result is accepted only when ``B D(q) C`` is the URDF's flange (within
:data:`~robocritics.robot.model.DH_TOLERANCE_M`, m and rad) at spread-out configurations: any other arm, or a
UR file whose zeros or axis signs differ, keeps numeric IK.
"""

from __future__ import annotations

import numpy as np

__all__ = ["UrChain", "check_dh", "recognise_ur_chain"]

#: Configurations (rad) the recognised chain is compared with the URDF at (clipped to the limits).
_CHECKS = np.array([
    [0.3, -1.2, 1.1, -0.7, 0.9, 0.4],
    [-2.1, -0.4, -1.9, 2.2, -1.3, 2.7],
    [1.0, 0.8, 0.5, 1.5, 2.0, -1.0],
    [2.5, -2.0, 2.4, -2.6, 0.3, -2.9],
])


class UrChain:
    """A recognised UR chain: ``dh`` (:class:`~robocritics.robot.arms.DH`), ``base`` (4x4, the DH base in the
    robot's base frame) and ``flange_in_dh`` (4x4, the URDF flange ``tip`` in DH frame 6)."""

    def __init__(self, dh, base: np.ndarray, flange_in_dh: np.ndarray, tip: str):
        self.dh, self.base, self.flange_in_dh, self.tip = dh, base, flange_in_dh, tip


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def recognise_ur_chain(robot, tip: str, tolerance: float) -> UrChain | None:
    """The UR chain of ``robot`` (a :class:`~robocritics.robot.model.Robot` of six revolute joints) with its
    flange at the link ``tip``, or None when the URDF is not one within ``tolerance`` (m and rad)."""
    import pinocchio as pin

    from .arms import DH
    from .kinematic_tables import rotation_angle

    model = robot.model
    if robot.n != 6 or model.njoints != 7 or any(robot._joint_motion[j][0] != "revolute" for j in range(1, 7)):
        return None
    data = model.createData()
    pin.forwardKinematics(model, data, np.zeros(6))
    points = [None] + [data.oMi[j].translation.copy() for j in range(1, 7)]
    axes = [None] + [data.oMi[j].rotation @ _unit(np.asarray(robot._joint_motion[j][1], float)) for j in range(1, 7)]
    z0, z1 = axes[1], axes[2]
    if abs(z0 @ z1) > 1e-6:
        return None
    flange0 = robot.forward(np.zeros(6))[robot.frame_names.index(tip)]
    origin = points[1] + ((np.zeros(3) - points[1]) @ z0) * z0  # the base origin's foot on joint 1's axis
    y0 = -z1
    x0 = np.cross(y0, z0)
    base = np.eye(4)
    base[:3, :3] = np.column_stack([x0, y0, z0])
    base[:3, 3] = origin
    d1 = (points[2] - origin) @ z0
    o1 = origin + d1 * z0
    a2 = (points[3] - o1) @ x0
    a3 = (points[4] - o1) @ x0 - a2
    d4 = (points[5] - o1) @ z1
    o4 = o1 + (a2 + a3) * x0 + d4 * z1
    d5 = (points[6] - o4) @ axes[5]
    o5 = o4 + d5 * axes[5]
    d6 = (flange0[:3, 3] - o5) @ axes[6]
    if min(abs(a2), abs(a3)) < 1e-6:
        return None
    dh = DH.ur(float(d1), float(a2), float(a3), float(d4), float(d5), float(d6), name=f"{robot.name} (from its URDF)")
    flange_in_dh = np.linalg.inv(np.array(dh.flange_pose(np.zeros(6)))) @ np.linalg.inv(base) @ flange0
    checks = np.clip(_CHECKS, robot.lower, robot.upper)
    urdf = robot.forward(checks)[:, robot.frame_names.index(tip)]
    for q, pose in zip(checks, urdf):
        chain = base @ np.array(dh.flange_pose(q)) @ flange_in_dh
        if np.linalg.norm(chain[:3, 3] - pose[:3, 3]) > tolerance or rotation_angle(chain[:3, :3].T @ pose[:3, :3]) > tolerance:
            return None
    return UrChain(dh, base, flange_in_dh, tip)


def check_dh(robot, dh, tolerance: float) -> None:
    """Refuse ``dh`` (given to the :class:`~robocritics.robot.model.Robot` constructor) unless the URDF's ``tool0``
    is the DH flange (within ``tolerance`` m and rad) at a spread of configurations: a URDF in another base
    convention (ROS's UR description turns the base 180 deg about z) would otherwise get IK solutions for the
    wrong arm. Raises :class:`~robocritics.errors.RobotModelError` naming the worst configuration."""
    from ..errors import RobotModelError
    from .kinematic_tables import rotation_angle

    flange = robot._check_link("tool0", "the flange that dh= describes")
    if robot.n != 6:
        raise RobotModelError(f"{robot.urdf_path}: dh= describes 6 joints, the URDF has {robot.n}")
    # zero, home-like and two off-axis configurations: each length and each twist shows in one of them
    checks = np.array([
        np.zeros(6),
        [0.3, -1.2, 1.1, -0.7, 0.9, 0.4],
        [-2.1, -0.4, -1.9, 2.2, -1.3, 2.7],
        [1.0, 0.8, 0.5, 1.5, 2.0, -1.0],
    ])
    checks = np.clip(checks, robot.lower, robot.upper)
    # accepted on the tables Pinocchio read (the FK tests/test_fk_fast.py checks against it; a tolerance of
    # 1e-6 m and rad is far above their difference from Pinocchio's); a refusal names the configuration that
    # Pinocchio's own FK and log3 find worst, as it always has
    frames = robot.forward(checks)[:, flange]
    if all(
        np.linalg.norm(urdf[:3, 3] - table[:3, 3]) <= tolerance
        and rotation_angle(urdf[:3, :3].T @ table[:3, :3]) <= tolerance
        for urdf, table in zip(frames, (np.array(dh.flange_pose(q)) for q in checks))
    ):
        return
    import pinocchio as pin

    from .ik import dh_forward

    worst_m, worst_rad, worst_q = 0.0, 0.0, checks[0]
    flange_id = int(robot.model.getFrameId("tool0", pin.FrameType.BODY))
    for q in checks:
        table = dh_forward(dh, q)
        pin.framesForwardKinematics(robot.model, robot.data, q)
        urdf = robot.data.oMf[flange_id].homogeneous
        dp = float(np.linalg.norm(urdf[:3, 3] - table[:3, 3]))
        dr = float(np.linalg.norm(pin.log3(urdf[:3, :3].T @ table[:3, :3])))
        if max(dp, dr) > max(worst_m, worst_rad):
            worst_m, worst_rad, worst_q = dp, dr, q
    if worst_m > tolerance or worst_rad > tolerance:
        raise RobotModelError(
            f"{robot.urdf_path}: the URDF's tool0 does not follow dh={getattr(dh, 'name', dh)!r}: at q = "
            f"[{', '.join(f'{v:.2f}' for v in worst_q)}] rad it is {worst_m:.4f} m and {worst_rad:.4f} rad from "
            "the DH flange. Check the base convention (ROS UR descriptions turn base_link 180 deg about z "
            "against UR's DH base) and the joint zero offsets, or load it without dh= (numeric IK)"
        )
