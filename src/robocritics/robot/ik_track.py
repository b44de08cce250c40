"""Tracking IK: the solution nearest a seed that is itself the solution of a nearby target (the previous point of
a straight line), by Newton steps on its optimality conditions. rad, m.

:func:`robocritics.robot.ik_numeric.numeric_ik` is general (any seed: restarts, branches, a descent along the
self-motion of a redundant arm) and costs tens of Pinocchio calls per solve. A straight line is solved every
few millimetres, each point seeded by the previous one's solution, so the nearest solution is a small step away
and one problem answers it (``delta = q - seed``):

    minimise  |delta|²   subject to   f(q) = target,   lower <= q <= upper,

the joints at a limit pinned there (the active set ``P``, the others free ``F``). Its Newton step at ``q``
linearises ``f`` (``J`` the constraint Jacobian, ``e`` the error ``target - f(q)``, both in the world frame) and
solves the linear problem exactly: the free joints move to

    delta_F' = J_Fᵀ y,   (J_F J_Fᵀ) y = e + J_F delta_F,

the least-norm offset from the seed whose linearised error is zero. With as many free joints as constraints it
is Newton's step; with more (a 7-joint arm) the offset also ends orthogonal to the self-motion (the null space of
``J_F``): the first-order condition of the nearest solution. A joint the step would take past a limit is
clamped there and pinned; a pinned joint whose multiplier says the optimum lies inside
(``(J_Pᵀ y)_i`` on the inner side of ``delta_i``) is freed again. From a seed a few millimetres away, two to four
steps reach the tolerance.

So the solution is the one :func:`numeric_ik` approximates from the same seed (its damped descent, then its
slide along the self-motion towards the seed), to the solver tolerances: its descent stops where a step brings
the arm less than 1e-12 rad nearer, about 1e-7 rad from the optimum at worst. Where the steps do not settle this
quickly, a joint would move more than ``max_move_rad``, or a pinned set leaves fewer free joints than
constraints, these functions return None and the caller solves the point with :func:`numeric_ik` (the general
solver decides). ``tests/test_ik_track.py`` checks them against :func:`numeric_ik` (hypothesis).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import eigenpy
import numpy as np
import pinocchio as pin

from ..errors import PlanningError
from .approach import approach_rotation

__all__ = ["track_line", "track_pose", "track_pointing", "TRACK_MAX_MOVE_RAD"]

#: The most a joint may move from the seed in a tracking solve [rad]; beyond, the general solver decides.
TRACK_MAX_MOVE_RAD = 0.5
#: Restarts of the general solver for a line's point after its first: the four near the seed
#: (:func:`~robocritics.robot.ik_numeric.numeric_ik`); a solution from anywhere else is a joint jump.
LINE_RESTARTS = 4
#: Newton steps before a tracking solve gives up (the general solver then decides).
_MAX_STEPS = 12
#: A converged iterate whose next step moves no joint more than this [rad] is the optimum (the step is the
#: distance to it, to first order).
_STEP_TOL_RAD = 1e-12
#: A converged iterate reached by a step of at most this [rad] is the optimum: the distance left is the next
#: step's, which shrinks by a factor of the order of ``|q - seed|`` (rad: the constraint's curvature times the
#: multipliers; quadratic with as many joints as constraints). Measured on the vendor arms' lines (5 mm apart):
#: 1e-3 to 1e-2, so at most ~1e-8 rad is left (the general solver stops ~1e-7 from it). A converged iterate whose next step is this small is stepped
#: to without evaluating the error there: the step zeroes the linearised error, so what is left is the
#: second-order term, about ``|d²f/dq²| s²`` <= 1e-12 (m, rad; the arm's reach times ``s²``), inside ``tol``.
_QUADRATIC_RAD = 1e-6
#: The longest Newton step [rad, any joint]: a longer one is shortened to this along its direction. A step this
#: long comes only from a start far from the solution (IK from a posture seed; a line's points are millimetres
#: apart), where a full step can overshoot across a near-singular shoulder and oscillate (the xArm7 did).
_TRUST_RAD = 0.25
#: At most this last step [rad] after the steps run out still counts as settled (rounding in ``J_F J_Fᵀ``).
_SETTLED_RAD = 1e-9

#: ``residual(q) -> (e, J, position error m, rotation error rad)`` of a tracking problem at ``q``.
Residual = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, float, float]]


def _solve(A: np.ndarray, b: np.ndarray, spd: bool) -> np.ndarray | None:
    """``A⁻¹ b`` for a small ``A`` (Cholesky where ``spd``: ``J_F J_Fᵀ``; else LU with partial pivoting), or
    None where ``A`` is singular or the result is not finite (the caller's general solver decides). Eigen's
    decompositions through eigenpy (Pinocchio's own binding): numpy's ``linalg.solve`` costs about three
    times as much on 6x6 systems, mostly its per-call checks, and a line solves one system per point."""
    x = (eigenpy.LLT(A) if spd else eigenpy.PartialPivLU(A)).solve(b)
    return x if math.isfinite(float(x.dot(x))) else None


def _kkt_step(J: np.ndarray, e: np.ndarray, q: np.ndarray, seed: np.ndarray,
              pinned: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None] | None:
    """The module docstring's linearised step from ``q``: ``(new q, multipliers y or None)``, None where there
    is no step (fewer free joints than constraints, a singular system)."""
    if pinned is None:
        if J.shape[0] == J.shape[1]:  # as many joints as constraints: Newton's step
            dq = _solve(J, e, spd=False)
            return None if dq is None else (q + dq, None)
        y = _solve(J.dot(J.T), e + J.dot(q - seed), spd=True)
        return None if y is None else (seed + J.T.dot(y), y)
    free = ~pinned
    Jf = J[:, free]
    if Jf.shape[1] < Jf.shape[0]:
        return None  # fewer free joints than constraints: no exact solution with these joints pinned
    y = _solve(Jf.dot(Jf.T), e + Jf.dot(q[free] - seed[free]), spd=True)
    if y is None:
        return None
    new = q.copy()
    new[free] = seed[free] + Jf.T.dot(y)
    return new, y


def _nearest_kkt(residual: Residual, seed: np.ndarray, lo: np.ndarray, hi: np.ndarray, tol: float,
                 max_move_rad: float, guess: np.ndarray | None, max_steps: int = _MAX_STEPS) -> np.ndarray | None:
    """The active-set Newton iteration of the module docstring from ``guess`` (default ``seed``; both within
    ``[lo, hi]``), the offsets measured from ``seed``; None where it does not settle (the caller's general
    solver decides). Converged when the error is within ``tol`` and the last step moved no joint more than
    :data:`_QUADRATIC_RAD` (the distance left is then of the order of its square) or the next one would move
    none more than :data:`_STEP_TOL_RAD`; with a joint pinned the multipliers are checked too."""
    q = seed if guess is None else guess
    lo_list, hi_list, seed_list = lo.tolist(), hi.tolist(), seed.tolist()
    pinned: np.ndarray | None = None  # the joints held at a limit, or None (the common case: no mask work)
    last_step = math.inf
    for _ in range(max_steps):
        e, J, dp, dr = residual(q)
        converged = dp <= tol and dr <= tol
        if converged and pinned is None and last_step <= _QUADRATIC_RAD:
            return q
        stepped = _kkt_step(J, e, q, seed, pinned)
        if stepped is None:
            return None
        new, y = stepped
        new_list = new.tolist()
        step = max(abs(a - b) for a, b in zip(new_list, q.tolist()))
        if step > _TRUST_RAD:  # far from the solution, the linearisation is not to be trusted this far
            new = q + (new - q) * (_TRUST_RAD / step)
            new_list, step = new.tolist(), _TRUST_RAD
        if converged:
            if pinned is not None:
                # the multipliers of the pinned joints: one whose optimum lies inside its limit is freed
                pull = J[:, pinned].T.dot(y) - (q[pinned] - seed[pinned])
                inside = np.where(q[pinned] >= hi[pinned], pull < 0.0, pull > 0.0)
                if inside.any():
                    pinned[np.flatnonzero(pinned)[inside]] = False
                    if not pinned.any():
                        pinned = None
                    last_step = math.inf
                    continue
            if step <= _STEP_TOL_RAD:
                return q
            if pinned is None and step <= _QUADRATIC_RAD and all(l <= a <= h for a, l, h in zip(new_list, lo_list, hi_list)):
                return new  # converged, and the last step: see _QUADRATIC_RAD
        if any(a < l or a > h for a, l, h in zip(new_list, lo_list, hi_list)):
            beyond = (new < lo) | (new > hi)
            new = np.minimum(np.maximum(new, lo), hi)
            pinned = beyond if pinned is None else pinned | beyond
            new_list = new.tolist()
        if max(abs(a - b) for a, b in zip(new_list, seed_list)) > max_move_rad:
            return None
        q, last_step = new, step
    e, J, dp, dr = residual(q)
    return q if dp <= tol and dr <= tol and last_step <= _SETTLED_RAD else None


def track_pose(model, data, fid: int, rotation: np.ndarray, position: np.ndarray, seed: np.ndarray,
               lo: np.ndarray, hi: np.ndarray, *, tol: float = 1e-10, max_move_rad: float = TRACK_MAX_MOVE_RAD,
               guess: np.ndarray | None = None, max_steps: int = _MAX_STEPS) -> np.ndarray | None:
    """Joint angles (rad) putting frame ``fid`` of the Pinocchio ``model`` at ``rotation`` (3x3) and ``position``
    (m), nearest ``seed`` (:func:`_nearest_kkt`), or None. The error is ``e = [p* - p; log3(R* Rᵀ)]`` (world
    frame), the Jacobian the frame's world-aligned one; converged when both norms are at most ``tol`` (m,
    rad), as :func:`~robocritics.robot.ik_numeric.numeric_ik` judges."""
    R_des = np.asarray(rotation, dtype=float)
    p_des = np.asarray(position, dtype=float)
    world = pin.LOCAL_WORLD_ALIGNED

    def residual(q):
        J = pin.computeFrameJacobian(model, data, q, fid, world)  # the joint placements for the frame's pose
        oMf = pin.updateFramePlacement(model, data, fid)
        e = np.concatenate((p_des - oMf.translation, pin.log3(R_des.dot(oMf.rotation.T))))
        ex, ey, ez, rx, ry, rz = e.tolist()
        return e, J, math.sqrt(ex * ex + ey * ey + ez * ez), math.sqrt(rx * rx + ry * ry + rz * rz)

    return _nearest_kkt(residual, seed, lo, hi, tol, max_move_rad, guess, max_steps)


def track_pointing(model, data, fid: int, position: np.ndarray, axis: np.ndarray, seed: np.ndarray,
                   lo: np.ndarray, hi: np.ndarray, *, tol: float = 1e-9, max_move_rad: float = TRACK_MAX_MOVE_RAD,
                   guess: np.ndarray | None = None, max_steps: int = _MAX_STEPS) -> np.ndarray | None:
    """Joint angles (rad) putting frame ``fid`` at ``position`` (m) with its +z axis along ``axis`` (the turn
    about it free: five constraints), nearest ``seed``, or None. With ``u``, ``v`` unit vectors across
    ``z*``, the axis constraints are ``z . u = z . v = 0`` (rows ``(z x u)ᵀ J_w``, ``(z x v)ᵀ J_w``) and
    ``z . z* > 0``; the rotation error is ``|z x z*|`` (rad to first order), as
    :func:`~robocritics.robot.ik_numeric.pointing_ik` judges."""
    p_des = np.asarray(position, dtype=float)
    ax, ay, az = np.asarray(axis, dtype=float).tolist()
    norm = math.sqrt(ax * ax + ay * ay + az * az)
    ax, ay, az = ax / norm, ay / norm, az / norm
    # u = z* x (the basis vector least along z*), v = z* x u: written out, as np.cross costs ten times this
    k = min(range(3), key=lambda i: abs((ax, ay, az)[i]))
    ux, uy, uz = ((0.0, az, -ay), (-az, 0.0, ax), (ay, -ax, 0.0))[k]
    norm = math.sqrt(ux * ux + uy * uy + uz * uz)
    ux, uy, uz = ux / norm, uy / norm, uz / norm
    vx, vy, vz = ay * uz - az * uy, az * ux - ax * uz, ax * uy - ay * ux
    world = pin.LOCAL_WORLD_ALIGNED
    across = np.empty((2, 3))
    A = np.empty((5, model.nv))

    def residual(q):
        J = pin.computeFrameJacobian(model, data, q, fid, world)
        oMf = pin.updateFramePlacement(model, data, fid)
        zx, zy, zz = oMf.rotation[:, 2].tolist()
        # z x u and z x v, written out (np.cross costs ten times a 3x3 product here)
        across[0] = (zy * uz - zz * uy, zz * ux - zx * uz, zx * uy - zy * ux)
        across[1] = (zy * vz - zz * vy, zz * vx - zx * vz, zx * vy - zy * vx)
        A[:3] = J[:3]
        A[3:] = across.dot(J[3:])
        ex, ey, ez = (p_des - oMf.translation).tolist()
        cu, cv = zx * ux + zy * uy + zz * uz, zx * vx + zy * vy + zz * vz
        e = np.array((ex, ey, ez, -cu, -cv))
        dr = math.hypot(cu, cv) if zx * ax + zy * ay + zz * az > 0.0 else math.inf
        return e, A, math.sqrt(ex * ex + ey * ey + ez * ez), dr

    return _nearest_kkt(residual, seed, lo, hi, tol, max_move_rad, guess, max_steps)


def _extrapolated(rows: list[np.ndarray], lo: np.ndarray, hi: np.ndarray) -> np.ndarray | None:
    """Where the next point of an evenly spaced line starts its Newton iterations: the last three solutions'
    parabola one spacing on (``3 q[i-1] - 3 q[i-2] + q[i-3]``, off by about the third difference of ``q``
    along the line, ~1e-6 rad at the planner's 5 mm: within :data:`_QUADRATIC_RAD` after one step), the last
    two's line (``2 q[i-1] - q[i-2]``, ~|dq|²) with two, clamped to the limits; None (the seed) before."""
    if len(rows) >= 3:
        guess = 3.0 * (rows[-1] - rows[-2]) + rows[-3]
    elif len(rows) == 2:
        guess = 2.0 * rows[-1] - rows[-2]
    else:
        return None
    return np.minimum(np.maximum(guess, lo), hi)


def track_line(robot, positions: np.ndarray, seed: np.ndarray, yaw_rad: float,
               tilts: np.ndarray) -> tuple[np.ndarray, PlanningError | None]:
    """:meth:`~robocritics.robot.model.Robot.ik_line` for an arm without a closed form: ``robot.ik`` at each
    of ``positions (n, 3)`` m in turn, each seeded by the previous solution (the first by ``seed``), the
    fingers down turned by ``yaw_rad`` and tilted by ``tilts[i]`` (rad) as ``robot.ik`` puts them; each point
    tracked (:func:`track_pose`, or :func:`track_pointing` where ``robot.ik`` points the fingers), and solved
    by ``robot.ik`` itself where tracking does not settle (and for a closed-form arm, a 5-joint arm's tilted
    cone, a point that is not finite). The Newton iterations start from the solutions so far extrapolated
    (:func:`_extrapolated`); the seed, what "nearest" is measured from, stays the previous solution.
    Returns ``(q (m, n) rad, error)`` as ``ik_line`` does."""
    lo, hi = robot.lower, robot.upper
    closed_form = robot.dh is not None and robot.tcp_in_flange is not None
    fid = None
    rows: list[np.ndarray] = []
    seed = np.minimum(np.maximum(np.asarray(seed, dtype=float), lo), hi)  # as numeric_ik clamps it
    for point, tilt in zip(positions, tilts.tolist()):
        q = None
        pointing = robot.n < 6 or tilt != 0.0
        if np.isfinite(point).all() and not (robot.n < 6 and tilt != 0.0) and not (closed_form and not pointing):
            if fid is None:
                model, data, fid = robot.model, robot.data, robot._tcp_frame_id
            guess = _extrapolated(rows, lo, hi)
            R = approach_rotation(point, yaw_rad, tilt, robot.shoulder_m)
            if pointing:
                q = track_pointing(model, data, fid, point, R[:, 2], seed, lo, hi, guess=guess)
            else:
                q = track_pose(model, data, fid, R, point, seed, lo, hi, guess=guess)
        if q is None:
            try:
                # after a line's first point only the restarts near the seed (a far solution is a joint
                # jump the planner refuses): a point out of reach at this tilt fails in 5 tries, not 21
                q = robot.ik(point, seed=seed, yaw_rad=yaw_rad, tilt_rad=tilt, restarts=LINE_RESTARTS if rows else 20)
            except PlanningError as exc:
                return np.array(rows, dtype=float).reshape(-1, robot.n), exc
        rows.append(q)
        seed = q
    return np.array(rows, dtype=float).reshape(-1, robot.n), None
