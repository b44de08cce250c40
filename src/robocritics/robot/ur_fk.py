"""Forward kinematics of a UR-like DH chain in closed form, on Python floats: the closed-form IK's check.

Units: m, rad, base frame. With the UR structure (``alpha = (pi/2, 0, 0, pi/2, -pi/2, 0)``, ``a_1 = a_4 = a_5 =
a_6 = 0``; see :class:`~robocritics.robot.arms.DH`) the product ``T_06 = A_1 ... A_6`` of
``A_i = Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i)`` collapses to a few vectors. Joints 2, 3 and 4 turn about the same
axis ``z_1 = (s_1, -c_1, 0)`` (``c_i = cos q_i``, ``s_i = sin q_i``, ``q_23 = q_2 + q_3``, ``q_234 = q_23 + q_4``);
with ``u = (c_234 c_1, c_234 s_1, s_234)`` and ``v = (-s_234 c_1, -s_234 s_1, c_234)``::

    x_5 = c_5 u + s_5 z_1,        z_6 = c_5 z_1 - s_5 u,
    x_6 = c_6 x_5 + s_6 v,        y_6 = c_6 v - s_6 x_5,
    p   = (0, 0, d_1) + (a_2 c_2 + a_3 c_23) (c_1, s_1, 0) + (0, 0, a_2 s_2 + a_3 s_23)
          + (d_2 + d_3 + d_4) z_1 - d_5 v + d_6 z_6

(``d_2``, ``d_3`` and ``d_4`` all translate along ``z_1``, so only their sum matters). Twelve sines and cosines and
some sixty products: a third of the CPU of a Pinocchio ``forwardKinematics`` called from Python, with the same
floats to rounding (``tests/test_ur_fk.py`` compares the two).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = ["ur_flange_pose12", "ur_pose_errors", "ur_reproduces"]


def ur_flange_pose12(k: Sequence[float], q: Sequence[float]) -> list[float]:
    """The flange pose ``T_06(q)`` as its top three rows, row-major (12 floats: rotation, position in m).

    ``k`` the closed form's constants (``DH._ur``: d1, a2, a3, d2 + d3 + d4, d5, d6, ...), ``q`` 6 joint angles (rad).
    """
    d1, a2, a3, d4, d5, d6 = k[0], k[1], k[2], k[3], k[4], k[5]
    q1, q2, q3, q4, q5, q6 = q
    cos, sin = math.cos, math.sin
    c1, s1 = cos(q1), sin(q1)
    q23 = q2 + q3
    q234 = q23 + q4
    c234, s234 = cos(q234), sin(q234)
    c5, s5 = cos(q5), sin(q5)
    c6, s6 = cos(q6), sin(q6)
    ux, uy = c234 * c1, c234 * s1
    vx, vy = -s234 * c1, -s234 * s1
    x5x, x5y, x5z = c5 * ux + s5 * s1, c5 * uy - s5 * c1, c5 * s234
    zx, zy, zz = c5 * s1 - s5 * ux, -c5 * c1 - s5 * uy, -s5 * s234
    reach = a2 * cos(q2) + a3 * cos(q23)
    return [
        c6 * x5x + s6 * vx, c6 * vx - s6 * x5x, zx, reach * c1 + d4 * s1 - d5 * vx + d6 * zx,
        c6 * x5y + s6 * vy, c6 * vy - s6 * x5y, zy, reach * s1 - d4 * c1 - d5 * vy + d6 * zy,
        c6 * x5z + s6 * c234, c6 * c234 - s6 * x5z, zz, d1 + a2 * sin(q2) + a3 * sin(q23) - d5 * c234 + d6 * zz,
    ]  # fmt: skip


def ur_pose_errors(k: Sequence[float], q: Sequence[float], t: Sequence[float]) -> tuple[float, float]:
    """(position error m, rotation error rad) of the flange at ``q`` (rad) against the 12-float target ``t``
    (row-major top rows of a pose): ``|p - p_t|`` and ``||R - R_t||_F / sqrt(2)`` (``2 sin(theta / 2)`` for a
    rotation by ``theta`` between them), as :func:`robocritics.robot.ik._pose_error`."""
    f = ur_flange_pose12(k, q)
    e3, e7, e11 = f[3] - t[3], f[7] - t[7], f[11] - t[11]
    dp = math.sqrt(e3 * e3 + e7 * e7 + e11 * e11)
    e0, e1, e2, e4, e5, e6 = f[0] - t[0], f[1] - t[1], f[2] - t[2], f[4] - t[4], f[5] - t[5], f[6] - t[6]
    e8, e9, e10 = f[8] - t[8], f[9] - t[9], f[10] - t[10]
    sq = 0.0 + e0 * e0 + e1 * e1 + e2 * e2 + e4 * e4 + e5 * e5 + e6 * e6 + e8 * e8 + e9 * e9 + e10 * e10
    return dp, math.sqrt(0.5 * sq)


def ur_reproduces(k: Sequence[float], q: Sequence[float], t: Sequence[float], tol: float) -> bool:
    """Whether the flange at ``q`` (rad) is within ``tol`` m and ``tol`` rad of the 12-float target ``t``:
    :func:`ur_pose_errors` both within ``tol`` (NaN never is)."""
    position_m, rotation_rad = ur_pose_errors(k, q, t)
    return position_m <= tol and rotation_rad <= tol
