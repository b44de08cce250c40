"""Inverse kinematics: closed-form for Universal Robots arms, damped least squares otherwise.

Units: metres for lengths and positions, radians for angles, everything in the
robot base frame (z up) unless a docstring says otherwise.

Kinematic convention (standard Denavit-Hartenberg, as published by Universal
Robots)::

    A_i(theta_i) = Rz(theta_i) · Tz(d_i) · Tx(a_i) · Rx(alpha_i)
    T_06(q)      = A_1(q_1) · A_2(q_2) · ... · A_6(q_6)

``T_06`` is the pose of the flange (``tool0``) in the base frame. A UR arm has
``a_1 = a_4 = a_5 = a_6 = 0``, ``d_2 = d_3 = 0`` and
``alpha = (pi/2, 0, 0, pi/2, -pi/2, 0)``: joints 2, 3 and 4 are parallel, and
the last three axes do *not* intersect (there is no spherical wrist), which is
why the closed form below (Hawkins 2013; Andersen 2018) goes through the
wrist-2 centre rather than a wrist centre of the usual kind.

The closed form (frame ``i`` has axes ``x_i, y_i, z_i``; the target flange pose
has rotation ``R = [x_6 y_6 z_6]`` and position ``p``):

1. Shoulder pan ``q1``. The wrist-2 centre ``p_5 = p - d_6 z_6`` lies at signed
   distance ``d_4`` (more generally ``d_2 + d_3 + d_4``) from the arm plane, whose
   normal is ``z_1 = (sin q1, -cos q1, 0)``: ``p_5 · z_1 = d_4``. With
   ``p_5 = r (cos phi, sin phi, *)`` this is ``r sin(q1 - phi) = d_4``, so
   ``q1 = phi + pi/2 ± acos(d_4 / r)`` (two branches, "shoulder left/right").
   No solution when ``r < d_4``: the wrist would have to enter the cylinder of
   radius ``d_4`` around the base axis.
2. Wrist 2 ``q5``. Expressed in the flange frame, ``z_1 = (cos q6 sin q5,
   -sin q6 sin q5, cos q5)``, so ``cos q5 = z_6 · z_1`` and
   ``|sin q5| = |(x_6 · z_1, y_6 · z_1)|``; ``q5 = atan2(±|sin q5|, cos q5)``
   (two branches, "wrist up/down"; the ``atan2`` form stays accurate near
   ``q5 = 0`` where ``acos`` would lose half the digits).
3. Wrist 3 ``q6 = atan2(-(y_6 · z_1) / sin q5, (x_6 · z_1) / sin q5)``. When
   ``sin q5 ≈ 0`` (wrist singularity: axes 4 and 6 align) only ``q4 + q6`` or
   ``q4 - q6`` is determined; ``q6`` is then set to a caller-chosen value (the
   seed's, in :func:`ur_ik`) and ``q4`` absorbs the rest. Since ``q6`` also
   decides where the ``d5`` offset puts the wrist, a pose at the edge of the
   workspace may be reachable only for some ``q6``: then the nearest such
   value is taken (see :func:`_singular_q6`).
4. Shoulder lift, elbow, wrist 1 (``q2, q3, q4``): a planar 3R arm. From the
   flange frame, ``x_5 = cos q6 x_6 - sin q6 y_6``, ``z_4 = -(sin q6 x_6 + cos q6 y_6)``,
   ``x_4 = cos q5 x_5 - sin q5 z_6``; the wrist-1 centre is
   ``p_4 = p - d_6 z_6 - d_5 z_4``. In frame 1 (origin ``(0, 0, d_1)``, ``x_1 =
   (cos q1, sin q1, 0)``, ``y_1 = (0, 0, 1)``) its planar coordinates ``X, Y``
   satisfy ``X + iY = a_2 e^{i q2} + a_3 e^{i(q2+q3)}``, hence
   ``cos q3 = (X² + Y² - a_2² - a_3²) / (2 a_2 a_3)`` (two branches, "elbow
   up/down"; no solution when ``|cos q3| > 1``: the wrist is farther than
   ``|a_2| + |a_3|`` from the shoulder, or closer than ``||a_2| - |a_3||``),
   ``q2 = atan2(Y, X) - atan2(a_3 sin q3, a_2 + a_3 cos q3)`` and
   ``q4 = atan2(x_4 · y_1, x_4 · x_1) - q2 - q3``.

That gives up to 2 × 2 × 2 = 8 solutions. Every one is checked by forward
kinematics before it is returned: the closed-form FK of :mod:`robocritics.robot.ur_fk`
(Pinocchio's on the URDF of the DH chain, :func:`dh_forward`, to rounding; a third of its
CPU from Python), or, for a branch no step of which was clipped, nudged or clamped, of a
target whose rotation is orthonormal, the certificate that the closed form is then exact
(:func:`_certified`; ``tests/test_ik_nearest.py`` checks it against Pinocchio at the
singularities). :func:`ur_ik_all` lists the branches; :func:`ur_ik_all_many` lists those of
many poses in one numpy pass (cheaper per pose from about 15 poses on; ``benchmarks/bench_ik.py
--all-many``); :func:`ur_ik` searches the same steps branch-and-bound for the one nearest a seed
configuration (:mod:`robocritics.robot.ik_nearest`; in C where ``robocritics.robot._ur_nearest`` is built, the
same floats).

For arms that are not UR-like, :func:`~robocritics.robot.ik_numeric.numeric_ik` runs a damped-least-squares
(Levenberg-Marquardt) iteration on a Pinocchio model with random restarts.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from typing import Any

import numpy as np

from robocritics.errors import PlanningError, RobotModelError

from .arms import DH, UR3E
from .ik_many import (
    _CLIP_TOL,
    _DUPLICATE_TOL,
    _HALF_PI,
    _LIMIT_SLACK,
    _LINE_CHUNK,
    _PI,
    _TWO_PI,
    _VECTORISED_WALK_POSES,
    _VERIFY_TOL,
    _WRIST_NEAR_SINGULAR,
    _WRIST_SINGULAR,
    _branches_many,
    _nearest_chain,
    _pose_errors_many,
)
from .ik_nearest import _nearest_equivalent, _nearest_search, _nearest_solution, _singular_q6, _wrap, _wrist1_planar
from .ur_fk import ur_reproduces

__all__ = [
    "DH",
    "UR3E_DH",
    "dh_forward",
    "dh_urdf",
    "ur_ik",
    "ur_ik_all",
    "ur_ik_all_many",
    "ur_reach",
]

_UNIT_WEIGHTS = (1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
_JOINT_NAMES = (
    "joint 1 (base)",
    "joint 2 (shoulder)",
    "joint 3 (elbow)",
    "joint 4 (wrist 1)",
    "joint 5 (wrist 2)",
    "joint 6 (wrist 3)",
)

#: UR3e (e-series) nominal DH parameters, m / rad (from :data:`robocritics.robot.arms.UR3E`).
UR3E_DH = UR3E.dh


# --------------------------------------------------------------------------- #
# Forward kinematics: Pinocchio on the URDF of the DH chain
# --------------------------------------------------------------------------- #


def dh_urdf(dh: DH, name: str | None = None, base: str = "base_link", tip: str = "tool0") -> str:
    """A minimal URDF of the DH chain (the model behind :func:`dh_forward` and the IK check).

    Joint ``i`` (``joint_1`` ... ``joint_6``, revolute about its local z, limits
    ±2π rad) sits at the end of the fixed part ``Tz(d) Tx(a) Rx(alpha)`` of link
    ``i - 1``, i.e. URDF origin ``xyz = (a, 0, d)``, ``rpy = (alpha, 0, 0)``; a
    fixed joint carries ``A_6``'s fixed part to the flange link ``tip``. Every
    link gets a small inertia so that parsers that require one are satisfied.
    """
    name = name or dh.name
    links = [base] + [f"link_{i}" for i in range(1, 7)] + [tip]
    inertial = (
        '<inertial><origin xyz="0 0 0" rpy="0 0 0"/><mass value="0.5"/>'
        '<inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial>'
    )
    out = ['<?xml version="1.0"?>', f'<robot name="{name}">']
    for link in links:
        out.append(f'  <link name="{link}">{inertial}</link>')
    prev_a, prev_d, prev_alpha = 0.0, 0.0, 0.0
    for i in range(6):
        out.append(
            f'  <joint name="joint_{i + 1}" type="revolute">'
            f'<parent link="{links[i]}"/><child link="{links[i + 1]}"/>'
            f'<origin xyz="{prev_a!r} 0 {prev_d!r}" rpy="{prev_alpha!r} 0 0"/>'
            f'<axis xyz="0 0 1"/>'
            f'<limit lower="{-_TWO_PI!r}" upper="{_TWO_PI!r}" effort="100" velocity="3.14159"/>'
            f"</joint>"
        )
        prev_a, prev_d, prev_alpha = dh.a[i], dh.d[i], dh.alpha[i]
    out.append(
        f'  <joint name="flange" type="fixed"><parent link="{links[6]}"/><child link="{tip}"/>'
        f'<origin xyz="{prev_a!r} 0 {prev_d!r}" rpy="{prev_alpha!r} 0 0"/></joint>'
    )
    out.append("</robot>")
    return "\n".join(out)


_CHAIN_MODELS: dict[DH, tuple[Any, int]] = {}
_THREAD = threading.local()  # Pinocchio Data is scratch space: one per thread and chain


class _Chain:
    """Flange FK of one DH chain: its Pinocchio model and this thread's Data."""

    __slots__ = ("model", "data", "flange")

    def __init__(self, dh: DH):
        import pinocchio as pin  # here: a check needs this chain only to explain a failed solve (~30-60 ms import)

        entry = _CHAIN_MODELS.get(dh)
        if entry is None:
            model = pin.buildModelFromXML(dh_urdf(dh))
            # setdefault: if two threads build it at once, both use the first
            entry = _CHAIN_MODELS.setdefault(dh, (model, model.getFrameId("tool0", pin.FrameType.BODY)))
        self.model, self.flange = entry
        datas = getattr(_THREAD, "datas", None)
        if datas is None:
            datas = _THREAD.datas = {}
        data = datas.get(dh)
        if data is None:
            data = datas[dh] = self.model.createData()
        self.data = data

    def pose(self, q) -> Any:
        """Flange placement ``pin.SE3`` for joints ``q`` (6 rad)."""
        import pinocchio as pin  # loaded by __init__

        pin.forwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return pin.updateFramePlacement(self.model, self.data, self.flange)

    def error(self, q: Sequence[float], t: Sequence[float]) -> tuple[float, float]:
        """(position error m, rotation error rad) of the flange at ``q`` against the 12-float target ``t``."""
        return _pose_error(self.pose(q).homogeneous[:3].ravel().tolist(), t)


def _chain(dh: DH) -> _Chain:
    """This thread's :class:`_Chain` of ``dh``, built once (a solve looks it up instead of building one)."""
    chains = getattr(_THREAD, "chains", None)
    if chains is None:
        chains = _THREAD.chains = {}
    chain = chains.get(dh)
    if chain is None:
        chain = chains[dh] = _Chain(dh)
    return chain


def dh_forward(dh: DH, q: Any) -> np.ndarray:
    """Flange pose ``T_06(q) = A_1 ... A_6`` in the base frame (Pinocchio on :func:`dh_urdf`).

    ``q`` is ``(6,)`` rad → returns ``(4, 4)``; or ``(..., 6)`` → ``(..., 4, 4)``.
    Translation in metres.
    """
    q = np.asarray(q, dtype=float)
    if q.shape[-1:] != (6,):
        raise RobotModelError(f"dh_forward: q must have 6 joint values in its last axis, got shape {q.shape}")
    chain = _chain(dh)
    flat = q.reshape(-1, 6)
    out = np.empty((len(flat), 4, 4))
    for i, qi in enumerate(flat):
        out[i] = chain.pose(qi).homogeneous
    return out.reshape(q.shape[:-1] + (4, 4))


def _pose_error(fk: Sequence[float], target: Sequence[float]) -> tuple[float, float]:
    """(position error m, rotation error rad) between two 12-float row-major poses.

    The rotation error uses ``||R_a - R_b||_F / sqrt(2)``, which equals
    ``2 sin(theta/2)`` for a rotation by ``theta`` between them (≈ theta when small).
    """
    dp = math.sqrt(
        (fk[3] - target[3]) ** 2 + (fk[7] - target[7]) ** 2 + (fk[11] - target[11]) ** 2
    )
    sq = 0.0
    for i in (0, 1, 2, 4, 5, 6, 8, 9, 10):
        e = fk[i] - target[i]
        sq += e * e
    return dp, math.sqrt(0.5 * sq)


# --------------------------------------------------------------------------- #
# Analytic UR inverse kinematics: the steps of the closed form
# --------------------------------------------------------------------------- #


def _pose12(pose: Any) -> list[float]:
    """The top 3 rows of a 4x4 homogeneous transform as 12 plain floats."""
    if isinstance(pose, np.ndarray) and pose.shape == (4, 4):
        t = pose.ravel().tolist()  # one view fewer than pose[:3].ravel(): a tenth of ur_ik's numpy time
        del t[12:]
        return t
    homogeneous = getattr(pose, "homogeneous", None)  # pinocchio.SE3
    arr = np.asarray(homogeneous if homogeneous is not None else pose, dtype=float)
    if arr.shape != (4, 4):
        raise PlanningError(f"target pose must be a 4x4 homogeneous transform, got shape {arr.shape}")
    return arr[:3].ravel().tolist()


def _shoulder_pans(k: tuple[float, ...], t: Sequence[float]) -> tuple[float, float, tuple[float, float]] | None:
    """Step 1: the base-frame (x, y) of the wrist-2 centre ``p5 = p - d6 z6`` and
    the two shoulder pans ``q1 = phi + pi/2 ± acos(d4 / r)``; None when the wrist
    is inside the cylinder of radius ``d4`` around the base axis."""
    d4, d6 = k[3], k[5]
    p5x = t[3] - d6 * t[2]
    p5y = t[7] - d6 * t[6]
    r = math.sqrt(p5x * p5x + p5y * p5y)
    if r == 0.0:
        return None
    ratio = d4 / r
    if not -1.0 - _CLIP_TOL <= ratio <= 1.0 + _CLIP_TOL:
        return None
    ratio = 1.0 if ratio > 1.0 else (-1.0 if ratio < -1.0 else ratio)
    phi = math.atan2(p5y, p5x) + _HALF_PI
    dphi = math.acos(ratio)
    return p5x, p5y, (phi + dphi, phi - dphi)


def _wrists(
    t: Sequence[float], c1: float, s1: float, q6_free: float
) -> tuple[float, tuple[tuple[float, float], tuple[float, float]]]:
    """Steps 2 and 3 for the shoulder pan with cosine ``c1`` and sine ``s1``:
    ``(|sin q5|, ((q5, q6) wrist up, (q5, q6) wrist down))``. At the wrist
    singularity (``|sin q5| < 1e-10``) ``q6`` is ``q6_free``."""
    xx, yx, zx, _, xy, yy, zy = t[:7]
    xz1 = xx * s1 - xy * c1  # z1 = (s1, -c1, 0) in flange axes: cos q6 sin q5
    yz1 = yx * s1 - yy * c1  # -sin q6 sin q5
    zz1 = zx * s1 - zy * c1  # cos q5
    s5abs = math.sqrt(xz1 * xz1 + yz1 * yz1)
    if s5abs < _WRIST_SINGULAR:
        return s5abs, ((math.atan2(s5abs, zz1), q6_free), (math.atan2(-s5abs, zz1), q6_free))
    return s5abs, (
        (math.atan2(s5abs, zz1), math.atan2(-yz1, xz1)),
        (math.atan2(-s5abs, zz1), math.atan2(yz1, -xz1)),
    )


def _elbow(
    k: tuple[float, ...],
    t: Sequence[float],
    c1: float,
    s1: float,
    p5x: float,
    p5y: float,
    s5abs: float,
    q5: float,
    q6: float,
) -> tuple[float, float, float, float] | None:
    """Step 4 for one (shoulder, wrist) branch: ``(cos q3, atan2(Y, X), q2 + q3 + q4, q6)``,
    or None when the wrist-1 centre is out of the elbow's range. Near the wrist
    singularity ``q6`` may come back nudged (see :func:`_singular_q6`)."""
    a2a3_sq, two_a2a3 = k[6], k[7]
    X, Y = _wrist1_planar(k, t, c1, s1, p5x, p5y, q6)
    c3 = (X * X + Y * Y - a2a3_sq) / two_a2a3
    if not -1.0 <= c3 <= 1.0 and s5abs < _WRIST_NEAR_SINGULAR:
        nudged = _singular_q6(k, t, c1, s1, p5x, p5y, q6, c3 > 1.0)
        if nudged is not None:
            q6 = nudged
            X, Y = _wrist1_planar(k, t, c1, s1, p5x, p5y, q6)
            c3 = (X * X + Y * Y - a2a3_sq) / two_a2a3
    if not -1.0 <= c3 <= 1.0:
        if not -1.0 - _CLIP_TOL <= c3 <= 1.0 + _CLIP_TOL:
            return None
        c3 = 1.0 if c3 > 1.0 else -1.0
    xx, yx, zx, _, xy, yy, zy, _, xz, yz, zz, _ = t
    c5 = math.cos(q5)
    s5 = math.sin(q5)
    c6 = math.cos(q6)
    s6 = math.sin(q6)
    # x4 = c5 x5 - s5 z6 with x5 = c6 x6 - s6 y6
    x4x = c5 * (c6 * xx - s6 * yx) - s5 * zx
    x4y = c5 * (c6 * xy - s6 * yy) - s5 * zy
    x4z = c5 * (c6 * xz - s6 * yz) - s5 * zz
    return c3, math.atan2(Y, X), math.atan2(x4z, x4x * c1 + x4y * s1), q6


def _shoulder_lift(k: tuple[float, ...], base: float, q3: float, c3: float) -> float:
    """Step 4, last: ``q2 = atan2(Y, X) - atan2(a3 sin q3, a2 + a3 cos q3)``."""
    a2, a3 = k[1], k[2]
    return base - math.atan2(a3 * math.sin(q3), a2 + a3 * c3)


def _branches(k: tuple[float, ...], t: Sequence[float], q6_free: float) -> list[list[float]]:
    """Every closed-form branch (unwrapped angles, not yet FK-checked, possibly
    duplicated) for the 12-float row-major target ``t``; see the module docstring."""
    return [b for b, _ in _flagged_branches(k, t, q6_free)]


def _flagged_branches(k: tuple[float, ...], t: Sequence[float], q6_free: float) -> list[tuple[list[float], bool]]:
    """:func:`_branches`, each with whether it is exact as :func:`_nearest_search` means it: no step clipped
    (``|d4 / r| <= 1``, ``|cos q3| < 1``) and the wrist away from its singularity (``|sin q5| >=
    _WRIST_NEAR_SINGULAR``, so ``q6`` was neither free nor nudged)."""
    shoulder = _shoulder_pans(k, t)
    if shoulder is None:
        return []
    p5x, p5y, pans = shoulder
    exact_pan = -1.0 <= k[3] / math.sqrt(p5x * p5x + p5y * p5y) <= 1.0  # _shoulder_pans' ratio, not clipped
    out: list[tuple[list[float], bool]] = []
    for q1 in pans:
        c1, s1 = math.cos(q1), math.sin(q1)
        s5abs, wrists = _wrists(t, c1, s1, q6_free)
        for q5, q6 in wrists:
            elbow = _elbow(k, t, c1, s1, p5x, p5y, s5abs, q5, q6)
            if elbow is None:
                continue
            c3, base, q234, q6 = elbow
            exact = exact_pan and s5abs >= _WRIST_NEAR_SINGULAR and -1.0 < c3 < 1.0  # +-1: perhaps clipped
            t3 = math.acos(c3)
            for q3 in (t3, -t3):
                q2 = _shoulder_lift(k, base, q3, c3)
                out.append(([q1, q2, q3, q234 - q2 - q3, q5, q6], exact))
    return out


_REACH_CACHE: dict[DH, float] = {}


def ur_reach(dh: DH) -> float:
    """Largest distance (m) the flange can be from the shoulder (frame-1 origin).

    In frame 1 the flange is ``X + iY = a2 e^{iq2} + a3 e^{iq23} + e^{iq234}(-d6 sin q5 - i d5)``
    in the arm plane and ``d4 + d6 cos q5`` along its normal, so the maximum of
    ``(|a2| + |a3| + sqrt(d5² + d6² sin² q5))² + (d4 + d6 cos q5)²`` over ``q5``.
    """
    v = _REACH_CACHE.get(dh)
    if v is None:
        _, a2, a3, d4, d5, d6, _, _ = dh._ur
        q5 = np.linspace(-_PI, _PI, 200_001)
        ell = abs(a2) + abs(a3) + np.sqrt(d5 * d5 + (d6 * np.sin(q5)) ** 2)
        v = float(np.sqrt(ell * ell + (d4 + d6 * np.cos(q5)) ** 2).max())
        _REACH_CACHE[dh] = v
    return v


def _fmt_pos(t: Sequence[float]) -> str:
    return f"({t[3]:.3f}, {t[7]:.3f}, {t[11]:.3f}) m"


def _diagnose(dh: DH, t: Sequence[float]) -> str:
    """Plain-words reason why the closed form found no branch for target ``t``."""
    k = dh._ur
    d1, a2, a3, d4, d5, d6, _, _ = k
    rot = np.array([t[0:3], t[4:7], t[8:11]])
    if not np.all(np.isfinite(t)):
        return "the target pose contains NaN or infinite values"
    ortho = float(np.abs(rot.T @ rot - np.eye(3)).max())
    if ortho > 1e-6 or np.linalg.det(rot) < 0:
        return f"the target orientation is not a rotation matrix (|R^T R - I| = {ortho:.2g})"
    px, py, pz = t[3], t[7], t[11]
    dist = math.sqrt(px * px + py * py + (pz - d1) ** 2)
    reach = ur_reach(dh)
    if dist > reach:
        return f"out of reach: target is {dist:.3f} m from the shoulder, the arm reaches {reach:.3f} m"
    shoulder = _shoulder_pans(k, t)
    if shoulder is None:
        r = math.hypot(px - d6 * t[2], py - d6 * t[6])
        return (
            f"too close to the base axis: the wrist (flange minus d6 = {d6:.4f} m along the "
            f"flange z-axis) is {r:.3f} m from the base z-axis, and the shoulder offset keeps it "
            f"at least {abs(d4):.3f} m away"
        )
    # planar distance shoulder -> wrist-1 centre over the shoulder/wrist branches
    p5x, p5y, pans = shoulder
    dists: list[float] = []
    for q1 in pans:
        c1, s1 = math.cos(q1), math.sin(q1)
        for _q5, q6 in _wrists(t, c1, s1, 0.0)[1]:
            dists.append(math.hypot(*_wrist1_planar(k, t, c1, s1, p5x, p5y, q6)))
    reach_planar = abs(a2) + abs(a3)
    fold = abs(abs(a2) - abs(a3))
    far = min(dists)
    if far > reach_planar:
        return (
            f"out of reach in this orientation: target is {dist:.3f} m from the shoulder, but "
            f"with the flange oriented this way the wrist would be about {far:.3f} m from the "
            f"shoulder in the arm plane, and upper arm + forearm reach {reach_planar:.3f} m"
        )
    if max(dists) < fold:
        return (
            f"too close to the shoulder: the wrist would be {max(dists):.3f} m from the shoulder "
            f"in the arm plane, and the elbow cannot fold tighter than {fold:.3f} m"
        )
    return (
        f"out of reach in this orientation: target is {dist:.3f} m from the shoulder "
        f"(the arm reaches {reach:.3f} m), but no elbow configuration places the wrist "
        "for this flange orientation"
    )


def ur_ik_all(dh: DH, flange_pose: Any, *, q6_singular: float = 0.0) -> np.ndarray:
    """All closed-form IK solutions of a UR arm for a flange pose.

    ``flange_pose`` is the ``(4, 4)`` pose of ``tool0`` in the base frame (m)
    (a ``pinocchio.SE3`` also works). Returns ``(k, 6)`` joint vectors in rad,
    each wrapped to ``(-pi, pi]``, ``0 <= k <= 8``, duplicates (at shoulder,
    elbow or wrist singularities) removed, every row verified:
    ``dh_forward(dh, q)`` matches the pose within 1e-9 m and 1e-9 rad (rows that
    do not — only possible at the very edge of the workspace — are dropped).
    ``k = 0`` means unreachable; :func:`ur_ik` says why.

    At the wrist singularity (``sin q5 ≈ 0``) ``q6`` is set to ``q6_singular``.
    """
    return np.array(_solutions(dh, _pose12(flange_pose), q6_singular), dtype=float).reshape(-1, 6)


def ur_ik_all_many(dh: DH, flange_poses: Any, *, q6_singular: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """:func:`ur_ik_all` of ``n`` flange poses in one call: the eight branches of every pose as arrays.

    ``flange_poses`` ``(n, 4, 4)`` (m). Returns ``(q (n, 8, 6) rad, valid (n, 8) bool)``: ``q[i][valid[i]]`` is
    ``ur_ik_all(dh, flange_poses[i])`` (the same rows in the same order, equal to the last bit or two: numpy's
    and libm's sines may round differently), each wrapped to ``(-pi, pi]``, duplicates removed, every row within
    1e-9 m and 1e-9 rad of its pose by forward kinematics; invalid rows are NaN. The branches are computed for
    all poses at once (:func:`_branches_many`, one closed-form FK check of all ``8 n`` branches: :func:`_pose_errors_many`); a pose near the wrist
    singularity (``q6`` free: ``q6_singular``) goes through :func:`ur_ik_all`'s scalar steps.
    """
    poses = np.asarray(flange_poses, dtype=float)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise PlanningError(f"ur_ik_all_many: flange_poses must have shape (n, 4, 4), got {poses.shape}")
    n = len(poses)
    targets12 = poses[:, :3].reshape(-1, 12)
    q, valid, scalar = _branches_many(dh._ur, targets12)
    with np.errstate(invalid="ignore"):  # the rows of branches that do not exist are garbage (NaN)
        # _wrap elementwise, bit for bit: fmod is exact, and so is the one shift by 2 pi of a remainder beyond pi
        q = np.fmod(q, _TWO_PI)
        q = np.where(q > _PI, q - _TWO_PI, q)
        q = np.where(q <= -_PI, q + _TWO_PI, q)
        dp, dr = _pose_errors_many(dh._ur, q.reshape(-1, 6), np.repeat(targets12, 8, axis=0))
        valid = valid & (dp <= _VERIFY_TOL).reshape(n, 8) & (dr <= _VERIFY_TOL).reshape(n, 8)
    # _is_duplicate against the rows kept before, branch by branch (all poses at once)
    for j in range(1, 8):
        near = np.abs(np.fmod(q[:, j : j + 1] - q[:, :j], _TWO_PI))  # within the tolerance of 0 or of 2 pi
        same = (near < _DUPLICATE_TOL) | (near > _TWO_PI - _DUPLICATE_TOL)
        valid[:, j] &= ~(same.all(axis=2) & valid[:, :j]).any(axis=1)
    for i in np.flatnonzero(scalar).tolist():
        rows = _solutions(dh, targets12[i].tolist(), q6_singular)
        valid[i] = np.arange(8) < len(rows)
        q[i, : len(rows)] = rows
    q[~valid] = np.nan
    return q, valid


def _solutions(dh: DH, t: Sequence[float], q6_singular: float) -> list[list[float]]:
    """:func:`ur_ik_all` for the 12-float target ``t``."""
    k = dh._ur
    sols: list[list[float]] = []
    remainder = math.remainder
    certified = _certified(t)  # then an exact branch needs no FK check (see ur_ik)
    for b, exact in _flagged_branches(k, t, q6_singular):
        w = [x + _TWO_PI if x <= -_PI else x for x in [remainder(x, _TWO_PI) for x in b]]  # _wrap
        if not _is_duplicate(w, sols) and ((exact and certified) or ur_reproduces(k, w, t, _VERIFY_TOL)):
            sols.append(w)
    return sols


def _is_duplicate(q: list[float], solutions: list[list[float]]) -> bool:
    """Whether ``q`` is within ``_DUPLICATE_TOL`` rad of one of ``solutions`` in every joint (modulo ``2 pi``)."""
    remainder = math.remainder
    for s in solutions:
        for u, v in zip(q, s):
            # abs(_wrap(x)) < tol without the call: _wrap differs from remainder only at -pi, far from 0
            if not abs(remainder(u - v, _TWO_PI)) < _DUPLICATE_TOL:
                break
        else:
            return True
    return False


def ur_ik(
    dh: DH,
    flange_pose: Any,
    seed: Any,
    lower: Any,
    upper: Any,
    *,
    weights: Any = None,
    tol: float = _VERIFY_TOL,
) -> np.ndarray:
    """The closed-form IK solution nearest to ``seed`` within the joint limits.

    Every branch of the closed form (with its ``2 pi``-shifted equivalents, as
    UR joints range ±2π) is moved per joint to the equivalent within
    ``[lower, upper]`` nearest to ``seed``; the branch with the smallest
    weighted joint distance ``sum_i w_i (q_i - seed_i)²`` (``weights`` default
    all ones) whose forward kinematics reproduces the pose wins. At the wrist
    singularity, ``q6`` keeps the seed's value.

    Arguments: ``flange_pose`` ``(4, 4)`` pose of ``tool0`` in the base frame (m);
    ``seed``, ``lower``, ``upper`` ``(6,)`` rad. Returns ``(6,)`` rad, verified
    by forward kinematics (or certified exact, for ``tol`` at least ``_CERTIFIED_ERROR``) to within
    ``tol`` m and ``tol`` rad.

    Raises :class:`PlanningError` naming the target position and the reason:
    out of reach (with the distance from the shoulder and the arm's reach), too
    close to the base axis, "no solution within the joint limits (branches
    found: k; the joints that rule them out)", or, at the very edge of the
    workspace, that no branch reproduces the pose.
    """
    k = dh._ur
    t = _pose12(flange_pose)
    sd = seed.tolist() if isinstance(seed, np.ndarray) else [float(v) for v in seed]
    lo = lower.tolist() if isinstance(lower, np.ndarray) else [float(v) for v in lower]
    hi = upper.tolist() if isinstance(upper, np.ndarray) else [float(v) for v in upper]
    if len(sd) != 6 or len(lo) != 6 or len(hi) != 6:
        raise PlanningError("ur_ik: seed, lower and upper must each have 6 values")
    if weights is None:
        w = _UNIT_WEIGHTS
    else:
        w = weights.tolist() if isinstance(weights, np.ndarray) else [float(v) for v in weights]
    # The nearest branch nearly always reproduces the pose: certainly when _certified, else checked by the
    # closed-form FK (ur_fk); only at the edge of the workspace does it not, and then the search is repeated
    # checking every candidate.
    found = _nearest_search(k, t, sd, lo, hi, w)
    if found is not None:
        best = found[1]
        if (found[2] and tol >= _CERTIFIED_ERROR and _certified(t)) or ur_reproduces(k, best, t, tol):
            return np.array(best)
        best = _nearest_solution(k, t, sd, lo, hi, w, lambda q: ur_reproduces(k, q, t, tol))
        if best is not None:
            return np.array(best)
    raise PlanningError(
        f"cannot reach flange target {_fmt_pos(t)}: {_why_no_solution(dh, t, sd, lo, hi, _chain(dh), tol)}"
    )


#: Largest rotation-matrix defect (the root of the sum of the squares of ``|x6|² - 1``, ``|z6|² - 1``, ``x6 · z6``
#: and the entries of ``y6 - z6 × x6``) of a target :func:`_certified` accepts, and its square.
_ROTATION_DEFECT = 1e-12
_ROTATION_DEFECT_SQ = _ROTATION_DEFECT * _ROTATION_DEFECT
#: Flange error (m, rad) a certified branch stays below (``tests/test_ik_nearest.py`` asserts it on branches at
#: every singularity); ``ur_ik`` relies on the certificate only for tolerances at least this large.
_CERTIFIED_ERROR = 1e-11


def _certified(t: Sequence[float]) -> bool:
    """Whether a branch that :func:`_nearest_search` calls exact (no step clipped or nudged, the wrist away from
    its singularity, no joint clamped onto a limit) reproduces the 12-float target ``t`` without a
    forward-kinematics check: whether ``t``'s rotation ``[x6 y6 z6]`` is one (orthonormal, right-handed: defect
    within :data:`_ROTATION_DEFECT`).

    When no step is clipped, each step of the closed form solves its equation exactly for such a target, so the
    branch reproduces it to rounding (about 1e-15 m and rad; the FK check would pass): 30 multiplications
    instead of the FK's 60 and twelve sines."""
    xx, yx, zx, _, xy, yy, zy, _, xz, yz, zz, _ = t
    e1 = xx * xx + xy * xy + xz * xz - 1.0
    e2 = zx * zx + zy * zy + zz * zz - 1.0
    e3 = xx * zx + xy * zy + xz * zz
    e4 = yx - (zy * xz - zz * xy)
    e5 = yy - (zz * xx - zx * xz)
    e6 = yz - (zx * xy - zy * xx)
    return (
        e1 * e1 + e2 * e2 + e3 * e3 + e4 * e4 + e5 * e5 + e6 * e6 <= _ROTATION_DEFECT_SQ
    )  # fmt: skip


def ur_ik_line(
    dh: DH, flange_poses: np.ndarray, seed: Any, lower: Any, upper: Any, *, tol: float = _VERIFY_TOL
) -> tuple[np.ndarray, PlanningError | None]:
    """:func:`ur_ik` along a path, each pose seeded by the previous solution.

    ``flange_poses`` ``(n, 4, 4)`` (m); ``seed``, ``lower``, ``upper`` ``(6,)`` rad. Row ``i`` of the result is
    ``ur_ik(dh, flange_poses[i], q[i - 1], lower, upper, tol=tol)`` (``q[-1]`` is ``seed``) without the per-call
    conversions; on a long path the same branch, equal to the last bit or two (the branches of all poses are
    computed at once in numpy, see :func:`_unverified_walk`). Returns ``(q (m, 6) rad, error)``: ``m = n`` and
    ``error`` None when every pose is solved, else the ``m`` solved rows and the :class:`PlanningError`
    :func:`ur_ik` raises for pose ``m``.
    """
    k = dh._ur
    poses = np.asarray(flange_poses, dtype=float)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise PlanningError(f"ur_ik_line: flange_poses must have shape (n, 4, 4), got {poses.shape}")
    seed_arr = np.asarray(seed, dtype=float).ravel()
    lo_arr = np.asarray(lower, dtype=float).ravel()
    hi_arr = np.asarray(upper, dtype=float).ravel()
    if len(seed_arr) != 6 or len(lo_arr) != 6 or len(hi_arr) != 6:
        raise PlanningError("ur_ik_line: seed, lower and upper must each have 6 values")
    lo, hi = lo_arr.tolist(), hi_arr.tolist()
    w = (1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    n = len(poses)
    targets12 = poses[:, :3].reshape(-1, 12)
    targets = targets12.tolist()
    # First the nearest branches unverified, each seeded by the previous, up to the first pose without a
    # solution; the leading rows _certified stand (they reproduce their poses to rounding, within tol / 2); then
    # one vectorised FK check of the rest: rows it puts within tol / 2 (the FKs agree to ~1e-15) are what
    # ur_ik's own check accepts, so they stand; from the first other row on, ur_ik's steps exactly (check per
    # pose, the verified search if needed).
    fast, m, certified = _unverified_walk(k, targets12, targets, seed_arr, lo_arr, hi_arr, 0.5 * tol >= _CERTIFIED_ERROR)
    good = m
    if certified < m:
        dp, dr = _flange_errors(dh, fast[certified:m], poses[certified:m])
        bad = np.flatnonzero(~((dp <= 0.5 * tol) & (dr <= 0.5 * tol)))
        if len(bad):
            good = certified + int(bad[0])
    if good == n:
        return fast, None
    out = fast[:good].tolist()
    sd_list = out[-1] if out else seed_arr.tolist()
    for t in targets[good:]:
        best = _nearest_solution(k, t, sd_list, lo, hi, w)
        if best is not None and not ur_reproduces(k, best, t, tol):
            best = _nearest_solution(k, t, sd_list, lo, hi, w, lambda q: ur_reproduces(k, q, t, tol))
        if best is None:
            reason = _why_no_solution(dh, t, sd_list, lo, hi, _chain(dh), tol)
            return np.array(out, dtype=float).reshape(-1, 6), PlanningError(
                f"cannot reach flange target {_fmt_pos(t)}: {reason}"
            )
        out.append(best)
        sd_list = best
    return np.array(out, dtype=float).reshape(-1, 6), None


def _unverified_walk(
    k: tuple[float, ...], targets12: np.ndarray, targets: list[list[float]], seed: np.ndarray, lo: np.ndarray,
    hi: np.ndarray, certify: bool,
) -> tuple[np.ndarray, int, int]:
    """:func:`_nearest_solution` (unit weights, unverified) at each of the 12-float targets ``targets12 (n, 12)``
    (``targets`` as lists) in turn, seeded by the previous one's result (the first by ``seed``):
    ``(solutions (m, 6) rad, m, c)``, ``m`` the first target without a solution (``n`` if none), ``c`` how many
    leading solutions are exact branches of :func:`_certified` targets (0 unless ``certify``).

    Up to :data:`_VECTORISED_WALK_POSES` poses, pose by pose; longer walks solve the branches of all poses at once
    (:func:`_branches_many`, :func:`_nearest_chain`, in runs of at most :data:`_LINE_CHUNK` poses; none
    certified), which costs a fixed ~0.9 ms of numpy calls and then half the time per pose; a pose the chain
    leaves out (the wrist singularity, no branch within the limits) goes to :func:`_nearest_solution`.
    """
    n = len(targets)
    w = (1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    lo_list, hi_list = lo.tolist(), hi.tolist()
    if n < _VECTORISED_WALK_POSES:
        sd = seed.tolist()
        rows = []
        certified = 0
        for t in targets:
            found = _nearest_search(k, t, sd, lo_list, hi_list, w)
            if found is None:
                break
            sd = found[1]
            rows.append(sd)
            if certify:
                if found[2] and _certified(t):
                    certified += 1
                else:
                    certify = False
        return np.array(rows, dtype=float).reshape(-1, 6), len(rows), certified
    fast = np.empty((n, 6))
    branches, exists, _ = _branches_many(k, targets12)
    m = 0
    sd = seed
    while m < n:
        stop = min(n, m + _LINE_CHUNK)
        run, solved = _nearest_chain(branches[m:stop], exists[m:stop], sd, lo, hi)
        fast[m : m + solved] = run
        m += solved
        if solved:
            sd = fast[m - 1]
        if m == stop:
            continue
        best = _nearest_solution(k, targets[m], sd.tolist(), lo_list, hi_list, w)
        if best is None:
            break
        fast[m] = best
        sd = fast[m]
        m += 1
    return fast[:m], m, 0



def _flange_errors(dh: DH, q: np.ndarray, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position error m, rotation error rad) ``(n,)`` each of the flange at ``q (n, 6)`` rad against ``poses
    (n, 4, 4)``, as :func:`_pose_error`: ``T_06 = prod_i Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i)`` in numpy."""
    # the six link transforms of every row at once (n, 6, 4, 4), then their product in order
    ct, st = np.cos(q), np.sin(q)
    alpha = np.asarray(dh.alpha, dtype=float)
    ca, sa = np.cos(alpha), np.sin(alpha)
    a, d = np.asarray(dh.a, dtype=float), np.asarray(dh.d, dtype=float)
    A = np.zeros(q.shape + (4, 4))
    A[..., 0, 0], A[..., 0, 1], A[..., 0, 2], A[..., 0, 3] = ct, -st * ca, st * sa, a * ct
    A[..., 1, 0], A[..., 1, 1], A[..., 1, 2], A[..., 1, 3] = st, ct * ca, -ct * sa, a * st
    A[..., 2, 1], A[..., 2, 2], A[..., 2, 3] = sa, ca, d
    A[..., 3, 3] = 1.0
    T = A[:, 0]
    for i in range(1, 6):
        T = T @ A[:, i]
    e = T[:, :3] - poses[:, :3]
    dp = np.sqrt((e[:, :, 3] ** 2).sum(axis=1))
    dr = np.sqrt(0.5 * (e[:, :, :3] ** 2).sum(axis=(1, 2)))
    return dp, dr


def _why_no_solution(
    dh: DH, t: Sequence[float], sd: Sequence[float], lo: Sequence[float], hi: Sequence[float], chain: _Chain, tol: float
) -> str:
    """Why :func:`ur_ik` found nothing: the pose is unreachable, or every exact
    solution is outside the joint limits (and which joints rule them out)."""
    solutions = _solutions(dh, t, sd[5])
    blocked: dict[int, int] = {}
    for q in solutions:
        for j in range(6):
            if _nearest_equivalent(q[j], sd[j], lo[j], hi[j]) is None:
                blocked[j] = blocked.get(j, 0) + 1
                break
    if solutions and sum(blocked.values()) == len(solutions):
        which = "".join(
            f"; {_JOINT_NAMES[j]} [{lo[j]:.3f}, {hi[j]:.3f}] rad rules out {c}" for j, c in sorted(blocked.items())
        )
        return f"no solution within the joint limits (branches found: {len(solutions)}{which})"
    branches = _branches(dh._ur, t, sd[5])
    if not branches:
        return _diagnose(dh, t)
    worst = min(chain.error(b, t) for b in branches)
    return (
        f"at the edge of the workspace, no branch reproduces the pose within {tol:g} m / {tol:g} rad "
        f"(best: {worst[0]:.2g} m, {worst[1]:.2g} rad); {_diagnose(dh, t)}"
    )


