"""Numeric IK for arms without a closed form (Pinocchio, damped least squares): the Panda and URDF arms, and
pointing IK for arms with fewer than six joints. rad, m.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pinocchio as pin

from robocritics.errors import PlanningError, RobotModelError

from .ik_track import track_pointing, track_pose

__all__ = ["numeric_ik", "pointing_ik"]


# --------------------------------------------------------------------------- #
# Numeric IK (Pinocchio, damped least squares)
# --------------------------------------------------------------------------- #


def _parse_target(target: Any) -> tuple[np.ndarray, np.ndarray | None]:
    """(position (3,) m, rotation (3, 3) or None for position-only)."""
    if isinstance(target, pin.SE3):
        return np.array(target.translation, dtype=float), np.array(target.rotation, dtype=float)
    if isinstance(target, tuple) and len(target) == 2:
        pos, rot = target
        pos = np.asarray(pos, dtype=float).reshape(3)
        return pos, None if rot is None else np.asarray(rot, dtype=float).reshape(3, 3)
    arr = np.asarray(target, dtype=float)
    if arr.shape == (4, 4):
        return arr[:3, 3].copy(), arr[:3, :3].copy()
    if arr.shape == (3,):
        return arr.copy(), None
    raise PlanningError(
        f"numeric_ik: target must be a pin.SE3, a 4x4 transform, a 3-vector (position only) "
        f"or (position, rotation-or-None), got shape {arr.shape}"
    )


#: A descent whose error (position m + rotation rad) has not fallen below :data:`STALL_GAIN` times its best
#: for this many iterations is stuck and ends. Measured (300 random targets per arm, seeds 0.6-1.5 rad off,
#: /tmp profiling of the iiwa14 R820, xArm7, Kinova, KUKA iiwa, Panda): of ~1,300 descents that converge, one
#: had such a stretch of 20 or more iterations (the Panda's, 37); a stuck descent otherwise runs all ``max_iter``.
STALL_ITERATIONS = 20
#: What counts as progress for :data:`STALL_ITERATIONS`: the error below this fraction of the last mark.
STALL_GAIN = 0.99
#: Null-space steps :func:`numeric_ik` takes towards the seed on a redundant arm.
NULL_SPACE_STEPS = 30
#: Newton steps numeric IK tries from the seed before its descents. Far from the seed the iteration converges
#: linearly (by a factor of about ``|q - seed|`` rad a step: the constraint's curvature is left out), and its
#: steps are at most ``ik_track``'s trust length, 0.25 rad: a posture seed 0.7 rad from the solution took 16.
NEWTON_FIRST_STEPS = 30
#: A redundant arm's IK solution with every joint within this of the seed [rad] is taken without looking for
#: other branches; a farther one is compared with up to two more (near-seed restarts first).
NEAR_SEED_RAD = 1.0


def _towards_seed(model, data, fid, q, seed, lo, hi, clip, attempt, tol, max_step, task_dims) -> np.ndarray:
    """From the solution ``q`` of a redundant arm, step along its self-motion (the Jacobian's null space, where
    the TCP stays put) towards ``seed``, re-converging after each step, while that brings it nearer the seed.

    The null-space preference: among the solutions joined to ``q`` by self-motion, the one a gradient descent of
    ``|q - seed|`` reaches: deterministic, and the arm's posture (elbow, wrist) stays as near the seed's as
    the target allows. A step that does not re-converge or does not get nearer ends the descent."""
    for _ in range(NULL_SPACE_STEPS):
        pin.computeJointJacobians(model, data, q)
        pin.framesForwardKinematics(model, data, q)
        J = pin.getFrameJacobian(model, data, fid, pin.LOCAL).reshape(6, model.nv)[:task_dims]
        null = np.eye(model.nv) - np.linalg.pinv(J) @ J
        step = null @ (seed - q)
        big = float(np.abs(step).max())
        if big < 1e-9:
            break
        if big > max_step:
            step *= max_step / big
        moved = q + step
        if clip:
            moved = np.clip(moved, lo, hi)
        moved, dp, dr = attempt(moved)
        if not (dp <= tol and dr <= tol) or np.linalg.norm(moved - seed) >= np.linalg.norm(q - seed) - 1e-12:
            break
        q = moved
    return q


def _nearest_along_self_motion(model, data, fid, q, seed, lo, hi, clip, attempt, tol, max_step,
                               oMdes) -> np.ndarray:
    """From the solution ``q`` of a redundant arm, the solution nearest ``seed`` that self-motion reaches.

    For a full pose on an arm whose configuration is its joint angles: the active-set Newton iteration on the
    conditions of ``min |q - seed|²`` subject to the pose (:func:`~robocritics.robot.ik_track.track_pose`,
    started at ``q``), taken when it converges no farther from the seed than ``q``: it lands on the point the
    descent of :func:`_towards_seed` approaches, in a few Newton steps instead of up to
    :data:`NULL_SPACE_STEPS` re-converged null-space steps. Otherwise (position only, a model with quaternion
    joints, no convergence) that descent."""
    if clip and oMdes is not None:
        nearest = track_pose(model, data, fid, oMdes.rotation, oMdes.translation, seed, lo, hi, tol=tol,
                             max_move_rad=math.inf, guess=q)
        if nearest is not None and np.linalg.norm(nearest - seed) <= np.linalg.norm(q - seed):
            return nearest
    task_dims = 6 if oMdes is not None else 3
    return _towards_seed(model, data, fid, q, seed, lo, hi, clip, attempt, tol, max_step, task_dims)


def _held_step(J: np.ndarray, err: np.ndarray, lam: float, eye: np.ndarray, q: np.ndarray, lo: np.ndarray,
               hi: np.ndarray, clip: bool, outward: float = 1.0) -> np.ndarray:
    """The damped least-squares step ``dq = Jᵀ (J Jᵀ + λ I)⁻¹ e`` (rad) with the joints at a limit that it
    would push further out held there: their columns dropped from ``J`` and the step solved again with the
    rest, until no free joint at a limit is pushed out (the active set of projected Levenberg-Marquardt; at
    most one solve per joint). ``outward``: the sign that turns the returned step into the joints' motion
    (-1 where the caller applies ``-dq``).

    Why: clipping the plain step after the fact throws away the held joint's share of the correction, and
    the ``max_step`` scaling of a step dominated by a joint pushing into its limit leaves the others creeping
    (the iiwa14 R820 seeded near its base limit: 100 iterations a descent, no convergence). With the joint
    held the others take the whole correction: a 7-joint arm keeps six, enough for a pose."""
    dq = J.T @ np.linalg.solve(J @ J.T + lam * eye, err)
    if not clip:
        return dq
    held = np.zeros(len(q), dtype=bool)
    for _ in range(len(q)):
        move = outward * dq
        push = ~held & (((q <= lo) & (move < 0.0)) | ((q >= hi) & (move > 0.0)))
        if not push.any():
            break
        held |= push
        free = ~held
        Jf = J[:, free]
        dq = np.zeros(len(q))
        dq[free] = Jf.T @ np.linalg.solve(Jf @ Jf.T + lam * eye, err)
    return dq


def _dls(model: Any, data: Any, fid: int, q: np.ndarray, p_des: np.ndarray, oMdes: Any, eye: np.ndarray,
         lo: np.ndarray, hi: np.ndarray, clip: bool, max_iter: int, tol: float, damping: float,
         max_step: float) -> tuple[np.ndarray, float, float]:
    """One damped-least-squares descent of :func:`numeric_ik` from ``q``: the best iterate and its position (m)
    and rotation (rad) errors."""
    best_q, best = q, (math.inf, math.inf)
    mark, since = math.inf, 0  # the error the last real improvement reached, and the iterations since
    for _ in range(max_iter):
        pin.framesForwardKinematics(model, data, q)
        oMf = data.oMf[fid]
        if oMdes is None:
            err = p_des - oMf.translation
            dp, dr = float(np.linalg.norm(err)), 0.0
        else:
            iMd = oMf.actInv(oMdes)
            err = pin.log6(iMd).vector
            dp = float(np.linalg.norm(oMf.translation - p_des))
            dr = float(np.linalg.norm(err[3:]))
        if dp + dr < best[0] + best[1]:
            best_q, best = q, (dp, dr)
        if dp <= tol and dr <= tol:
            break
        if dp + dr < STALL_GAIN * mark:
            mark, since = dp + dr, 0
        elif (since := since + 1) >= STALL_ITERATIONS:
            break  # stuck (a 2-cycle, or a local minimum of the error): the next restart is a better use
        Jf = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL)
        lam = damping + 1e-3 * float(err @ err)
        if oMdes is None:
            dq = _held_step(oMf.rotation @ Jf[:3], err, lam, eye, q, lo, hi, clip)
        else:
            dq = -_held_step(-pin.Jlog6(iMd.inverse()) @ Jf, err, lam, eye, q, lo, hi, clip, outward=-1.0)
        big = float(np.abs(dq).max())
        if big > max_step:
            dq *= max_step / big
        q = pin.integrate(model, q, dq)
        if clip:
            q = np.clip(q, lo, hi)
    return best_q, best[0], best[1]


def _frame_id(model: Any, frame_id: int | str) -> int:
    """The id of frame ``frame_id`` (an id, or a link name) in ``model``; RobotModelError naming it if none."""
    if isinstance(frame_id, str):
        if not model.existFrame(frame_id, pin.FrameType.BODY):
            raise RobotModelError(
                f"numeric_ik: no link {frame_id!r} in model {model.name!r} (pass a frame id for other frame types)"
            )
        fid = model.getFrameId(frame_id, pin.FrameType.BODY)
    else:
        fid = int(frame_id)
    if fid < 0 or fid >= model.nframes:
        raise RobotModelError(f"numeric_ik: no frame {frame_id!r} in model {model.name!r}")
    return fid


def _restart(model: Any, gen: np.random.Generator, q0: np.ndarray, lo: np.ndarray, hi: np.ndarray, clip: bool,
             near_seed_try: int) -> np.ndarray:
    """Where restart ``near_seed_try`` of numeric IK begins: the first four near the seed (a descent from the
    seed that failed at a joint limit, or a solution far from it, is on another branch: deterministic noise
    growing 0.15 rad a try); otherwise anywhere within the limits (an unbounded joint within +-pi), or
    Pinocchio's random configuration for a model whose configuration is not its joint angles."""
    if 0 < near_seed_try <= 4 and clip:
        return np.clip(q0 + gen.normal(0.0, 0.15 * near_seed_try, q0.shape), lo, hi)
    if clip:
        return gen.uniform(np.where(np.isfinite(lo), lo, -math.pi), np.where(np.isfinite(hi), hi, math.pi))
    return pin.randomConfiguration(model)


def numeric_ik(
    model: Any,
    data: Any,
    frame_id: int | str,
    target: Any,
    seed: Any,
    lower: Any = None,
    upper: Any = None,
    *,
    max_iter: int = 100,
    tol: float = 1e-10,
    damping: float = 1e-10,
    restarts: int = 20,
    max_step: float = 0.5,
    rng: int | np.random.Generator = 0,
) -> np.ndarray:
    """Damped-least-squares IK on a Pinocchio model (any serial arm).

    Solves ``oMf(q) = target`` for the frame ``frame_id`` (a frame id, or a link name).
    ``target``: a ``pin.SE3`` or ``(4, 4)`` transform (full pose), a ``(3,)``
    position, or ``(position, rotation)`` where ``rotation=None`` means
    position-only. ``seed``: ``(nq,)`` rad. ``lower``/``upper``: ``(nq,)``
    position limits (default: the model's); every iterate is clipped to them.

    Iteration (full pose): with ``iMd = oMf⁻¹ · target`` the error is
    ``e = log6(iMd)`` (local frame, m and rad), the Jacobian ``J = -Jlog6(iMd⁻¹) · J_f``
    where ``J_f`` is the LOCAL frame Jacobian, and the step is
    ``dq = -Jᵀ (J Jᵀ + λ I)⁻¹ e`` with ``λ = damping + |e|²·1e-3``, scaled so
    that no joint moves more than ``max_step`` rad, applied with
    ``pin.integrate``; a joint at a limit that the step would push further out is held there and the step
    solved with the others (:func:`_held_step`). Position-only uses ``e = p* - p`` and the translational
    rows rotated to the base frame. Converged when the position error ≤ ``tol``
    m and the rotation error ≤ ``tol`` rad; a descent whose error has not fallen 1% in
    :data:`STALL_ITERATIONS` iterations is stuck and ends early; otherwise up to ``restarts`` more
    attempts, the first four near the seed, then from random configurations within the limits (deterministic
    ``rng``). On a redundant arm (more joints than the target constrains, a 7-joint arm) the solution then
    moves along its self-motion to the solution nearest the seed (:func:`_nearest_along_self_motion`): the null-space preference is the seed's posture. On any arm, a solution with a joint more than
    :data:`NEAR_SEED_RAD` from the seed is compared with the solutions of further attempts (near the seed first)
    and the nearest of up to three is returned. Returns ``(nq,)``; raises :class:`PlanningError` with the best
    residual (m, rad) if nothing converged.

    Newton first: for a full pose on an arm of six or more joint angles, the active-set Newton iteration for the
    solution nearest the seed (:func:`~robocritics.robot.ik_track.track_pose`, from the seed, every iterate
    within :data:`NEAR_SEED_RAD` of it) runs before any descent, and its answer is returned where it converges:
    a solution within :data:`NEAR_SEED_RAD` that is stationary for ``|q - seed|`` is what the descents below
    look for, in a few steps instead of tens (0.7 ms against 3.8 ms for a Panda ``move_to``).
    """
    fid = _frame_id(model, frame_id)
    p_des, R_des = _parse_target(target)
    oMdes = pin.SE3(R_des, p_des) if R_des is not None else None
    lo = np.asarray(model.lowerPositionLimit if lower is None else lower, dtype=float)
    hi = np.asarray(model.upperPositionLimit if upper is None else upper, dtype=float)
    clip = model.nq == model.nv
    gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    eye = np.eye(6 if oMdes is not None else 3)

    def attempt(q: np.ndarray) -> tuple[np.ndarray, float, float]:
        return _dls(model, data, fid, q, p_des, oMdes, eye, lo, hi, clip, max_iter, tol, damping, max_step)

    q0 = np.asarray(seed, dtype=float).reshape(model.nq)
    if clip:
        q0 = np.clip(q0, lo, hi)
    if clip and oMdes is not None and model.nv >= 6:
        newton = track_pose(model, data, fid, oMdes.rotation, oMdes.translation, q0, lo, hi, tol=tol,
                            max_move_rad=NEAR_SEED_RAD, max_steps=NEWTON_FIRST_STEPS)
        if newton is not None:  # Newton first: see the docstring
            return newton
    best = (q0, math.inf, math.inf)
    redundant = model.nv > len(eye)
    found: list[np.ndarray] = []
    for k in range(restarts + 1):
        start = q0 if k == 0 else _restart(model, gen, q0, lo, hi, clip, k)
        q, dp, dr = attempt(start)
        if dp + dr < best[1] + best[2]:
            best = (q, dp, dr)
        if dp <= tol and dr <= tol:
            if redundant:
                q = _nearest_along_self_motion(model, data, fid, q, q0, lo, hi, clip, attempt, tol, max_step,
                                               oMdes)
            found.append(np.array(q, dtype=float))
            # near the seed (every joint within NEAR_SEED_RAD), or several branches seen: the nearest of them
            if np.abs(q - q0).max() <= NEAR_SEED_RAD or len(found) >= 3:
                break
    if found:
        return min(found, key=lambda sol: float(np.linalg.norm(sol - q0)))
    _, dp, dr = best
    what = "position" if oMdes is None else "pose"
    raise PlanningError(
        f"numeric IK did not converge to the {what} target ({p_des[0]:.3f}, {p_des[1]:.3f}, "
        f"{p_des[2]:.3f}) m for frame {model.frames[fid].name!r} after {restarts + 1} attempts: "
        f"best residual {dp:.3g} m, {dr:.3g} rad (tolerance {tol:g})"
    )


def pointing_ik(model: Any, data: Any, fid: int, position: Any, axis: Any, seed: Any, lower: Any, upper: Any, *,
                max_iter: int = 200, tol: float = 1e-9, restarts: int = 20, max_step: float = 0.5, rng: int = 0,
                cone_rad: float | None = None) -> np.ndarray:
    """IK for the frame ``fid`` at ``position`` (m) with its +z axis along ``axis`` and the turn about that axis
    free: five constraints, for arms with fewer than six joints (a 5-joint arm cannot choose the yaw of a
    fingers-down grasp as well). Damped least squares on ``e = [p* - p, z x z*]`` with the rows
    ``[J_v; (J_w x z) x z*]`` (world-aligned frame Jacobian), clipped to the limits; restarts as
    :func:`numeric_ik` (the seed first, then near it, then anywhere, deterministic), each descent ending early when
    stuck (:data:`STALL_ITERATIONS`). Raises PlanningError. Without ``cone_rad``, Newton first as in
    :func:`numeric_ik` (:func:`~robocritics.robot.ik_track.track_pointing`: the solution nearest the seed).

    ``cone_rad``: the +z axis at this angle from ``axis`` instead, leaning whichever way the arm allows (four
    constraints: a 5-joint arm's wrist leans in its own plane): ``e = [p* - p, cos(cone) - z . z*]`` with the
    rows ``[J_v; (z x z*)^T J_w]``."""
    p_des = np.asarray(position, float).reshape(3)
    z_des = np.asarray(axis, float).reshape(3)
    z_des = z_des / np.linalg.norm(z_des)
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    gen = np.random.default_rng(rng)
    q0 = np.clip(np.asarray(seed, float).reshape(model.nq), lo, hi)
    cone = None if cone_rad is None else math.cos(cone_rad)  # the cosine the axes' dot product must have

    def attempt(q):
        best_q, best = q, (math.inf, math.inf)
        mark, since = math.inf, 0  # as _dls: a descent stuck STALL_ITERATIONS iterations ends
        for _ in range(max_iter):
            pin.computeJointJacobians(model, data, q)
            pin.framesForwardKinematics(model, data, q)
            oMf = data.oMf[fid]
            z = oMf.rotation[:, 2]
            if cone is None:
                e = np.concatenate([p_des - oMf.translation, np.cross(z, z_des)])
                dp, dr = float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:])) + (2.0 if z @ z_des < 0 else 0.0)
            else:
                e = np.append(p_des - oMf.translation, cone - z @ z_des)
                dp, dr = float(np.linalg.norm(e[:3])), abs(float(e[3]))
            if dp + dr < best[0] + best[1]:
                best_q, best = q, (dp, dr)
            if dp <= tol and dr <= tol:
                break
            if dp + dr < STALL_GAIN * mark:
                mark, since = dp + dr, 0
            elif (since := since + 1) >= STALL_ITERATIONS:
                break
            J = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED).reshape(6, model.nv)  # a 1-joint model gives (6,)
            if cone is None:
                Jr = np.cross(np.cross(J[3:].T, z), z_des).T  # d(z x z*)/dq: z moves by w x z
                A = np.vstack([J[:3], -Jr])
            else:  # d(z . z*)/dq = z* . (w x z) = (z x z*) . w
                A = np.vstack([J[:3], np.cross(z, z_des) @ J[3:]])
            lam = 1e-10 + 1e-3 * float(e @ e)
            dq = A.T @ np.linalg.solve(A @ A.T + lam * np.eye(len(e)), e)
            big = float(np.abs(dq).max())
            if big > max_step:
                dq *= max_step / big
            q = np.clip(pin.integrate(model, q, dq), lo, hi)
        return best_q, best[0], best[1]

    if cone is None and model.nv >= 5:
        newton = track_pointing(model, data, fid, p_des, z_des, q0, lo, hi, tol=tol, max_move_rad=NEAR_SEED_RAD,
                                max_steps=NEWTON_FIRST_STEPS)
        if newton is not None:  # Newton first: see numeric_ik's docstring
            return newton
    best = (q0, math.inf, math.inf)
    for k in range(restarts + 1):
        if k == 0:
            start = q0
        elif k <= 4:
            start = np.clip(q0 + gen.normal(0.0, 0.15 * k, q0.shape), lo, hi)
        else:
            start = gen.uniform(np.where(np.isfinite(lo), lo, -math.pi), np.where(np.isfinite(hi), hi, math.pi))
        q, dp, dr = attempt(start)
        if dp + dr < best[1] + best[2]:
            best = (q, dp, dr)
        if dp <= tol and dr <= tol:
            return np.array(q, dtype=float)
    _, dp, dr = best
    how = f"along {np.round(z_des, 3).tolist()}" if cone_rad is None else \
        f"{math.degrees(cone_rad):.0f} deg from {np.round(z_des, 3).tolist()}"
    raise PlanningError(f"numeric IK did not reach ({p_des[0]:.3f}, {p_des[1]:.3f}, {p_des[2]:.3f}) m with the finger "
                        f"axis {how} after {restarts + 1} attempts: best residual "
                        f"{dp:.3g} m, {dr:.3g} rad")
