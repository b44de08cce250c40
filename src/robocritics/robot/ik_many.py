"""The UR closed-form IK for many poses at once (the straight lines of :func:`robocritics.robot.ik.ur_ik_line`):
the eight branches of every pose as arrays, and the branch nearest the previous pose chained along the line; and
the closed form's tolerances, which :mod:`robocritics.robot.ik` shares. rad, m.
"""

from __future__ import annotations

import math

import numpy as np

__all__: list[str] = []  # the closed form's internals: robocritics.robot.ik is the API



_PI = math.pi
_TWO_PI = 2.0 * math.pi
_HALF_PI = 0.5 * math.pi
# |arg| of acos may exceed 1 by this much from rounding and still be clipped;
# beyond it the target is genuinely out of reach. The FK check decides the rest.
_CLIP_TOL = 1e-8
# |sin q5| below this is the wrist singularity (q6 is then a free choice). At
# this size any choice of q6 costs at most pi * 1e-10 rad of orientation error.
_WRIST_SINGULAR = 1e-10
# Below this |sin q5| the computed q6 is only known to ~1e-16 / |sin q5| rad; if
# that leaves the wrist just out of the elbow's range (a pose at the edge of
# the workspace), q6 is nudged to the nearest value that reaches, which moves
# the flange orientation by at most |sin q5| times the nudge. The FK check
# below has the last word.
_WRIST_NEAR_SINGULAR = 1e-6
# Forward-kinematics acceptance of a branch: position (m) and rotation (rad).
_VERIFY_TOL = 1e-9
# Branches closer than this (rad, every joint) are one configuration (they
# differ only by rounding at a shoulder, elbow or wrist singularity).
_DUPLICATE_TOL = 1e-7
# A solution this close outside a joint limit (rad) counts as on it and is
# clamped to it (the closed form is accurate to ~1e-11 rad near singularities).
_LIMIT_SLACK = 1e-10
# --------------------------------------------------------------------------- #
# The closed form for many poses at once (straight lines: ur_ik_line)
# --------------------------------------------------------------------------- #

#: Branch index ``b = 4 s + 2 w + e`` of :func:`_branches_many`: shoulder pan ``s`` (``phi + dphi``, ``phi -
#: dphi``), wrist ``w`` (up, down), elbow ``e`` (``q3 = +acos``, ``-acos``): the order :func:`_branches` lists them.
_SHOULDER_OF_BRANCH = np.arange(8) // 4
_WRIST_OF_BRANCH = (np.arange(8) // 2) % 2
_ELBOW_OF_BRANCH = np.arange(8) % 2
#: Passes of the chained selection (see :func:`_nearest_chain`) before the rest is taken one pose per pass.
_CHAIN_PASSES = 6
#: Most poses of a straight line solved in one vectorised run (see :func:`ur_ik_line`).
_LINE_CHUNK = 256
#: Fewest poses :func:`_unverified_walk` solves vectorised: below this a pose-by-pose walk is cheaper (measured
#: on the UR3e, fingers-down vertical lines, CPU of ``ur_ik_line``: 0.66 vs 0.97 ms at 100 poses, 2.0 vs 2.0 at
#: 300, 6.7 vs 5.6 at 1000; the pose-by-pose walk needs no FK check of certified poses).
_VECTORISED_WALK_POSES = 300


def _branches_many(k: tuple[float, ...], t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every branch of the closed form for ``n`` poses at once: the steps of :func:`_branches` in numpy.

    ``t`` ``(n, 12)``: row-major flange targets (m). Returns ``(q (n, 8, 6) rad, unwrapped, in the order of
    :data:`_SHOULDER_OF_BRANCH`; exists (n, 8) bool; scalar (n,) bool)``. ``exists`` is False where the wrist is
    inside the base cylinder or the elbow cannot reach (those ``q`` are garbage). ``scalar`` marks poses near the
    wrist singularity (``|sin q5| < _WRIST_NEAR_SINGULAR``), where ``q6`` depends on the seed and may be nudged:
    their branches are not computed here (the caller takes :func:`_nearest_solution` for them). Each expression
    is :func:`_branches`' in the same order, so the angles agree with it to the last bit or two (numpy's and
    libm's transcendental functions may round differently).
    """
    d1, a2, a3, d4, d5, d6, a2a3_sq, two_a2a3 = k
    n = len(t)
    xx, yx, zx, px, xy, yy, zy, py, xz, yz, zz, pz = (t[:, i : i + 1] for i in range(12))
    with np.errstate(invalid="ignore", divide="ignore"):
        # step 1: the shoulder pans (n, 2)
        p5x = px - d6 * zx
        p5y = py - d6 * zy
        r = np.sqrt(p5x * p5x + p5y * p5y)
        ratio = d4 / r
        shoulder_ok = (r != 0.0) & (-1.0 - _CLIP_TOL <= ratio) & (ratio <= 1.0 + _CLIP_TOL)
        phi = np.arctan2(p5y, p5x) + _HALF_PI
        dphi = np.arccos(np.clip(ratio, -1.0, 1.0))
        q1 = np.concatenate([phi + dphi, phi - dphi], axis=1)
        c1, s1 = np.cos(q1), np.sin(q1)
        # steps 2 and 3: the wrists (n, 2 shoulders, 2 wrists)
        xz1 = xx * s1 - xy * c1
        yz1 = yx * s1 - yy * c1
        zz1 = zx * s1 - zy * c1
        s5abs = np.sqrt(xz1 * xz1 + yz1 * yz1)
        q5 = np.stack([np.arctan2(s5abs, zz1), np.arctan2(-s5abs, zz1)], axis=2)
        q6 = np.stack([np.arctan2(-yz1, xz1), np.arctan2(yz1, -xz1)], axis=2)
        scalar = (s5abs < _WRIST_NEAR_SINGULAR).any(axis=1) & shoulder_ok[:, 0]
        # step 4: the elbow of each (shoulder, wrist)
        C1, S1 = c1[:, :, None], s1[:, :, None]
        P5x, P5y = p5x[:, :, None], p5y[:, :, None]
        XX, YX, ZX, XY, YY, ZY, XZ, YZ, ZZ, PZ = (v[:, :, None] for v in (xx, yx, zx, xy, yy, zy, xz, yz, zz, pz))
        c6, s6 = np.cos(q6), np.sin(q6)
        z4x = -(s6 * XX + c6 * YX)
        z4y = -(s6 * XY + c6 * YY)
        z4z = -(s6 * XZ + c6 * YZ)
        X = (P5x - d5 * z4x) * C1 + (P5y - d5 * z4y) * S1
        Y = PZ - d6 * ZZ - d5 * z4z - d1
        c3 = (X * X + Y * Y - a2a3_sq) / two_a2a3
        elbow_ok = (-1.0 - _CLIP_TOL <= c3) & (c3 <= 1.0 + _CLIP_TOL)
        c3 = np.clip(c3, -1.0, 1.0)
        c5, s5 = np.cos(q5), np.sin(q5)
        x4x = c5 * (c6 * XX - s6 * YX) - s5 * ZX
        x4y = c5 * (c6 * XY - s6 * YY) - s5 * ZY
        x4z = c5 * (c6 * XZ - s6 * YZ) - s5 * ZZ
        base = np.arctan2(Y, X)
        q234 = np.arctan2(x4z, x4x * C1 + x4y * S1)
        t3 = np.arccos(c3)
        # the two elbows (n, 2, 2, 2)
        q3 = np.stack([t3, -t3], axis=3)
        q2 = base[..., None] - np.arctan2(a3 * np.sin(q3), a2 + a3 * c3[..., None])
        q4 = q234[..., None] - q2 - q3
    q = np.empty((n, 2, 2, 2, 6))
    q[..., 0] = q1[:, :, None, None]
    q[..., 1], q[..., 2], q[..., 3] = q2, q3, q4
    q[..., 4], q[..., 5] = q5[..., None], q6[..., None]
    exists = np.broadcast_to((shoulder_ok[:, :, None] & elbow_ok)[..., None], (n, 2, 2, 2))
    return q.reshape(n, 8, 6), exists.reshape(n, 8) & ~scalar[:, None], scalar


def _nearest_equivalents(x: np.ndarray, seed: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_nearest_equivalent` elementwise: ``(x + 2 pi n within [lo, hi] nearest to seed, whether one fits)``.

    The same operations in the same order (``np.round`` rounds half to even, as ``round``), so bit-identical.
    """
    v = x + np.round((seed - x) / _TWO_PI) * _TWO_PI
    inside = (lo <= v) & (v <= hi)
    if inside.all():  # the common case
        return v, inside
    with np.errstate(invalid="ignore"):
        n_min = np.ceil((lo - _LIMIT_SLACK - x) / _TWO_PI)
        n_max = np.floor((hi + _LIMIT_SLACK - x) / _TWO_PI)
        fits = n_min <= n_max
        shifted = x + np.where(v > hi, n_max, n_min) * _TWO_PI
        shifted = np.where(shifted > hi, hi, np.where(shifted < lo, lo, shifted))
    return np.where(inside, v, shifted), inside | fits


def _select_nearest(
    q: np.ndarray, exists: np.ndarray, seeds: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """For each pose, :func:`_nearest_solution`'s choice among its branches ``q (m, 8, 6)`` (``exists (m, 8)``)
    for the seed ``seeds (m, 6)`` (unit weights, no verification): ``(solution (m, 6) rad, found (m,))``.

    The cost of a branch is summed in the order the branch-and-bound search adds it (``q1``, ``q5``, ``q6``,
    ``q3``, ``q2``, ``q4``), so it is the same float; the search returns the first branch of least cost in its
    order (shoulders and then wrists by increasing partial cost, a later one only when strictly cheaper; elbow
    ``+acos`` before ``-acos``), and so does the tie-break here. Rows not found are NaN.
    """
    m = len(q)
    v, fits = _nearest_equivalents(q, seeds[:, None, :], lo, hi)
    d = v - seeds[:, None, :]
    c = d * d
    cost1 = c[:, :, 0]
    cost56 = cost1 + c[:, :, 4] + c[:, :, 5]
    total = cost56 + c[:, :, 2] + c[:, :, 1] + c[:, :, 3]
    ok = exists & fits.all(axis=2)
    total = np.where(ok, total, np.inf)
    # the search order: a shoulder is listed when its q1 fits, a wrist when its q5 and q6 fit
    shoulder_listed = fits[:, (0, 4), 0]  # (m, 2)
    swap_shoulders = shoulder_listed.all(axis=1) & (cost1[:, 4] < cost1[:, 0])
    wrist_listed = fits[:, (0, 2, 4, 6)][:, :, (4, 5)].all(axis=2).reshape(m, 2, 2)
    wrist_cost = cost56[:, (0, 2, 4, 6)].reshape(m, 2, 2)
    swap_wrists = wrist_listed.all(axis=2) & (wrist_cost[:, :, 1] < wrist_cost[:, :, 0])  # (m, 2 shoulders)
    rank = (
        4 * (_SHOULDER_OF_BRANCH ^ swap_shoulders[:, None])
        + 2 * (_WRIST_OF_BRANCH ^ swap_wrists[:, _SHOULDER_OF_BRANCH])
        + _ELBOW_OF_BRANCH
    )
    least = total.min(axis=1)
    found = np.isfinite(least)
    pick = np.argmin(np.where(total == least[:, None], rank, 8), axis=1)
    out = v[np.arange(m), pick]
    out[~found] = np.nan
    return out, found


def _nearest_chain(
    q: np.ndarray, exists: np.ndarray, seed: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, int]:
    """The nearest branch of each pose seeded by the previous pose's choice (the first by ``seed``):
    ``(solutions (m, 6) rad, m)``, ``m`` the first pose with no branch within the limits, or one that
    :func:`_branches_many` leaves to :func:`_nearest_solution` (``n`` if none).

    The choice of pose ``i`` depends on that of ``i - 1``. Rather than a Python step per pose, every pose is
    solved at once for guessed seeds (the previous pass's choices, shifted by one pose), and again until the
    seeds reproduce themselves: then each row is exactly what the pose-by-pose walk chooses. A pass fixes at
    least the first pose whose seed was wrong; along a smooth line the second pass confirms the first. After
    :data:`_CHAIN_PASSES` passes the rest is finished a pose per pass (the same result, only slower).
    """
    n = len(q)
    seeds = np.empty((n, 6))
    seeds[:] = seed
    out = np.empty((n, 6))
    done = 0  # seeds[:done + 1] are the walk's own
    passes = 0
    while done < n:
        passes += 1
        stop = n if passes <= _CHAIN_PASSES else done + 1
        sol, found = _select_nearest(q[done:stop], exists[done:stop], seeds[done:stop], lo, hi)
        out[done:stop] = sol
        # the first pose past `done` whose guessed seed is not the choice before it (NaN never equals)
        wrong = np.flatnonzero((seeds[done + 1 : stop] != sol[:-1]).any(axis=1))
        good_to = done + 1 + int(wrong[0]) if len(wrong) else stop
        missing = np.flatnonzero(~found[: good_to - done])
        if len(missing):
            return out[: done + int(missing[0])], done + int(missing[0])
        seeds[good_to:stop] = sol[good_to - done - 1 : stop - done - 1]
        if good_to < n and stop == good_to:
            seeds[good_to] = sol[-1]
        done = good_to
    return out, n


def _pose_errors_many(k: tuple[float, ...], q: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`robocritics.robot.ur_fk.ur_pose_errors` elementwise: ``(position error m, rotation error rad)``
    ``(m,)`` each of the flange at ``q (m, 6)`` rad against the 12-float targets ``t (m, 12)``, by the closed-form
    FK of :mod:`robocritics.robot.ur_fk` (the same expressions, in numpy: some 60 products over ``m`` rows
    instead of a ``(4, 4)`` matrix product per joint)."""
    d1, a2, a3, d4, d5, d6 = k[:6]
    q1, q2, q3, q4, q5, q6 = q.T
    c1, s1 = np.cos(q1), np.sin(q1)
    q23 = q2 + q3
    q234 = q23 + q4
    c234, s234 = np.cos(q234), np.sin(q234)
    c5, s5 = np.cos(q5), np.sin(q5)
    c6, s6 = np.cos(q6), np.sin(q6)
    ux, uy = c234 * c1, c234 * s1
    vx, vy = -s234 * c1, -s234 * s1
    x5x, x5y, x5z = c5 * ux + s5 * s1, c5 * uy - s5 * c1, c5 * s234
    zx, zy, zz = c5 * s1 - s5 * ux, -c5 * c1 - s5 * uy, -s5 * s234
    reach = a2 * np.cos(q2) + a3 * np.cos(q23)
    f = (
        c6 * x5x + s6 * vx, c6 * vx - s6 * x5x, zx, reach * c1 + d4 * s1 - d5 * vx + d6 * zx,
        c6 * x5y + s6 * vy, c6 * vy - s6 * x5y, zy, reach * s1 - d4 * c1 - d5 * vy + d6 * zy,
        c6 * x5z + s6 * c234, c6 * c234 - s6 * x5z, zz, d1 + a2 * np.sin(q2) + a3 * np.sin(q23) - d5 * c234 + d6 * zz,
    )  # fmt: skip
    e = [f[i] - t[:, i] for i in range(12)]
    dp = np.sqrt(e[3] * e[3] + e[7] * e[7] + e[11] * e[11])
    sq = sum(e[i] * e[i] for i in (0, 1, 2, 4, 5, 6, 8, 9, 10))
    return dp, np.sqrt(0.5 * sq)
