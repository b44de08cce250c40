"""Numeric IK for arms without a closed form (Pinocchio, damped least squares): the Panda and URDF arms. rad, m.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pinocchio as pin

from robocritics.errors import PlanningError, RobotModelError

__all__ = ["numeric_ik"]


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


def _random_start(model: Any, gen: np.random.Generator, lo: np.ndarray, hi: np.ndarray, clip: bool) -> np.ndarray:
    """A random configuration within the limits ``lo``/``hi`` (rad; an unbounded joint within +-pi) to restart
    from, or Pinocchio's for a model whose configuration is not its joint angles (``clip`` False)."""
    if not clip:
        return pin.randomConfiguration(model)
    return gen.uniform(np.where(np.isfinite(lo), lo, -math.pi), np.where(np.isfinite(hi), hi, math.pi))


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
    ``pin.integrate``. Position-only uses ``e = p* - p`` and the translational
    rows rotated to the base frame. Converged when the position error ≤ ``tol``
    m and the rotation error ≤ ``tol`` rad; otherwise up to ``restarts`` more
    attempts from random configurations within the limits (deterministic
    ``rng``). Returns ``(nq,)``; raises :class:`PlanningError` with the best
    residual (m, rad) if nothing converged.
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
        best_q, best = q, (math.inf, math.inf)
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
            Jf = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL)
            lam = damping + 1e-3 * float(err @ err)
            if oMdes is None:
                J = oMf.rotation @ Jf[:3]
                dq = J.T @ np.linalg.solve(J @ J.T + lam * eye, err)
            else:
                J = -pin.Jlog6(iMd.inverse()) @ Jf
                dq = -J.T @ np.linalg.solve(J @ J.T + lam * eye, err)
            big = float(np.abs(dq).max())
            if big > max_step:
                dq *= max_step / big
            q = pin.integrate(model, q, dq)
            if clip:
                q = np.clip(q, lo, hi)
        return best_q, best[0], best[1]

    q0 = np.asarray(seed, dtype=float).reshape(model.nq)
    if clip:
        q0 = np.clip(q0, lo, hi)
    best = (q0, math.inf, math.inf)
    for k in range(restarts + 1):
        start = q0 if k == 0 else _random_start(model, gen, lo, hi, clip)
        q, dp, dr = attempt(start)
        if dp + dr < best[1] + best[2]:
            best = (q, dp, dr)
        if dp <= tol and dr <= tol:
            return np.array(q, dtype=float)
    _, dp, dr = best
    what = "position" if oMdes is None else "pose"
    raise PlanningError(
        f"numeric IK did not converge to the {what} target ({p_des[0]:.3f}, {p_des[1]:.3f}, "
        f"{p_des[2]:.3f}) m for frame {model.frames[fid].name!r} after {restarts + 1} attempts: "
        f"best residual {dp:.3g} m, {dr:.3g} rad (tolerance {tol:g})"
    )
