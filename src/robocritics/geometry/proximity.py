"""Exact signed distances between the robot's capsules and the scene's shapes, vectorised over samples.

Every length is in metres. A **capsule** is a segment ``p0``-``p1`` (base frame)
swept by a ball of radius ``r``; scene shapes are :class:`~robocritics.scene.Shape`
primitives: ``box`` (``size`` = full extents), ``cylinder`` (``size`` =
``[radius, height]``, axis along the shape's local z) and ``sphere``
(``size = [radius]``), each centred at its 4x4 ``pose``. A pose may also vary
per sample (``(T, 4, 4)``): an object the program moves.

**Signed distance.** For two convex sets A, B the signed distance is their
separation distance when they are apart and ``-(penetration depth)`` when they
overlap, the penetration depth being the length of the shortest translation that
separates them (coal's convention too). For a capsule ``A = S + ball(r)`` around
the segment ``S``::

    sd(A, B) = dist(S, B) - r                    if S does not touch B
    sd(A, B) = -(depth(S, B) + r)                if S meets B

(the Minkowski difference ``B - A`` is ``B - S`` grown by ``r``, so its boundary
is ``r`` further from the origin in every direction). Every capsule distance
thus reduces to the distance or the depth of a *segment*, computed here in
closed form or to machine precision:

* capsule-capsule: closest points of two segments (closed form with clamping,
  robust for parallel and zero-length segments); segments that meet have depth
  0, so ``segment distance - ra - rb`` is exact everywhere.
* capsule-sphere: point-segment distance minus both radii, exact everywhere.
* capsule-box: in the box frame ``f(t) = sum_i max(|a_i + t d_i| - h_i, 0)^2``
  (squared distance of the point ``a + t d``) is convex and piecewise quadratic,
  ``f'`` continuous, piecewise linear and non-decreasing. The slab intervals
  ``[l_i, u_i]`` (where the line is between the faces ``+-h_i``) give
  ``U = min u_i``, ``L = max l_i``: if ``L <= U`` the line passes through the box;
  otherwise the root of ``f'`` lies in ``[U, L]``, where only one axis can still
  switch, and is ``clip(t_mid, t_lo, t_hi)`` of three weighted means
  (:func:`_box_sq`), then clipped to [0, 1]: no sorting, no iteration. A segment
  meeting the box has the depth ``min_n h_Z(n)`` over the facet normals of the
  zonotope ``Z = box - segment`` (the box axes ``e_i`` and ``e_i x d``), also
  closed form (:func:`_seg_box_depth`).
* capsule-cylinder: ``F(t) = max(rho(t) - R, 0)^2 + max(|z(t)| - H, 0)^2`` is
  convex and C1 (``rho`` the distance to the axis). ``F'`` at the ends decides
  most pairs (closest point at an end of the segment); otherwise the root of the
  non-decreasing ``F'`` is found by Newton steps kept in a shrinking bracket
  (false position, then bisection, where Newton leaves it), to ``1e-12`` in ``t``
  or until ``F`` is provably within ``2e-24`` m^2 of its minimum: the distance is
  then good to ~1e-12 m (:func:`_cyl_sq`, :func:`_cyl_sq_inner`). A segment
  meeting the cylinder gets its depth from the finite candidate set of
  ``min_n h_Z(n)``: the caps, the radial directions of both endpoints, and the
  directions orthogonal to the segment, where the problem is the 2-D depth of
  a point in the cylinder's shadow along the segment (a rectangle capped by two
  half ellipses), the distance to a half ellipse using all stationary points
  (roots of a quartic, Newton-polished) and the arc's ends
  (:func:`_seg_cyl_depth`). coal's EPA is not used for this: on cylinders it is
  off by up to ~1e-4 m with its default settings (and by decimetres when its
  tolerance is tightened below 1e-6), and puts a sphere at a cylinder's centre
  out through the side when a cap is nearer.

Measured against coal (GJK at a 1e-12 tolerance; EPA for boxes and capsules)
the closed forms agree to ~1e-15 m, and against brute-force minimisation of the
support function to ~1e-12 m (``tests/test_proximity.py``).

Shape against shape (an object the gripper carries against the others): a
sphere against anything is a point-shape distance minus the radius, closed form
everywhere (a point inside a box or cylinder has the depth of its nearest
face). Box or cylinder against box or cylinder has no closed form in general,
but two closed-form bounds settle most real placements (:func:`_convex_bounds`):
the projection gap ``n.(c_B - c_A) - h_A(n) - h_B(n)`` along any unit ``n`` is
a lower bound of the signed distance (which is the maximum of the gap over
``n``), and the signed distance of any point of one shape to the other an upper
bound. Along the face normals and centre directions, with the support points of
the best one (and a round of alternating projections, :func:`_refine_bounds`),
the two meet to 1e-12 m whenever the nearest feature of one shape is a face of
the other: an object carried over the table, lowered into a bin or set on a
plate. The rest (a rim against an
edge, overlapping cylinders) goes to ``coal.distance``, once per run of samples
in which neither pose changes (~3 us per call), GJK to 1e-10 m when apart, EPA
when overlapping (boxes exact; cylinders to ~1e-5 m): on the six bundled
programs 3,551 of the 12,460 samples coal used to see (:func:`_shape_runs`).

:class:`ProximityKernel` batches it all for a trajectory: built once from the
capsules, the scene shapes, the pairs and the names of the shapes that move,
its :meth:`~ProximityKernel.distances` returns ``(T, K)`` signed distances for
capsule endpoints ``(T, C, 3)``. On a 10,000-sample UR3e trajectory (10
capsules, 27 self pairs, 150 capsule-shape pairs in the breakfast scene) it
takes about 40 ms on one core, and about 30 ms with ``far_m=0.1``
(``benchmarks/bench_proximity.py``: random motions, where most pairs are near).

**Far pairs** (``far_m``): per capsule and block of 32 samples, bounding balls of
the segments give a lower bound of every capsule/box and capsule/cylinder pair's
distance; a pair is evaluated exactly only in the blocks where that bound is
within the cutoff, so on a real program (a few per cent of the pairs near) most
of the exact work is skipped. The cutoff rises per sample to an upper bound of the
least distance of chosen columns (``exact_min_of``), which keeps their minimum
exact: see :meth:`ProximityKernel.distances`.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..scene import Shape

__all__ = [
    "CapsuleSpec",
    "ProximityKernel",
    "segment_distance",
    "capsule_capsule",
    "capsule_sphere",
    "capsule_box",
    "capsule_cylinder",
    "capsule_shape",
    "point_shape",
    "sphere_shape",
    "shape_shape",
    "reduce_min",
]

_FLOAT = np.float64
_EYE3 = np.eye(3)


# ----------------------------------------------------------------------------------------------
# flat kernels: component arrays (broadcastable), float64, no Python loop over samples
# ----------------------------------------------------------------------------------------------


def _dot3(ax, ay, az, bx, by, bz):
    """Component-wise dot product ``a . b`` of vectors given as x, y, z arrays (one fresh array)."""
    out = ax * bx
    out += ay * by
    out += az * bz
    return out


def _seg_seg_sq(ax, ay, az, ux, uy, uz, bx, by, bz, vx, vy, vz):
    """Squared distance (m^2) between segments ``a + s u`` and ``b + t v``, ``s, t`` in [0, 1].

    Closed form (Ericson, *Real-Time Collision Detection* 5.1.9): ``s`` from the
    lines' closest points, clamped; ``t`` optimal for ``s``, clamped; ``s`` optimal
    for that ``t``, clamped. That is Ericson's exact algorithm except that ``s`` is
    always recomputed, an exact one-variable minimisation that can only lower the
    distance. For (nearly) parallel segments the first ``s`` is arbitrary in [0, 1]
    and the two clamped projections still reach the minimum (intervals on a
    common line: projecting any point of one onto the other and back lands in
    their overlap, or on the facing ends); zero-length segments fall out of the
    ``1e-300`` guards.
    """
    rx = ax - bx
    ry = ay - by
    rz = az - bz
    a = _dot3(ux, uy, uz, ux, uy, uz)
    e = _dot3(vx, vy, vz, vx, vy, vz)
    b = _dot3(ux, uy, uz, vx, vy, vz)
    c = _dot3(ux, uy, uz, rx, ry, rz)
    f = _dot3(vx, vy, vz, rx, ry, rz)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        inv_a = 1.0 / (a + 1e-300)
        inv_e = 1.0 / (e + 1e-300)
        den = a * e
        den -= b * b
        np.maximum(den, 1e-300, out=den)
        s = b * f
        s -= c * e
        s /= den
        s = np.clip(s, 0.0, 1.0)
        t = b * s
        t += f
        t *= inv_e
        t = np.clip(t, 0.0, 1.0)
        s = b * t
        s -= c
        s *= inv_a
        s = np.clip(s, 0.0, 1.0)
    wx = s * ux
    wx += rx
    wx -= t * vx
    wy = s * uy
    wy += ry
    wy -= t * vy
    wz = s * uz
    wz += rz
    wz -= t * vz
    wx *= wx
    wy *= wy
    wz *= wz
    wx += wy
    wx += wz
    return wx


def _point_seg_sq(px, py, pz, ax, ay, az, dx, dy, dz, inv_dd=None):
    """Squared distance (m^2) from points ``p`` to segments ``a + t d``, ``t`` in [0, 1] (exact).

    ``inv_dd`` may pass a precomputed ``1 / (|d|^2 + 1e-300)``.
    """
    if inv_dd is None:
        inv_dd = 1.0 / (dx * dx + dy * dy + dz * dz + 1e-300)
    wx = px - ax
    wy = py - ay
    wz = pz - az
    t = _dot3(wx, wy, wz, dx, dy, dz)
    t *= inv_dd
    t = np.clip(t, 0.0, 1.0)
    wx -= t * dx
    wy -= t * dy
    wz -= t * dz
    wx *= wx
    wy *= wy
    wz *= wz
    wx += wy
    wx += wz
    return wx


def _box_prep(dx, dy, dz):
    """Per-segment part of :func:`_box_sq`: ``(-1/d_i, |1/d_i|, d_i^2)`` per axis and ``1/sum d_i^2``.

    A zero component is replaced by ``1e-300``: its weight underflows to 0 and its
    slab covers every realistic ``t``, as for the whole line.
    """
    ninv, ainv, w = [], [], []
    with np.errstate(divide="ignore", over="ignore", under="ignore"):
        for d in (dx, dy, dz):
            ds = np.copysign(1e-300, d)
            ds += d
            ni = np.divide(-1.0, ds)
            ninv.append(ni)
            ainv.append(np.abs(ni))
            ds *= ds
            w.append(ds)
        W = w[0] + w[1]
        W += w[2]
        np.maximum(W, 1e-300, out=W)
        invW = np.divide(1.0, W, out=W)
    return ninv, ainv, w, invW


def _take_prep(prep, rows):
    """The rows ``rows`` of a :func:`_box_prep` result."""
    ninv, ainv, w, invW = prep
    return [v[rows] for v in ninv], [v[rows] for v in ainv], [v[rows] for v in w], invW[rows]


def _box_sq(px, py, pz, dx, dy, dz, prep, cx, cy, cz, hx, hy, hz):
    """Squared distance (m^2) from segments ``p + t d``, ``t`` in [0, 1], to the box ``|x_i - c_i| <= h_i``.

    In the box frame; ``prep = _box_prep(dx, dy, dz)``; box parameters are scalars
    or arrays broadcasting with the segments.

    ``f(t) = sum_i max(|a_i + t d_i| - h_i, 0)^2`` (``a = p - c``) is convex; with the
    slab interval ``[l_i, u_i]`` of axis i (the ``t`` where ``|a_i + t d_i| <= h_i``,
    the whole line when ``d_i = 0``) and weight ``w_i = d_i^2``,
    ``f'(t)/2 = sum_i w_i (t - clip(t, l_i, u_i))``. Let ``U = min u_i`` (axis j),
    ``L = max l_i`` (axis k).

    * ``L <= U`` and ``[L, U]`` meets [0, 1]: the segment meets the box, ``f = 0``.
    * ``L > U``: the line misses; ``f' <= 0`` up to ``U`` and ``>= 0`` from ``L``.
      On ``[U, L]`` axis j is above its slab, axis k below, and only the third
      axis m can change state. With ``l'_i = max(l_i, U)``, ``u'_i = min(u_i, L)``
      (the breakpoints clipped to ``[U, L]``),
      ``sum w_i (t - u'_i) <= f'/2 <= sum w_i (t - l'_i)``, so the root lies between
      ``t_lo = sum w_i l'_i / W`` and ``t_hi = sum w_i u'_i / W``. It is ``t_lo`` if
      m is below its slab there, ``t_hi`` if above, and otherwise the root
      ``t_mid = (w_j U + w_k L) / (w_j + w_k)`` of the j and k terms alone; in all
      three cases ``t* = clip(t_mid, t_lo, t_hi)`` (when m never switches inside
      ``[U, L]``, ``t_lo = t_hi``, so ties between axes change nothing).
    * ``L <= U`` with ``[L, U]`` outside [0, 1]: the same formula gives ``t = L``.

    ``t*`` is clipped to [0, 1] (f is convex) and ``f`` evaluated there: the exact
    squared distance up to rounding, no sorting, no iteration.
    """
    ninv, ainv, (w0, w1, w2), invW = prep
    with np.errstate(invalid="ignore", over="ignore", under="ignore"):
        a, ls, us = [], [], []
        for p, c, h, ni, ai in ((px, cx, hx, ninv[0], ainv[0]), (py, cy, hy, ninv[1], ainv[1]), (pz, cz, hz, ninv[2], ainv[2])):
            ak = p - c
            s = ak * ni  # slab centre (c - p) / d
            hw = ai * h  # slab half width h / |d|
            ls.append(s - hw)
            s += hw
            us.append(s)
            a.append(ak)
        (l0, l1, l2), (u0, u1, u2) = ls, us
        U = np.minimum(u0, u1)
        wj = np.where(u0 <= u1, w0, w1)
        wj = np.where(U <= u2, wj, w2)
        np.minimum(U, u2, out=U)
        L = np.maximum(l0, l1)
        wk = np.where(l0 >= l1, w0, w1)
        wk = np.where(L >= l2, wk, w2)
        np.maximum(L, l2, out=L)
        hit = L <= U
        hit &= L <= 1.0
        hit &= U >= 0.0
        t_lo = np.maximum(l0, U)
        t_lo *= w0
        t_hi = np.minimum(u0, L)
        t_hi *= w0
        for l, u, w in ((l1, u1, w1), (l2, u2, w2)):
            np.maximum(l, U, out=l)
            l *= w
            t_lo += l
            np.minimum(u, L, out=u)
            u *= w
            t_hi += u
        t_lo *= invW
        t_hi *= invW
        U *= wj
        L *= wk
        U += L
        wj += wk
        np.maximum(wj, 1e-300, out=wj)
        U /= wj
        np.maximum(U, t_lo, out=U)
        np.minimum(U, t_hi, out=U)
        t = np.clip(U, 0.0, 1.0, out=U)
        sq = None
        for ak, d, h in zip(a, (dx, dy, dz), (hx, hy, hz)):
            e = t * d
            e += ak
            np.abs(e, out=e)
            e -= h
            np.clip(e, 0.0, None, out=e)
            e *= e
            if sq is None:
                sq = e
            else:
                sq += e
        if hit.any():
            sq[hit] = 0.0
    return sq


def _seg_box_sq(px, py, pz, dx, dy, dz, cx, cy, cz, hx, hy, hz):
    """Squared distance (m^2) from segments ``p + t d`` to boxes ``|x_i - c_i| <= h_i`` (box frame); see :func:`_box_sq`."""
    return _box_sq(px, py, pz, dx, dy, dz, _box_prep(dx, dy, dz), cx, cy, cz, hx, hy, hz)


def _seg_box_depth(ax, ay, az, dx, dy, dz, hx, hy, hz):
    """Penetration depth (m) of segments ``a + t d`` that meet the boxes ``|x_i| <= h_i`` (box frame).

    The depth is the distance from the origin to the boundary of the zonotope
    ``Z = box - segment``, ``min over unit n of h_Z(n)`` with
    ``h_Z(n) = sum_i h_i |n_i| - min(n.a, n.b)``, attained at a facet normal of Z:
    the box axes ``e_i`` and ``e_i x d`` (normalised; skipped when zero). Any other
    unit n only gives an upper bound, so the minimum over these candidates is exact.
    """
    bx, by, bz = ax + dx, ay + dy, az + dz
    depth = None
    for a, b, h in ((ax, bx, hx), (ay, by, hy), (az, bz, hz)):
        c = np.minimum(h - np.minimum(a, b), h + np.maximum(a, b))
        depth = c if depth is None else np.minimum(depth, c)
    # n = e_i x d, with n . d = 0 so min(n.a, n.b) = n.a and the +-n pair gives -|n.a|
    for n1, n2, n3 in (
        ((0.0, -dz, dy)),
        ((dz, 0.0, -dx)),
        ((-dy, dx, 0.0)),
    ):
        nx, ny, nz = (np.asarray(v, dtype=_FLOAT) for v in (n1, n2, n3))
        norm = np.sqrt(nx * nx + ny * ny + nz * nz)
        with np.errstate(divide="ignore", invalid="ignore"):
            c = (hx * np.abs(nx) + hy * np.abs(ny) + hz * np.abs(nz) - np.abs(nx * ax + ny * ay + nz * az)) / norm
        depth = np.minimum(depth, np.where(norm > 1e-12 * np.maximum(np.sqrt(dx * dx + dy * dy + dz * dz), 1e-300), c, np.inf))
    return depth


def _cyl_sq(px, py, pz, dx, dy, dz, A, cx, cy, cz, R, H, tol=1e-12, max_iter=100, defer=False):
    """Squared distance (m^2) from segments ``p + t d`` to the cylinder (centre c, radius R, half height H, axis z).

    In the cylinder frame; ``A = dx^2 + dy^2`` (per segment). With ``a = p - c``,
    ``F(t) = max(rho - R, 0)^2 + max(|a_z + t d_z| - H, 0)^2``, ``rho(t)^2 = A t^2 + 2 B t + C``,
    is the squared distance of a convex set along a line: convex and C1 (the
    radial term vanishes near the axis, where ``rho`` is not smooth). ``F' >= 0`` at
    ``t = 0`` puts the minimiser there, ``F' <= 0`` at ``t = 1`` puts it at 1.
    Otherwise (a few per cent of pairs) the segment is first tested exactly for
    meeting the cylinder (the ``t`` interval inside the z slab and inside
    ``rho <= R``, a quadratic; then ``F = 0``), and if not the root of the
    non-decreasing ``F'`` in the bracket (0, 1) is found by Newton steps (``F''`` of
    the active terms) that fall back to bisection when they leave the bracket,
    until the bracket or the step is below ``tol``. ``F'(t*) = 0``, so the
    distance error is second order in the ``t`` error.

    With ``defer=True`` those interior pairs are left at ``inf`` and returned as
    ``(sq, (index, args))`` for one batched :func:`_cyl_sq_inner` call later
    (``(sq, None)`` when there are none).
    """
    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        ax = px - cx
        ay = py - cy
        az = pz - cz
        B = ax * dx
        B += ay * dy
        C = ax * ax
        C += ay * ay
        shape = B.shape
        # t = 0
        rho0 = np.sqrt(C)
        g0 = B / np.maximum(rho0, 1e-300)
        rho0 -= R
        er0 = np.clip(rho0, 0.0, None, out=rho0)
        g0 *= er0
        ez0 = np.clip(az, -H, H)
        np.subtract(az, ez0, out=ez0)
        g0 += ez0 * dz
        # t = 1
        rho1 = A + C
        rho1 += B
        rho1 += B
        np.clip(rho1, 0.0, None, out=rho1)
        np.sqrt(rho1, out=rho1)
        g1 = A + B
        g1 /= np.maximum(rho1, 1e-300)
        rho1 -= R
        er1 = np.clip(rho1, 0.0, None, out=rho1)
        g1 *= er1
        z1 = az + dz
        ez1 = np.clip(z1, -H, H)
        np.subtract(z1, ez1, out=ez1)
        g1 += ez1 * dz
        er0 *= er0
        ez0 *= ez0
        er0 += ez0
        er1 *= er1
        ez1 *= ez1
        er1 += ez1
        sq = np.where(g0 >= 0.0, er0, er1)
        inner = g0 < 0.0
        inner &= g1 > 0.0
    pending = None
    if inner.any():
        idx = np.nonzero(inner)
        sub = [np.broadcast_to(v, shape)[idx] for v in (ax, ay, az, dx, dy, dz, A, B, C, R, H)]
        if defer:
            sq[idx] = np.inf
            pending = (idx, sub)
        else:
            sq[idx] = _cyl_sq_inner(*sub, tol=tol, max_iter=max_iter)
    return (sq, pending) if defer else sq


def _seg_cyl_sq(px, py, pz, dx, dy, dz, cx, cy, cz, R, H, tol=1e-12, max_iter=100, defer=False):
    """Squared distance (m^2) from segments ``p + t d`` to cylinders (cylinder frame); see :func:`_cyl_sq`."""
    return _cyl_sq(px, py, pz, dx, dy, dz, dx * dx + dy * dy, cx, cy, cz, R, H, tol=tol, max_iter=max_iter, defer=defer)


def _cyl_sq_inner(ax, ay, az, dx, dy, dz, A, B, C, R, H, tol, max_iter):
    """:func:`_cyl_sq` for flat arrays whose minimiser is interior: meet test, then safeguarded Newton.

    Newton steps on ``F'`` from the closest approach to the axis; a step that leaves
    the bracket (near a kink of ``F''``, where the side or a cap starts to count) is
    replaced by a false-position step on the bracket (Illinois variant, so neither end
    stalls), and bisection as the last resort.
    """
    n = ax.size
    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        ds = dz + np.copysign(1e-300, dz)
        z0 = (-H - az) / ds
        z1 = (H - az) / ds
        lo = np.maximum(np.minimum(z0, z1), 0.0)
        hi = np.minimum(np.maximum(z0, z1), 1.0)
        C2 = C - R * R
        disc = B * B - A * C2
        root = np.sqrt(np.maximum(disc, 0.0))
        q = -(B + np.where(B >= 0.0, root, -root))
        r1 = q / A
        r2 = C2 / q
        flat = A <= 1e-300
        lo = np.where(flat, np.where(C2 <= 0.0, lo, np.inf), np.maximum(lo, np.minimum(r1, r2)))
        hi = np.where(flat, hi, np.minimum(hi, np.maximum(r1, r2)))
        lo = np.where(~flat & (disc < 0.0), np.inf, lo)
    out = np.zeros(n)
    todo = np.flatnonzero(~(lo <= hi))  # segments that do not meet the cylinder
    if not todo.size:
        return out
    ax, az, dz, A, B, C, R, H = (v[todo] for v in (ax, az, dz, A, B, C, R, H))

    def grad(t, az, dz, A, B, C, R, H):
        rho = np.sqrt(np.maximum((A * t + 2.0 * B) * t + C, 0.0))
        er = np.maximum(rho - R, 0.0)
        rp = (A * t + B) / np.maximum(rho, 1e-300)
        z = az + t * dz
        ez = z - np.clip(z, -H, H)
        g = er * rp + ez * dz
        h = np.where(er > 0.0, rp * rp + er * (A - rp * rp) / np.maximum(rho, 1e-300), 0.0)
        h += np.where(ez != 0.0, dz * dz, 0.0)
        return g, h

    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        sub = [az, dz, A, B, C, R, H]
        m = todo.size
        lo, hi = np.zeros(m), np.ones(m)
        flo, _ = grad(lo, *sub)  # F'/2 at the bracket ends: < 0 at lo, > 0 at hi
        fhi, _ = grad(hi, *sub)
        glo, ghi = flo.copy(), fhi.copy()  # the same, halved by the Illinois rule, for false position
        ti = np.clip(-B / A, 0.0, 1.0)  # the closest approach to the axis: exact when only the side is active
        ti = np.where(np.isfinite(ti), ti, 0.5)
        last = np.zeros(m)  # which end moved last: -1 lo, +1 hi
        t = np.empty(m)
        pos = np.arange(m)
        for _ in range(max_iter):
            g, h = grad(ti, *sub)
            neg = g <= 0.0
            # Illinois: an end that stays put twice in a row has its value halved
            ghi = np.where(neg & (last < 0), 0.5 * ghi, ghi)
            glo = np.where(~neg & (last > 0), 0.5 * glo, glo)
            lo = np.where(neg, ti, lo)
            flo = np.where(neg, g, flo)
            glo = np.where(neg, g, glo)
            hi = np.where(neg, hi, ti)
            fhi = np.where(neg, fhi, g)
            ghi = np.where(neg, ghi, g)
            last = np.where(neg, -1.0, 1.0)
            tn = ti - g / h  # Newton; where it leaves the bracket (kinks of F''), false position
            bad = ~((tn > lo) & (tn < hi))
            tn = np.where(bad, (lo * ghi - hi * glo) / (ghi - glo), tn)
            tn = np.where((tn > lo) & (tn < hi), tn, 0.5 * (lo + hi))
            # F convex: F(e) - min F <= |F'(e)| (hi - lo) at either end e of the bracket; below
            # 2e-24 m^2 the distance is good to ~1e-12 m even at contact
            w = hi - lo
            at_lo = np.abs(flo) * w <= 1e-24
            at_hi = np.abs(fhi) * w <= 1e-24
            done = at_lo | at_hi | (np.abs(tn - ti) <= tol) | (w <= tol)
            ti = np.where(at_lo, lo, np.where(at_hi, hi, tn))
            if done.all():
                break
            if done.any():
                t[pos[done]] = ti[done]
                keep = ~done
                pos = pos[keep]
                sub = [v[keep] for v in sub]
                lo, hi, ti, last = lo[keep], hi[keep], ti[keep], last[keep]
                flo, fhi, glo, ghi = flo[keep], fhi[keep], glo[keep], ghi[keep]
        t[pos] = ti
    rho = np.sqrt(np.maximum((A * t + 2.0 * B) * t + C, 0.0))
    er = np.maximum(rho - R, 0.0)
    ez = np.maximum(np.abs(az + t * dz) - H, 0.0)
    out[todo] = er * er + ez * ez
    return out


def _dist_upper_half_ellipse(qx, qy, a, b):
    """Distance (m) from points q to the arcs ``(a cos p, b sin p)``, ``p`` in [0, pi] (a > 0, 0 <= b <= a).

    The nearest point is an arc end or a stationary point of
    ``g(p) = (a cos p - qx)^2 + (b sin p - qy)^2``, i.e. ``sin p (A cos p + a qx) = b qy cos p``
    with ``A = b^2 - a^2``; squaring gives a quartic in ``c = cos p`` whose four roots
    (companion-matrix eigenvalues) contain every stationary point. Each root is polished
    by Newton steps on ``g'`` that are only accepted when they decrease ``g``. When the
    quartic degenerates (``b`` within about 1e-3.5 of ``a``: a near circle) the radial
    direction, the projection on the major axis and the top of the arc are polished
    instead. Every candidate is a point of the arc, so the minimum over them is never
    below the true distance, and it contains the true minimiser.
    """
    qx = np.asarray(qx, dtype=_FLOAT) / a
    qy = np.asarray(qy, dtype=_FLOAT) / a
    m = np.asarray(b, dtype=_FLOAT) / a
    n = qx.size
    A = m * m - 1.0  # <= 0

    def g_of(p, qx, qy, m):
        return (np.cos(p) - qx) ** 2 + (m * np.sin(p) - qy) ** 2

    def polish(p, qx, qy, m, A, iters):
        g = g_of(p, qx, qy, m)
        lam = np.ones_like(p)
        for _ in range(iters):
            c, s = np.cos(p), np.sin(p)
            d1 = A * s * c + qx * s - m * qy * c
            d2 = A * (c * c - s * s) + qx * c + m * qy * s
            with np.errstate(divide="ignore", invalid="ignore"):
                step = np.where(d2 > 0.0, -d1 / d2, -np.sign(d1) * 0.1)
            step = np.where(np.isfinite(step), step, 0.0)
            pn = np.clip(p + lam * step, 0.0, np.pi)
            gn = g_of(pn, qx, qy, m)
            acc = gn < g
            p = np.where(acc, pn, p)
            g = np.where(acc, gn, g)
            lam = np.where(acc, 1.0, 0.5 * lam)
        return g

    best = np.minimum(g_of(np.zeros(n), qx, qy, m), g_of(np.full(n, np.pi), qx, qy, m))
    Cq = m * qy
    lead = A * A
    good = lead > 1e-14 * np.maximum(np.maximum(lead, qx * qx + Cq * Cq), 1e-300)
    i = np.flatnonzero(good)
    if i.size:
        Ai, Bi, Ci = A[i], qx[i], Cq[i]
        # -A^2 c^4 - 2AB c^3 + (A^2 - B^2 - C^2) c^2 + 2AB c + B^2 = 0, made monic
        M = np.zeros((i.size, 4, 4))
        M[:, 0, 0] = -2.0 * Bi / Ai
        M[:, 0, 1] = (Ai * Ai - Bi * Bi - Ci * Ci) / (Ai * Ai)
        M[:, 0, 2] = 2.0 * Bi / Ai
        M[:, 0, 3] = (Bi * Bi) / (Ai * Ai)
        M[:, 1, 0] = M[:, 2, 1] = M[:, 3, 2] = 1.0
        roots = np.linalg.eigvals(M).real
        p = np.arccos(np.clip(roots, -1.0, 1.0)).T.ravel()  # (4 * len(i),), root-major
        gi = polish(p, *(np.tile(v[i], 4) for v in (qx, qy, m, A)), iters=4).reshape(4, -1).min(axis=0)
        best[i] = np.minimum(best[i], gi)
    j = np.flatnonzero(~good)
    if j.size:
        qxj, qyj, mj, Aj = qx[j], qy[j], m[j], A[j]
        seeds = np.concatenate(
            [
                np.full(j.size, 0.5 * np.pi),
                np.clip(np.arctan2(qyj, qxj * mj), 0.0, np.pi),
                np.arccos(np.clip(qxj, -1.0, 1.0)),
            ]
        )
        gj = polish(seeds, *(np.tile(v, 3) for v in (qxj, qyj, mj, Aj)), iters=12).reshape(3, -1).min(axis=0)
        best[j] = np.minimum(best[j], gj)
    return np.sqrt(best) * a


def _seg_cyl_depth(ax, ay, az, dx, dy, dz, R, H):
    """Penetration depth (m) of segments ``a + t d`` that meet cylinders (radius R, half height H, local frame).

    ``depth = min over unit n of h_Z(n)``, ``Z = cylinder - segment``,
    ``h_Z(n) = R |n_xy| + H |n_z| - min(n.a, n.b)`` = ``max(g_a(n), g_b(n))`` with
    ``g_e(n) = h_cyl(n) - n.e``. The minimiser is a local minimum of ``g_a`` or
    ``g_b`` (a face normal: a cap ``+-z`` or an endpoint's radial direction) or
    lies where ``g_a = g_b``, i.e. on the unit vectors orthogonal to ``d``. On that
    circle the problem is the 2-D depth of the segment's shadow point ``a'`` in
    the cylinder's shadow along ``d``: the rectangle ``|u| <= R`` between two half
    ellipses (the rims, semi-axes R and ``R |d_z|/|d|``, centred at
    ``+-H |d_xy|/|d|``), i.e. the least of the distances to the straight sides and
    to the two half-ellipse arcs (:func:`_dist_upper_half_ellipse`). Each
    candidate is ``h_Z`` of some direction or the distance to a boundary piece,
    never below the depth, and the set contains the minimiser: exact.
    """
    ax, ay, az, dx, dy, dz, R, H = (np.asarray(v, dtype=_FLOAT) for v in np.broadcast_arrays(ax, ay, az, dx, dy, dz, R, H))
    bx, by, bz = ax + dx, ay + dy, az + dz
    depth = np.minimum(H - np.minimum(az, bz), H + np.maximum(az, bz))
    for px, py in ((ax, ay), (bx, by)):
        rho = np.hypot(px, py)
        pos = rho > 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            nx = np.where(pos, px / np.where(pos, rho, 1.0), 1.0)
            ny = np.where(pos, py / np.where(pos, rho, 1.0), 0.0)
        depth = np.minimum(depth, R - np.minimum(nx * ax + ny * ay, nx * bx + ny * by))
    dxy = np.hypot(dx, dy)
    dn = np.sqrt(dxy * dxy + dz * dz)
    ok = np.flatnonzero((dn > 1e-150) & (dxy > 1e-12 * dn))  # a shorter segment is a point
    if ok.size:
        ax_, ay_, az_, dx_, dy_, dz_, R_, H_ = (v[ok] for v in (ax, ay, az, dx, dy, dz, R, H))
        dxy_, dn_ = dxy[ok], dn[ok]
        ux, uy = -dy_ / dxy_, dx_ / dxy_
        hx, hy, hz = dx_ / dn_, dy_ / dn_, dz_ / dn_
        vx, vy, vz = -hz * uy, hz * ux, hx * uy - hy * ux  # v = d^ x u, vz = |d_xy| / |d| > 0
        alpha = ux * ax_ + uy * ay_
        beta = vx * ax_ + vy * ay_ + vz * az_
        k = dxy_ / dn_
        bsemi = R_ * np.abs(dz_) / dn_
        c = R_ - np.abs(alpha)
        c = np.minimum(c, _dist_upper_half_ellipse(alpha, beta - k * H_, R_, bsemi))
        c = np.minimum(c, _dist_upper_half_ellipse(alpha, -(beta + k * H_), R_, bsemi))
        depth[ok] = np.minimum(depth[ok], c)
    return depth


def _point_box(px, py, pz, hx, hy, hz):
    """Signed distance (m) from points (box frame) to boxes ``|x_i| <= h_i``: negative inside, exact."""
    ex, ey, ez = np.abs(px) - hx, np.abs(py) - hy, np.abs(pz) - hz
    out = np.sqrt(np.maximum(ex, 0.0) ** 2 + np.maximum(ey, 0.0) ** 2 + np.maximum(ez, 0.0) ** 2)
    inside = np.maximum(np.maximum(ex, ey), ez)
    return np.where(inside < 0.0, inside, out)


def _point_cyl(px, py, pz, R, H):
    """Signed distance (m) from points (cylinder frame) to cylinders (radius R, half height H), exact."""
    er = np.hypot(px, py) - R
    ez = np.abs(pz) - H
    out = np.hypot(np.maximum(er, 0.0), np.maximum(ez, 0.0))
    inside = np.maximum(er, ez)
    return np.where(inside < 0.0, inside, out)


# ----------------------------------------------------------------------------------------------
# public functions on (T, 3) arrays
# ----------------------------------------------------------------------------------------------


def _xyz(p: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    p = np.asarray(p, dtype=_FLOAT)
    if p.shape[-1] != 3:
        raise ValueError(f"points must have 3 coordinates in the last axis, got shape {p.shape}")
    return p[..., 0], p[..., 1], p[..., 2]


def _pose_parts(pose: Any) -> tuple[np.ndarray, np.ndarray]:
    pose = np.asarray(pose, dtype=_FLOAT)
    if pose.shape[-2:] != (4, 4):
        raise ValueError(f"a pose is a 4x4 homogeneous transform (or (T, 4, 4)), got shape {pose.shape}")
    return pose[..., :3, :3], pose[..., :3, 3]


def _to_local(px, py, pz, R, c, translate=True):
    """Components of ``R^T (p - c)`` (or ``R^T p`` when ``translate`` is False); R, c broadcast per sample."""
    if translate:
        px, py, pz = px - c[..., 0], py - c[..., 1], pz - c[..., 2]
    return (
        R[..., 0, 0] * px + R[..., 1, 0] * py + R[..., 2, 0] * pz,
        R[..., 0, 1] * px + R[..., 1, 1] * py + R[..., 2, 1] * pz,
        R[..., 0, 2] * px + R[..., 1, 2] * py + R[..., 2, 2] * pz,
    )


def _local_segment(p0, p1, pose):
    """Segment start (relative to the shape centre) and direction in the shape frame, as >= 1-D arrays."""
    R, c = _pose_parts(pose)
    x0, y0, z0 = (np.atleast_1d(v) for v in _xyz(p0))
    x1, y1, z1 = (np.atleast_1d(v) for v in _xyz(p1))
    a = _to_local(x0, y0, z0, R, c)
    d = _to_local(x1 - x0, y1 - y0, z1 - z0, R, c, translate=False)
    shape = np.broadcast_shapes(*(v.shape for v in (*a, *d)))
    a = tuple(np.ascontiguousarray(np.broadcast_to(v, shape)) for v in a)
    d = tuple(np.ascontiguousarray(np.broadcast_to(v, shape)) for v in d)
    return a, d


def _result_shape(*points: Any, pose: Any = None) -> tuple[int, ...]:
    shapes = [np.shape(p)[:-1] for p in points]
    if pose is not None:
        shapes.append(np.shape(pose)[:-2])
    return np.broadcast_shapes(*shapes)


def _components(*points: Any) -> list[np.ndarray]:
    """x, y, z of each point array ``(..., 3)``, broadcast together, at least 1-D, float64."""
    arrs = [np.asarray(p, dtype=_FLOAT) for p in points]
    for p in arrs:
        if p.shape[-1:] != (3,):
            raise ValueError(f"points must have 3 coordinates in the last axis, got shape {p.shape}")
    shape = np.broadcast_shapes(*(p.shape[:-1] for p in arrs)) or (1,)
    return [np.ascontiguousarray(np.broadcast_to(p[..., i], shape)) for p in arrs for i in range(3)]


def segment_distance(a0: Any, a1: Any, b0: Any, b1: Any) -> np.ndarray:
    """Distance (m) between segments ``a0-a1`` and ``b0-b1``; arrays ``(..., 3)`` broadcast, result ``(...)``."""
    ax, ay, az, x1, y1, z1, bx, by, bz, x2, y2, z2 = _components(a0, a1, b0, b1)
    sq = _seg_seg_sq(ax, ay, az, x1 - ax, y1 - ay, z1 - az, bx, by, bz, x2 - bx, y2 - by, z2 - bz)
    return np.sqrt(sq).reshape(_result_shape(a0, a1, b0, b1))


def capsule_capsule(a0: Any, a1: Any, ra: Any, b0: Any, b1: Any, rb: Any) -> np.ndarray:
    """Signed distance (m) between capsules ``(a0-a1, ra)`` and ``(b0-b1, rb)``: segment distance minus radii.

    Endpoints ``(T, 3)`` (any broadcastable ``(..., 3)``), radii in m. Negative values
    are the exact penetration depth (segments that cross have depth 0, so the capsules'
    depth is ``ra + rb - segment distance`` everywhere).
    """
    return segment_distance(a0, a1, b0, b1) - ra - rb


def capsule_sphere(p0: Any, p1: Any, r: Any, center: Any, radius: Any) -> np.ndarray:
    """Signed distance (m) between capsules ``(p0-p1, r)`` and spheres (``center`` ``(3,)`` or ``(T, 3)``, ``radius``).

    ``|c - closest point of the segment| - r - radius``, exact everywhere.
    """
    x0, y0, z0, x1, y1, z1, cx, cy, cz = _components(p0, p1, center)
    sq = _point_seg_sq(cx, cy, cz, x0, y0, z0, x1 - x0, y1 - y0, z1 - z0)
    return (np.sqrt(sq) - r - radius).reshape(_result_shape(p0, p1, center))


def _signed(sq, depth_fn, p, d, c, extra, r):
    """``sqrt(sq) - r``, with ``-(depth + r)`` where ``sq == 0`` (the segment meets the shape).

    ``p``, ``d``: segment start and direction components; ``c``: shape centres;
    ``extra``: the shape's size parameters for ``depth_fn``; all broadcast to ``sq``.
    """
    out = np.sqrt(sq)
    idx = np.nonzero(sq == 0.0)
    if idx[0].size:
        shape = sq.shape

        def g(v):
            return np.broadcast_to(np.asarray(v, dtype=_FLOAT), shape)[idx]

        a = [g(pi) - g(ci) for pi, ci in zip(p, c)]
        out[idx] = -depth_fn(*a, *(g(v) for v in d), *(g(v) for v in extra))
    out -= r
    return out


def capsule_box(p0: Any, p1: Any, r: Any, size: Any, pose: Any) -> np.ndarray:
    """Signed distance (m) between capsules ``(p0-p1, r)`` ``(T, 3)`` and a box.

    ``size`` is the box's full extents ``[x, y, z]`` (m); ``pose`` its centre's 4x4
    transform, static ``(4, 4)`` or per sample ``(T, 4, 4)``. Exact separation by the
    piecewise-quadratic root of :func:`_seg_box_sq`; exact depth (closed form,
    :func:`_seg_box_depth`) where the segment meets the box.
    """
    a, d = _local_segment(p0, p1, pose)
    h = tuple(np.asarray(size, dtype=_FLOAT)[..., i] * 0.5 for i in range(3))
    zero = (0.0, 0.0, 0.0)
    sq = _seg_box_sq(*a, *d, *zero, *h)
    return _signed(sq, _seg_box_depth, a, d, zero, h, r).reshape(_result_shape(p0, p1, pose=pose))


def capsule_cylinder(p0: Any, p1: Any, r: Any, radius: Any, height: Any, pose: Any) -> np.ndarray:
    """Signed distance (m) between capsules ``(p0-p1, r)`` ``(T, 3)`` and a cylinder.

    ``radius`` and full ``height`` in m, axis along the pose's z; ``pose`` ``(4, 4)`` or
    ``(T, 4, 4)``. Separation by safeguarded Newton on the convex ``F(t)``
    (:func:`_seg_cyl_sq`), depth exact where the segment meets the cylinder
    (:func:`_seg_cyl_depth`).
    """
    a, d = _local_segment(p0, p1, pose)
    extra = (np.asarray(radius, dtype=_FLOAT), np.asarray(height, dtype=_FLOAT) * 0.5)
    zero = (0.0, 0.0, 0.0)
    sq = _seg_cyl_sq(*a, *d, *zero, *extra)
    return _signed(sq, _seg_cyl_depth, a, d, zero, extra, r).reshape(_result_shape(p0, p1, pose=pose))


def capsule_shape(p0: Any, p1: Any, r: Any, shape: Shape, pose: Any = None) -> np.ndarray:
    """Signed distance (m) between capsules ``(p0-p1, r)`` ``(T, 3)`` and a scene :class:`Shape`.

    ``pose`` overrides ``shape.pose`` (e.g. ``(T, 4, 4)`` for an object carried by the gripper).
    """
    pose = shape.pose if pose is None else pose
    if shape.kind == "box":
        return capsule_box(p0, p1, r, shape.size, pose)
    if shape.kind == "cylinder":
        return capsule_cylinder(p0, p1, r, shape.size[0], shape.size[1], pose)
    if shape.kind == "sphere":
        _, c = _pose_parts(pose)
        return capsule_sphere(p0, p1, r, c, shape.size[0])
    raise ValueError(f"shape {shape.name!r}: unknown kind {shape.kind!r}; use box, cylinder or sphere")


def point_shape(points: Any, shape: Shape, pose: Any = None) -> np.ndarray:
    """Signed distance (m) from points ``(..., 3)`` to a :class:`Shape` (negative inside), exact."""
    pose = shape.pose if pose is None else pose
    R, c = _pose_parts(pose)
    px, py, pz = _xyz(points)
    if shape.kind == "sphere":
        return np.sqrt((px - c[..., 0]) ** 2 + (py - c[..., 1]) ** 2 + (pz - c[..., 2]) ** 2) - shape.size[0]
    lx, ly, lz = _to_local(px, py, pz, R, c)
    if shape.kind == "box":
        return _point_box(lx, ly, lz, *(0.5 * np.asarray(shape.size, dtype=_FLOAT)))
    if shape.kind == "cylinder":
        return _point_cyl(lx, ly, lz, shape.size[0], 0.5 * shape.size[1])
    raise ValueError(f"shape {shape.name!r}: unknown kind {shape.kind!r}; use box, cylinder or sphere")


def sphere_shape(center: Any, radius: float, shape: Shape, pose: Any = None) -> np.ndarray:
    """Signed distance (m) between spheres (``center (..., 3)``, ``radius``) and a :class:`Shape`, exact.

    A ball of radius r against a convex set K: ``sd = sd(center, K) - r`` both apart and
    overlapping (the depth of a point inside a box or cylinder is the distance to its
    nearest face).
    """
    return point_shape(center, shape, pose) - radius


# ----------------------------------------------------------------------------------------------
# shape-shape (carried object against the scene)
# ----------------------------------------------------------------------------------------------


def _coal_geometry(kind: str, size: Sequence[float]):
    import coal

    if kind == "box":
        return coal.Box(float(size[0]), float(size[1]), float(size[2]))  # full extents
    if kind == "cylinder":
        return coal.Cylinder(float(size[0]), float(size[1]))  # radius, full length
    if kind == "sphere":
        return coal.Sphere(float(size[0]))
    if kind == "capsule":
        return coal.Capsule(float(size[0]), float(size[1]))  # radius, full segment length
    raise ValueError(f"unknown shape kind {kind!r}; use box, cylinder, sphere or capsule")


def _bounding_radius(kind: str, size: Sequence[float]) -> float:
    if kind == "box":
        return 0.5 * float(np.linalg.norm(size))
    if kind == "cylinder":
        return float(np.hypot(size[0], 0.5 * size[1]))
    return float(size[0])


def shape_shape(a: Shape, b: Shape, pose_a: Any = None, pose_b: Any = None, far_m: float | None = None) -> np.ndarray:
    """Signed distance (m) between two scene shapes whose poses may vary per sample (``(T, 4, 4)``).

    Exact in closed form when either is a sphere (point-shape distance minus the
    radius). Box/cylinder against box/cylinder: once per run of samples in which
    neither pose changes, the closed-form bounds of :func:`_convex_bounds` where they
    meet (to 1e-12 m), else ``coal.distance`` (GJK with a 1e-10 tolerance when apart:
    exact to ~1e-10 m, ~1e-8 m near contact; EPA when overlapping: boxes exact to
    rounding, cylinders to about 1e-5 m), about 3 us per call (:func:`_shape_runs`).
    With ``far_m`` set (m, a scalar or one cutoff per sample), a run whose lower
    bound (a bounding ball's gap, or the projection gap of :func:`_convex_bounds`)
    is above every cutoff of its samples gets that bound instead: a *lower bound*
    (> ``far_m``), not the distance. Result shape ``(T,)`` (``(1,)`` for two static
    poses).
    """
    pose_a = np.asarray(a.pose if pose_a is None else pose_a, dtype=_FLOAT)
    pose_b = np.asarray(b.pose if pose_b is None else pose_b, dtype=_FLOAT)
    if a.kind == "sphere" or b.kind == "sphere":
        if a.kind != "sphere":
            a, b, pose_a, pose_b = b, a, pose_b, pose_a
        _, c = _pose_parts(pose_a)
        return np.atleast_1d(sphere_shape(c, a.size[0], b, pose_b))
    Pa = pose_a.reshape(-1, 4, 4)
    Pb = pose_b.reshape(-1, 4, 4)
    T = max(len(Pa), len(Pb))
    return _shape_runs([(a, b, Pa, Pb, _pose_changes(Pa, T) | _pose_changes(Pb, T))], far_m)[0]


#: Two bounds of a box/cylinder pair's signed distance closer than this (m) give its value without coal: far
#: below coal's own GJK tolerance (1e-10 m; near contact its error reaches ~1e-8 m) and its EPA error on
#: cylinders (~1e-5 m), far above the rounding of the closed forms (~1e-16 m per metre).
_CERTIFIED_M = 1e-12

#: Alternating-projection rounds (:func:`_refine_bounds`) for the samples the first bounds leave open, before
#: they go to coal: on the bundled programs they settle about two thirds of them.
_REFINE_ROUNDS = 1


@dataclass(frozen=True)
class _Convex:
    """N boxes or N cylinders (one per pair and sample), as component arrays ``(N,)``: ``half`` the half extents
    (box) or ``(radius, half height)`` (cylinder), m; ``c[i]`` the centre's coordinate i and ``R[i][j]`` the
    rotation's entry (i, j) (column j: the shape's axis j in the base frame)."""

    kind: str
    half: tuple[float, ...]
    c: tuple
    R: tuple

    @staticmethod
    def of(kind: str, half: np.ndarray, P: np.ndarray) -> "_Convex":
        """Shapes of one ``kind`` with sizes ``half (N, 3 or 2)`` at the poses ``P (N, 4, 4)``."""
        Q = np.ascontiguousarray(P[:, :3, :].transpose(1, 2, 0))  # (3, 4, N): one contiguous row per entry
        H = np.ascontiguousarray(half.T)
        return _Convex(kind, tuple(H), tuple(Q[i, 3] for i in range(3)), tuple(tuple(Q[i, j] for j in range(3)) for i in range(3)))

    def take(self, rows: np.ndarray) -> "_Convex":
        """The entries ``rows``."""
        half = tuple(h[rows] for h in self.half)
        return _Convex(self.kind, half, tuple(v[rows] for v in self.c), tuple(tuple(v[rows] for v in r) for r in self.R))

    def into(self, v):
        """Components of ``R^T v`` (along the shape's axes) of a vector ``v = (x, y, z)``."""
        R = self.R
        return tuple(v[0] * R[0][j] + v[1] * R[1][j] + v[2] * R[2][j] for j in range(3))

    def out_of(self, v):
        """Components of ``R v`` (base frame) of a vector ``v`` given along the shape's axes."""
        R = self.R
        return tuple(R[i][0] * v[0] + R[i][1] * v[1] + R[i][2] * v[2] for i in range(3))

    def local(self, p):
        """Coordinates of the points ``p`` in the shape's frame (centre at the origin)."""
        return self.into(tuple(p[i] - self.c[i] for i in range(3)))

    def world(self, q):
        """Base-frame points of the shape-frame points ``q``."""
        return tuple(v + c for v, c in zip(self.out_of(q), self.c))

    def support(self, n) -> np.ndarray:
        """Support function ``h(n) = max_x n . (x - c)`` (m) for unit vectors ``n``: a box's
        ``sum_i h_i |n . e_i|``, a cylinder's ``R sqrt(1 - (n . u)^2) + H |n . u|`` (axis u)."""
        loc = self.into(n)
        if self.kind == "box":
            return np.abs(loc[0]) * self.half[0] + np.abs(loc[1]) * self.half[1] + np.abs(loc[2]) * self.half[2]
        nu = np.abs(loc[2])
        return self.half[0] * np.sqrt(np.maximum(1.0 - nu * nu, 0.0)) + self.half[1] * nu

    def support_point(self, n):
        """A point of the shape that maximises ``n . x``: where a face or an edge does, its middle
        (``sign(0) = 0``), which is where the other shape's nearest point usually projects."""
        x, y, z = self.into(n)
        if self.kind == "box":
            return self.world((np.sign(x) * self.half[0], np.sign(y) * self.half[1], np.sign(z) * self.half[2]))
        rho = np.hypot(x, y)
        radial = rho > 1e-9  # n along the axis: the cap's centre
        s = np.where(radial, self.half[0] / np.where(radial, rho, 1.0), 0.0)
        return self.world((x * s, y * s, np.sign(z) * self.half[1]))

    def signed(self, p) -> np.ndarray:
        """Signed distance (m) of the points ``p`` to the shape (negative inside), exact (:func:`_point_box`)."""
        x, y, z = self.local(p)
        return _point_box(x, y, z, *self.half) if self.kind == "box" else _point_cyl(x, y, z, *self.half)

    def nearest(self, p):
        """The points of the (solid) shape nearest to ``p`` (``p`` itself inside), closed form."""
        x, y, z = self.local(p)
        if self.kind == "box":
            return self.world(tuple(np.clip(v, -h, h) for v, h in zip((x, y, z), self.half)))
        s = np.minimum(1.0, self.half[0] / np.maximum(np.hypot(x, y), 1e-300))
        return self.world((x * s, y * s, np.clip(z, -self.half[1], self.half[1])))

    def axes(self) -> list:
        """The face normals: a box's three axes, a cylinder's axis (its caps)."""
        R = self.R
        return [tuple(R[i][j] for i in range(3)) for j in ((0, 1, 2) if self.kind == "box" else (2,))]

    def radius(self) -> np.ndarray:
        """Radius (m) of the ball about the centre that holds the shape."""
        return np.sqrt(sum(h * h for h in self.half))


def _unit(v):
    """``v / |v|`` for a vector ``v = (x, y, z)`` of arrays, and where ``|v| > 1e-9`` (0 elsewhere)."""
    norm = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    ok = norm > 1e-9
    inv = np.where(ok, 1.0 / np.where(ok, norm, 1.0), 0.0)
    return tuple(x * inv for x in v), ok


def _gap(A: _Convex, B: _Convex, n, ok) -> np.ndarray:
    """``gap(n) = n . (c_B - c_A) - h_A(n) - h_B(n)`` (m) for unit ``n`` (``-inf`` where not ``ok``), each ``n``
    taken facing from A to B (``gap(n) - gap(-n) = 2 n . (c_B - c_A)``: the other sign is never better)."""
    s = np.abs(sum(ni * (cb - ca) for ni, ca, cb in zip(n, A.c, B.c)))
    g = s - A.support(n) - B.support(n)  # h(-n) = h(n): both shapes are centrally symmetric
    return np.where(ok, g, -np.inf)


def _convex_bounds(A: _Convex, B: _Convex) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds (m) of the signed distance between the convex shapes ``A`` and ``B`` at each of
    their N poses, closed form; equal up to rounding in most real placements.

    **Lower bound.** With ``M = B - A`` (Minkowski difference) and ``d = c_B - c_A``, the signed distance is
    ``sd(A, B) = max over unit n of gap(n)``, ``gap(n) = min_{y in B} n.y - max_{x in A} n.x
    = n.d - h_A(n) - h_B(n)``: apart, ``dist(0, M) = max_n min_{m in M} n.m`` (a point's distance to a convex
    set); overlapping, ``-depth = -min_n h_M(n)`` is the same maximum. So **every** unit ``n`` gives
    ``gap(n) <= sd``, and the best of a few candidates is a lower bound: each shape's face normals (box axes,
    cylinder axis), the centre direction ``d`` and each cylinder's radial direction toward the other centre.
    (The nine edge cross products of two boxes, which would make the bound their exact depth whenever they
    overlap, settled no more samples on the bundled programs than they cost.)

    **Upper bound.** For any ``x`` in A, ``sd(A, B) <= sd(x, B)``: apart, ``dist(A, B) <= dist(x, B)``; A
    overlapping B but x outside, ``sd <= 0 < sd(x, B)``; x inside B, any translation that separates A moves x
    out of B, so ``depth(A, B) >= depth(x, B)``. The same for ``y`` in B against A. We take the support points
    of the best direction ``n*`` (A's farthest point along ``n*``, B's along ``-n*``): when the contact is a
    face of one shape against a point, edge or face of the other that projects onto that face,
    ``sd(x, B) = gap(n*)`` and the bounds meet.
    """
    d = tuple(cb - ca for ca, cb in zip(A.c, B.c))
    cands = A.axes() + B.axes() + [d]
    for S in (A, B):
        if S.kind == "cylinder":  # toward the other centre, across the axis: side against side
            u = S.axes()[0]
            du = sum(di * ui for di, ui in zip(d, u))
            cands.append(tuple(di - du * ui for di, ui in zip(d, u)))
    N = np.broadcast(*d).shape
    n = tuple(np.stack([np.broadcast_to(v[i], N) for v in cands]) for i in range(3))  # (m, N) per component
    n, ok = _unit(n)
    g = _gap(A, B, n, ok)
    best = g.argmax(axis=0)
    cols = np.arange(g.shape[1])
    lb = g[best, cols]
    nb = tuple(v[best, cols] for v in n)
    s = np.sign(sum(ni * di for ni, di in zip(nb, d)))  # face from A to B, as _gap took it
    s = np.where(s == 0.0, 1.0, s)
    nb = tuple(v * s for v in nb)
    ub = np.minimum(B.signed(A.support_point(nb)), A.signed(B.support_point(tuple(-v for v in nb))))
    return lb, ub


def _refine_bounds(A: _Convex, B: _Convex, lb: np.ndarray, ub: np.ndarray, rounds: int) -> tuple[np.ndarray, np.ndarray]:
    """Tighter bounds (m) by alternating projections: ``y`` = the point of B nearest ``x``, then ``x`` = the
    point of A nearest ``y`` (closed form), from ``x`` = A's point nearest B's centre. Each pair gives the
    upper bound ``|x - y|`` (``sd <= dist(A, B) <= |x - y|`` for x in A, y in B) and, along ``y - x``, a lower
    bound :func:`_gap`. For disjoint convex sets the pairs converge to a closest pair (Cheney and Goldstein
    1959), so the bounds close in; a few rounds settle a rim or an edge against an edge, where the candidate
    directions of :func:`_convex_bounds` miss the optimum. Returns updated copies of ``lb``, ``ub``."""
    lb, ub = lb.copy(), ub.copy()

    def tighten(x, y):
        v = tuple(yi - xi for xi, yi in zip(x, y))
        np.minimum(ub, np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]), out=ub)
        np.maximum(lb, _gap(A, B, *_unit(v)), out=lb)

    x = A.nearest(tuple(np.broadcast_to(c, lb.shape) for c in B.c))
    for _ in range(rounds):
        y = B.nearest(x)
        tighten(x, y)
        x = A.nearest(y)
        tighten(x, y)
    return lb, ub


def _pose_changes(poses: np.ndarray, T: int) -> np.ndarray:
    """``(T,)`` bool: sample 0 and every sample whose pose differs from the one before (``poses (1 or T, 4, 4)``)."""
    changed = np.zeros(T, dtype=bool)
    changed[:1] = True  # (no sample at all: nothing changes)
    if len(poses) > 1:
        changed[1:] = (poses[1:] != poses[:-1]).any(axis=(1, 2))
    return changed


def _half_sizes(s: Shape) -> tuple[float, ...]:
    """A box's half extents or a cylinder's ``(radius, half height)``, m."""
    return (0.5 * s.size[0], 0.5 * s.size[1], 0.5 * s.size[2]) if s.kind == "box" else (float(s.size[0]), 0.5 * s.size[1])


def _shape_runs(items: Sequence[tuple[Shape, Shape, np.ndarray, np.ndarray, np.ndarray]], far_m) -> list[np.ndarray]:
    """Signed distances ``(T,)`` (m) of box/cylinder pairs ``items = [(a, b, Pa, Pb, changed)]``: poses
    ``(1 or T, 4, 4)``, evaluated at the samples where ``changed (T,)`` (a run of equal poses starts) and
    copied along the run. ``far_m``: None (every value exact), a cutoff (m) or one per sample ``(T,)``.

    All the pairs' run starts are evaluated together, per kind pair (a box against a cylinder is taken
    as the cylinder against the box: the distance is symmetric):

    1. with ``far_m``, the gap of one shape's bounding ball against the other (its centre's signed distance
       to it less its radius, both ways) is kept as the lower bound where it beats every cutoff of the run
       (a run's value stands for all its samples);
    2. for the rest, closed-form bounds ``lb <= sd <= ub`` (:func:`_convex_bounds`, then
       :func:`_refine_bounds` where they stay open): where ``ub - lb <= 1e-12 m`` (:data:`_CERTIFIED_M`) the
       value is ``ub``, exact without coal; where ``lb`` beats the run's cutoffs it is kept as the bound;
    3. only the rest goes to ``coal.distance`` (:func:`_coal_values`), pair by pair.
    """
    # pairs of one carried object share its pose changes (the same `changed` array): gather once per array
    runs: dict[int, tuple[np.ndarray, np.ndarray, Any]] = {}  # id(changed) -> run starts, run of each sample, cutoffs
    gathered: dict[tuple[int, int], np.ndarray] = {}  # (id(poses), id(changed)) -> the poses at the run starts
    firsts, vals, kinds, seen, twins = [], [], {}, {}, []
    for k, (a, b, Pa, Pb, changed) in enumerate(items):
        if id(changed) not in runs:
            first = np.flatnonzero(changed)
            limit = np.inf if far_m is None else (np.maximum.reduceat(far_m, first) if np.ndim(far_m) else far_m)
            runs[id(changed)] = first, np.cumsum(changed) - 1, limit
        first = runs[id(changed)][0]
        firsts.append(first)
        vals.append(np.empty(len(first)))
        j = seen.get((b.name, a.name))
        if j is not None and np.array_equal(items[j][4], changed):  # the pair the other way round: same bounds
            twins.append((k, j))
            continue
        seen[a.name, b.name] = k
        kinds.setdefault(tuple(sorted((a.kind, b.kind))), []).append(k)
    for (kind_a, kind_b), ks in kinds.items():
        counts = [len(firsts[k]) for k in ks]
        offsets = np.cumsum([0] + counts)
        poses, halves = ([], []), ([], [])
        limit = np.empty(offsets[-1])
        for k, lo, hi in zip(ks, offsets[:-1], offsets[1:]):
            a, b, Pa, Pb, changed = items[k]
            sides = ((a, Pa), (b, Pb)) if a.kind == kind_a else ((b, Pb), (a, Pa))
            for side, (shape, P) in enumerate(sides):
                if len(P) == 1:
                    poses[side].append(np.broadcast_to(P, (hi - lo, 4, 4)))
                else:
                    key = (id(P), id(changed))
                    if key not in gathered:
                        gathered[key] = P[firsts[k]]
                    poses[side].append(gathered[key])
                half = _half_sizes(shape)
                halves[side].append(np.broadcast_to(half, (hi - lo, len(half))))
            limit[lo:hi] = runs[id(changed)][2]
        A = _Convex.of(kind_a, np.concatenate(halves[0]), np.concatenate(poses[0]))
        B = _Convex.of(kind_b, np.concatenate(halves[1]), np.concatenate(poses[1]))
        out = np.empty(offsets[-1])
        todo = np.arange(offsets[-1])
        if far_m is not None:
            gap = np.maximum(B.signed(A.c) - A.radius(), A.signed(B.c) - B.radius())
            far = gap > limit
            out[far] = gap[far]
            todo = np.flatnonzero(~far)
            A, B = A.take(todo), B.take(todo)
        if len(todo):
            lb, ub = _convex_bounds(A, B)
            lim = limit[todo]
            open_ = np.flatnonzero((ub - lb > _CERTIFIED_M) & (lb <= lim))
            if len(open_) and _REFINE_ROUNDS:
                lb[open_], ub[open_] = _refine_bounds(A.take(open_), B.take(open_), lb[open_], ub[open_], _REFINE_ROUNDS)
                open_ = open_[(ub[open_] - lb[open_] > _CERTIFIED_M) & (lb[open_] <= lim[open_])]
            out[todo] = np.where(ub - lb > _CERTIFIED_M, lb, ub)  # exact where certified, else a bound above the cutoffs
            out[todo[open_]] = np.nan  # for coal
            if "cylinder" in (kind_a, kind_b):
                # overlapping cylinders keep coal's EPA depth (good to ~1e-5 m), the value they always had: the
                # certified depth is exact, but would move the reports' penetration values by ~1e-7 m
                out[todo[(ub <= 0.0) & (ub - lb <= _CERTIFIED_M)]] = np.nan
        for k, lo, hi in zip(ks, offsets[:-1], offsets[1:]):
            vals[k][:] = out[lo:hi]
    twin_of = dict(twins)  # each twin comes after the pair it copies
    asked: list[np.ndarray] = []  # per pair: where coal gave the value
    for k, v in enumerate(vals):
        j = twin_of.get(k)
        if j is not None:
            v[:] = vals[j]
            # coal's GJK distances are symmetric (to its tolerance), its EPA depths not exactly: where the twin's
            # coal value is an overlap, this order asks coal itself, as it always did
            v[asked[j] & (v <= 0.0)] = np.nan
        need = np.isnan(v)
        asked.append(need)
        if need.any():
            a, b, Pa, Pb, _ = items[k]
            need = np.flatnonzero(need)
            v[need] = _coal_values(a, b, Pa, Pb, firsts[k][need])
    return [v[runs[id(item[4])][1]] for v, item in zip(vals, items)]


def _coal_values(a: Shape, b: Shape, Pa: np.ndarray, Pb: np.ndarray, at: np.ndarray) -> np.ndarray:
    """``coal.distance`` (GJK to 1e-10 m when apart, EPA when overlapping) of boxes/cylinders ``a``, ``b`` at the
    samples ``at`` of their poses ``(1 or T, 4, 4)``."""
    import coal

    ga, gb = _coal_geometry(a.kind, a.size), _coal_geometry(b.kind, b.size)
    solver = coal.ComputeDistance(ga, gb)  # keeps no reference: ga and gb must outlive it
    req = coal.DistanceRequest()
    req.gjk_tolerance = 1e-10
    req.gjk_max_iterations = 1000
    req.epa_max_iterations = 256
    res = coal.DistanceResult()
    ta, tb = coal.Transform3s(), coal.Transform3s()
    moving = []
    for tr, P in ((ta, Pa), (tb, Pb)):
        if len(P) == 1:
            tr.setRotation(np.ascontiguousarray(P[0, :3, :3]))
            tr.setTranslation(np.ascontiguousarray(P[0, :3, 3]))
        else:
            moving.append((tr.setRotation, tr.setTranslation, np.ascontiguousarray(P[at, :3, :3]), np.ascontiguousarray(P[at, :3, 3])))
    clear = res.clear
    if len(moving) == 1:
        ((set_r, set_t, R, t),) = moving
        # a carried object keeps its orientation along a straight line: set a rotation only when it changes
        turned = np.ones(len(R), dtype=bool)
        turned[1:] = (R[1:] != R[:-1]).any(axis=(1, 2))
        out = []
        put = out.append
        for Ri, ti, new_r in zip(R, t, turned.tolist()):
            if new_r:
                set_r(Ri)
            set_t(ti)
            clear()  # the result keeps the least distance of every call until cleared
            put(solver(ta, tb, req, res))
    else:
        # both static (one sample) or both moving
        out = []
        for i in range(len(at)):
            for set_r, set_t, R, t in moving:
                set_r(R[i])
                set_t(t[i])
            clear()
            out.append(solver(ta, tb, req, res))
    del solver
    return np.array(out, dtype=_FLOAT)


# ----------------------------------------------------------------------------------------------
# batch API
# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CapsuleSpec:
    """A robot capsule: its name and radius (m). Endpoints come per call."""

    name: str
    radius: float


@dataclass
class _Group:
    """Pairs evaluated together.

    ``product`` groups (capsules against box / cylinder / sphere shapes): capsules
    ``caps`` (Cg) against shapes that share one rotation ``rot`` (None = identity),
    evaluated shape by shape over all the group's capsules; ``rows[s]`` are the
    output rows of shape s for each capsule (-1: pair not requested) and ``views[s]``
    the same as a slice when they form one (results are then written in place). A
    product group of a ``moving`` shape has one shape whose pose comes per sample
    (``pose_key``). ``capsule`` groups are self pairs (``ia``, ``ib``), ``shape``
    groups shape-shape pairs (shape indices ``ia``, ``ib``); ``cols`` are the output
    rows of the pairs.
    """

    kind: str
    cols: np.ndarray
    product: bool = False
    caps: np.ndarray | None = None
    rows: list[np.ndarray] = field(default_factory=list)
    views: list[slice | None] = field(default_factory=list)
    rot: np.ndarray | None = None
    centre: tuple[list[float], ...] = ()
    size: tuple[list[float], ...] = ()
    r: np.ndarray | None = None
    ia: np.ndarray | None = None
    ib: np.ndarray | None = None
    pose_key: str | None = None


def reduce_min(distances: np.ndarray, groups: Sequence[Sequence[int]] | Mapping[Any, Sequence[int]]) -> np.ndarray:
    """Minimum (m) over column groups of ``distances (T, K)``: ``(T, G)``.

    One entity is often several shapes (a container's floor and four walls); its
    distance to a capsule is the least over its shapes. ``groups`` lists the
    column indices of each group (a mapping: its values, in order).
    """
    distances = np.asarray(distances)
    if isinstance(groups, Mapping):
        groups = list(groups.values())
    out = np.empty((distances.shape[0], len(groups)), dtype=distances.dtype)
    for g, cols in enumerate(groups):
        cols = list(cols)
        if not cols:
            raise ValueError(f"group {g} is empty")
        if len(cols) == 1:
            out[:, g] = distances[:, cols[0]]
        else:
            np.min(distances[:, cols], axis=1, out=out[:, g])
    return out


_DEPTH = {"box": _seg_box_depth, "cylinder": _seg_cyl_depth}

#: How many times longer the chunks of samples are when only the near blocks of a pair are evaluated
#: (:meth:`ProximityKernel._chunks`): 8 covers the bundled programs' trajectories (up to ~13,000 samples with the
#: UR3e's 10 capsules) in one chunk.
_FAR_CHUNKS = 8

#: Samples per block of the far-pair bounds (:meth:`ProximityKernel._bounds`): a capsule far from a shape over a
#: block is not evaluated there; shorter blocks bound tighter, longer ones cost less.
_BLOCK = 32


def _capsule_balls(P0: np.ndarray, D: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per capsule and block of :data:`_BLOCK` samples, balls ``(centre (3, C, nb), radius (C, nb))`` m holding
    the segment midpoints (the radius grown by the farthest one's half length: the ball holds the segments),
    the start points and the end points of segments ``P0 + t D`` ``(3, C, T)``. Centre: the block's middle sample.
    """
    nb = -(-P0.shape[2] // _BLOCK)
    start, d = _blocks(P0, nb), _blocks(D, nb)  # (3, C, nb, B), padded once
    half = np.sqrt(np.einsum("icnb,icnb->cnb", d, d))
    half *= 0.5
    out = []
    for pb, h in ((start + 0.5 * d, half), (start, None), (start + d, None)):
        c = np.ascontiguousarray(pb[..., _BLOCK // 2])  # padding repeats real samples: any index will do
        diff = pb - c[..., None]
        dist = np.sqrt(np.einsum("icnb,icnb->cnb", diff, diff))
        if h is not None:
            dist += h
        out.append((c, dist.max(axis=2)))
    return out


def _blocks(x: np.ndarray, nb: int) -> np.ndarray:
    """``x (..., n)`` as ``(..., nb, _BLOCK)``, the last block padded with copies of the last sample."""
    n = x.shape[-1]
    if nb * _BLOCK != n:
        x = np.concatenate([x, np.repeat(x[..., -1:], nb * _BLOCK - n, axis=-1)], axis=-1)
    return x.reshape(*x.shape[:-1], nb, _BLOCK)


def _as_slice(rows: np.ndarray) -> slice | None:
    """``rows`` as an equivalent slice (for in-place output), or None."""
    if len(rows) == 0 or (rows < 0).any():
        return None
    step = int(rows[1] - rows[0]) if len(rows) > 1 else 1
    if step > 0 and np.array_equal(rows, rows[0] + step * np.arange(len(rows))):
        return slice(int(rows[0]), int(rows[-1]) + 1, step)
    return None


def _subgroup(g: _Group, keep: np.ndarray) -> _Group:
    """The product group ``g`` restricted to the capsules ``keep`` (a mask over ``g.caps``)."""
    rows = [rr[keep] for rr in g.rows]
    return replace(g, caps=g.caps[keep], rows=rows, views=[_as_slice(rr) for rr in rows], r=g.r[keep])


class ProximityKernel:
    """Signed distances (m) of many capsule and shape pairs over a whole trajectory, exact and vectorised.

    Built once from the capsules (``CapsuleSpec`` or ``(name, radius)``), the scene
    shapes and ``pairs`` of names ``(a, b)``:

    * ``(capsule, shape)``: a robot capsule against a scene shape;
    * ``(capsule, capsule)``: a self pair;
    * ``(shape, shape)``: two scene shapes (an object the gripper carries against
      the others): :func:`shape_shape`.

    ``moving`` names the shapes (by shape name or by owner, i.e. entity id) whose
    pose is given per sample at each :meth:`distances` call (objects the program
    moves); the others keep ``Shape.pose``. Names must be unique across capsules and
    shapes. Column k of the result is ``pairs[k]``; ``owners[k]`` is the entity of
    its b side (``Shape.owner``, or the capsule name) and :meth:`groups` gives the
    columns per ``(a, owner)`` for :func:`reduce_min` (a container's floor and
    walls are one entity).

    How it is fast: capsule/static-shape pairs are grouped by shape kind and
    rotation (a container's five boxes share one; upright objects and the table
    share the identity). Per group and chunk of samples, the capsules' segments are
    rotated into the shared frame and their per-segment terms (``1/d``, ``|d|^2``)
    computed once; then each shape is evaluated against all the group's capsules
    with its parameters as scalars on contiguous ``(Cg, n)`` arrays (``n`` about
    ``chunk / Cg`` samples, which keeps the temporaries in cache), writing straight
    into the output. A moving shape is one such group whose frame changes per
    sample. Penetrating samples (the segment meets the shape) and cylinder pairs
    whose closest point needs Newton steps are collected and solved in one batch
    each at the end.
    """

    def __init__(
        self,
        capsules: Sequence[CapsuleSpec | tuple[str, float]],
        shapes: Sequence[Shape],
        pairs: Sequence[tuple[str, str]],
        moving: Collection[str] = (),
        chunk: int = 16384,
    ):
        self.capsules = tuple(c if isinstance(c, CapsuleSpec) else CapsuleSpec(str(c[0]), float(c[1])) for c in capsules)
        self.shapes = tuple(shapes)
        self.chunk = int(chunk)
        cap_index = {c.name: i for i, c in enumerate(self.capsules)}
        shape_index = {s.name: i for i, s in enumerate(self.shapes)}
        if len(cap_index) != len(self.capsules):
            raise ValueError("capsule names must be unique")
        if len(shape_index) != len(self.shapes):
            raise ValueError("shape names must be unique")
        clash = set(cap_index) & set(shape_index)
        if clash:
            raise ValueError(f"names used by both a capsule and a shape: {sorted(clash)}")
        for s in self.shapes:
            if s.kind not in ("box", "cylinder", "sphere"):
                raise ValueError(f"shape {s.name!r}: unknown kind {s.kind!r}; use box, cylinder or sphere")
        moving = set(moving)
        unknown = moving - set(shape_index) - {s.owner for s in self.shapes}
        if unknown:
            raise ValueError(f"moving: no shape or owner named {sorted(unknown)}")
        for name in moving - set(shape_index):
            parts = [s.name for s in self.shapes if s.owner == name]
            if len(parts) > 1:
                raise ValueError(f"moving: {name!r} is {len(parts)} shapes ({', '.join(parts)}); name the shapes, each with its own pose")
        # the key of the per-sample pose of each moving shape: its name if listed, else its owner
        self._pose_key = {
            s.name: (s.name if s.name in moving else s.owner) for s in self.shapes if s.name in moving or s.owner in moving
        }
        self.moving = frozenset(self._pose_key.values())
        self.radii = np.array([c.radius for c in self.capsules], dtype=_FLOAT)
        self.pairs = tuple((str(a), str(b)) for a, b in pairs)
        owners: list[str] = []
        static: dict[tuple[str, bytes], list[tuple[int, int, int]]] = {}
        movers: dict[int, list[tuple[int, int, int]]] = {}
        selfs: list[tuple[int, int, int]] = []
        shape_pairs: list[tuple[int, int, int]] = []
        rot_keys: dict[int, bytes] = {}  # shape index -> its rotation as a group key (b"": the identity)
        for k, (a, b) in enumerate(self.pairs):
            if a in shape_index and b in shape_index:
                shape_pairs.append((k, shape_index[a], shape_index[b]))
                owners.append(self.shapes[shape_index[b]].owner)
                continue
            if a not in cap_index:
                raise ValueError(f"pair {k} {(a, b)}: {a!r} is not a capsule (have {', '.join(cap_index)})")
            ia = cap_index[a]
            if b in cap_index:
                selfs.append((k, ia, cap_index[b]))
                owners.append(b)
            elif b in shape_index:
                j = shape_index[b]
                s = self.shapes[j]
                owners.append(s.owner)
                if s.name in self._pose_key:
                    movers.setdefault(j, []).append((k, ia, j))
                    continue
                if j not in rot_keys:  # once per shape, not per (capsule, shape) pair
                    rot = np.asarray(s.pose, dtype=_FLOAT)[:3, :3]
                    rot_keys[j] = b"" if s.kind == "sphere" or np.array_equal(rot, _EYE3) else rot.tobytes()
                static.setdefault((s.kind, rot_keys[j]), []).append((k, ia, j))
            else:
                raise ValueError(f"pair {k} {(a, b)}: {b!r} is neither a capsule nor a scene shape")
        self.owners = tuple(owners)
        self._groups: list[_Group] = []
        for (kind, _), rows in static.items():
            caps = {r[1] for r in rows}
            shp = sorted({r[2] for r in rows})
            if len(rows) * 2 >= len(caps) * len(shp):
                self._groups.append(self._product_group(kind, rows))
            else:
                for j in shp:
                    self._groups.append(self._product_group(kind, [r for r in rows if r[2] == j]))
        for j, rows in movers.items():
            g = self._product_group(self.shapes[j].kind, rows)
            g.rot, g.centre, g.pose_key = None, ([0.0], [0.0], [0.0]), self._pose_key[self.shapes[j].name]
            self._groups.append(g)
        if selfs:
            ia = np.array([x[1] for x in selfs])
            ib = np.array([x[2] for x in selfs])
            self._groups.append(_Group("capsule", np.array([x[0] for x in selfs]), ia=ia, ib=ib, r=(self.radii[ia] + self.radii[ib])[:, None]))
        if shape_pairs:
            self._groups.append(
                _Group("shape", np.array([x[0] for x in shape_pairs]), ia=np.array([x[1] for x in shape_pairs]), ib=np.array([x[2] for x in shape_pairs]))
            )

    def _product_group(self, kind: str, rows: list[tuple[int, int, int]]) -> _Group:
        caps = sorted({r[1] for r in rows})
        shp = sorted({r[2] for r in rows})
        ci = {c: i for i, c in enumerate(caps)}
        out_rows = [np.full(len(caps), -1) for _ in shp]
        for k, c, j in rows:
            out_rows[shp.index(j)][ci[c]] = k
        views = [_as_slice(rr) for rr in out_rows]
        shapes = [self.shapes[j] for j in shp]
        rot = np.asarray(shapes[0].pose, dtype=_FLOAT)[:3, :3]
        rot = None if kind == "sphere" or np.array_equal(rot, _EYE3) else rot.copy()
        centres = np.array([np.asarray(s.pose, dtype=_FLOAT)[:3, 3] for s in shapes])  # (Sg, 3)
        if rot is not None:
            centres = centres @ rot  # R^T c, row by row
        if kind == "box":
            size = tuple([0.5 * float(s.size[i]) for s in shapes] for i in range(3))
        elif kind == "cylinder":
            size = ([float(s.size[0]) for s in shapes], [0.5 * float(s.size[1]) for s in shapes])
        else:
            size = ([float(s.size[0]) for s in shapes],)
        return _Group(
            kind,
            np.array([r[0] for r in rows]),
            product=True,
            caps=np.array(caps),
            rows=out_rows,
            views=views,
            rot=rot,
            centre=tuple(centres[:, i].tolist() for i in range(3)),
            size=size,
            r=self.radii[caps][:, None].copy(),
        )

    @property
    def names(self) -> list[str]:
        """Column labels ``"a|b"``."""
        return [f"{a}|{b}" for a, b in self.pairs]

    def groups(self) -> dict[tuple[str, str], list[int]]:
        """Columns per ``(a, owner of b)``: the shapes of one entity together, for :func:`reduce_min`."""
        out: dict[tuple[str, str], list[int]] = {}
        for k, ((a, _), owner) in enumerate(zip(self.pairs, self.owners)):
            out.setdefault((a, owner), []).append(k)
        return out

    def distances(
        self,
        p0: Any,
        p1: Any,
        poses: Mapping[str, Any] | None = None,
        far_m: float | None = None,
        exact_min_of: Sequence[int] | None = None,
    ) -> np.ndarray:
        """Signed distances ``(T, K)`` in m for capsule endpoints ``p0``, ``p1`` ``(T, C, 3)`` (base frame).

        ``poses`` gives the per-sample pose ``(T, 4, 4)`` of every ``moving`` name. The
        result is column-major (Fortran-ordered): each pair's column is contiguous.

        ``far_m=None`` (the default): every value is exact. With ``far_m >= 0`` set (m),
        the cutoff at sample t is ``c_t = far_m``, raised to ``max(far_m, u_t)`` when
        ``exact_min_of`` lists columns: ``u_t`` is an upper bound of their least distance
        at t. Every value at or below ``c_t`` is exact; a value above it may instead be a
        *lower bound* that is itself above ``c_t``. So any threshold test at or below
        ``far_m`` gives the exact answer, and the per-sample minimum over any set of
        columns that includes ``exact_min_of`` is exact at every sample (the pair that
        attains it is within ``u_t``). The bounds of a capsule/box or capsule/cylinder pair
        hold for a block of 32 samples (:meth:`_bounds`: balls about the segments'
        midpoints, starts and ends over the block), so only the blocks that can be within
        the cutoff are evaluated exactly; for two boxes/cylinders (:func:`shape_shape`),
        a bounding ball's gap or a projection gap (:func:`_convex_bounds`). Capsule-capsule
        and sphere pairs are always exact. A shape pair listed both ways round is bounded
        once (the distance is symmetric).
        """
        p0 = np.asarray(p0, dtype=_FLOAT)
        p1 = np.asarray(p1, dtype=_FLOAT)
        C = len(self.capsules)
        if p0.ndim != 3 or p0.shape[1:] != (C, 3) or p1.shape != p0.shape:
            raise ValueError(f"p0 and p1 must both be (T, {C}, 3) (one segment per capsule), got {p0.shape} and {p1.shape}")
        T = p0.shape[0]
        if far_m is not None and not far_m >= 0.0:
            raise ValueError(f"far_m must be >= 0 m (or None: every value exact), got {far_m}")
        tight = None
        if far_m is not None and exact_min_of is not None:
            tight = np.zeros(len(self.pairs), dtype=bool)
            tight[np.asarray(exact_min_of, dtype=np.int64)] = True
        poses = dict(poses or {})
        for key in self.moving:
            if key not in poses:
                raise ValueError(f"poses[{key!r}] (T, 4, 4) is needed: {key!r} was declared moving")
            pose = poses[key] = np.asarray(poses[key], dtype=_FLOAT)
            if pose.shape != (T, 4, 4):
                raise ValueError(f"poses[{key!r}] must be (T, 4, 4) = ({T}, 4, 4), got {pose.shape}")
        buf = np.empty((len(self.pairs), T))
        # structure of arrays (3, C, T): one contiguous time series per capsule and coordinate
        P0 = np.ascontiguousarray(p0.transpose(2, 1, 0))
        D = np.ascontiguousarray((p1 - p0).transpose(2, 1, 0))
        groups = self._groups
        if T > 1:
            # capsules that do not move (a robot's base) against static shapes: one sample, broadcast
            still = (P0 == P0[:, :, :1]).all(axis=(0, 2)) & (D == D[:, :, :1]).all(axis=(0, 2))
            if still.any():
                groups, once = [], []
                for g in self._groups:
                    if not g.product or g.pose_key is not None:
                        groups.append(g)
                        continue
                    s = still[g.caps]
                    if s.any():
                        once.append(_subgroup(g, s))
                    if not s.all():
                        groups.append(_subgroup(g, ~s) if s.any() else g)
                if once:
                    buf1 = np.empty((len(self.pairs), 1))
                    self._run(once, P0[:, :, :1], D[:, :, :1], {}, None, buf1)  # one sample: exact
                    for g in once:
                        for rr in g.rows:
                            rr = rr[rr >= 0]
                            buf[rr] = buf1[rr]
        self._run(groups, P0, D, poses, far_m, buf, tight)
        return buf.T

    def _run(
        self,
        groups: list[_Group],
        P0: np.ndarray,
        D: np.ndarray,
        poses: dict,
        far_m: float | None,
        buf: np.ndarray,
        tight: np.ndarray | None = None,
    ) -> None:
        """Evaluate ``groups`` for segments ``P0 + t D`` ``(3, C, T)`` into the rows of ``buf (K, T)``.

        With ``far_m``, a first pass writes every capsule/box and capsule/cylinder pair's lower bound into
        ``buf`` (:meth:`_bounds`) and sets the per-sample cutoff ``c_t = max(far_m, u_t)``, ``u_t`` the least
        upper bound over the rows ``tight`` (bool ``(K,)``); the second pass replaces the bounds that are
        ``<= c_t`` by exact values, sample by sample.
        """
        T = P0.shape[2]
        cut = None
        lbs: dict[tuple[int, int], list] = {}
        if far_m is not None:
            # u_t: +inf (every value exact) until a bound of a `tight` row lowers it; without `tight`, c_t = far_m
            upper = np.full(T, np.inf if tight is not None else far_m)
            balls = None
            for gi, g in enumerate(groups):
                if g.product and g.kind != "sphere":
                    if balls is None:
                        balls = _capsule_balls(P0, D)
                    for t0, t1, pose in self._chunks(g, T, poses, far=True):
                        lbs[gi, t0] = self._bounds(g, balls, t1 - t0, pose, buf, t0, upper, tight)
            cut = np.maximum(upper, far_m)
        hits: dict[str, list[tuple[np.ndarray, list[np.ndarray], np.ndarray]]] = {}
        changes: dict[tuple[str, ...], np.ndarray] = {}  # moving pose keys -> where any of them changes
        for gi, g in enumerate(groups):
            if g.kind == "shape":
                items, cols = [], []
                for col, i, j in zip(g.cols, g.ia, g.ib):
                    a, b = self.shapes[i], self.shapes[j]
                    ka, kb = self._pose_key.get(a.name, ""), self._pose_key.get(b.name, "")
                    moved = tuple(sorted({ka, kb} & poses.keys()))
                    for key in moved:
                        if (key,) not in changes:
                            changes[key,] = _pose_changes(poses[key], T)
                    if moved not in changes:  # one array per set of moving poses: _shape_runs shares its runs
                        changes[moved] = np.logical_or.reduce([changes[key,] for key in moved]) if moved else _pose_changes(a.pose[None], T)
                    changed = changes[moved]
                    Pa = poses[ka] if ka in poses else np.asarray(a.pose, dtype=_FLOAT)[None]
                    Pb = poses[kb] if kb in poses else np.asarray(b.pose, dtype=_FLOAT)[None]
                    if a.kind == "sphere" or b.kind == "sphere":  # closed form, exact: once per run of equal poses
                        first = np.flatnonzero(changed)
                        at = [P if len(P) == 1 else P[first] for P in (Pa, Pb)]
                        buf[col] = np.broadcast_to(shape_shape(a, b, *at), (len(first),))[np.cumsum(changed) - 1]
                        continue
                    items.append((a, b, Pa, Pb, changed))
                    cols.append(col)
                if items:
                    for col, v in zip(cols, _shape_runs(items, cut)):
                        buf[col] = v
                continue
            if g.product:
                for t0, t1, pose in self._chunks(g, T, poses, far=cut is not None and g.kind != "sphere"):
                    c = None if cut is None or g.kind == "sphere" else cut[t0:t1]
                    self._product(g, P0, D, t0, t1, buf, hits, c, pose, lbs.get((gi, t0)))
                continue
            step = max(64, self.chunk // max(len(g.cols), 1))
            for t0 in range(0, T, step):
                t1 = min(T, t0 + step)
                a, d = P0[:, g.ia, t0:t1], D[:, g.ia, t0:t1]
                b, e = P0[:, g.ib, t0:t1], D[:, g.ib, t0:t1]
                buf[g.cols, t0:t1] = np.sqrt(_seg_seg_sq(*a, *d, *b, *e)) - g.r
        flat = buf.reshape(-1)
        pending = hits.pop("cylinder-inner", None)
        if pending:
            where = np.concatenate([e[0] for e in pending])
            args = [np.concatenate([e[1][i] for e in pending]) for i in range(11)]
            r = np.concatenate([e[2] for e in pending])
            sq = _cyl_sq_inner(*args, tol=1e-12, max_iter=100)
            flat[where] = np.sqrt(sq) - r
            z = sq == 0.0
            if z.any():
                hits.setdefault("cylinder", []).append((where[z], [args[i][z] for i in (0, 1, 2, 3, 4, 5, 9, 10)], r[z]))
        for kind, entries in hits.items():
            where = np.concatenate([e[0] for e in entries])
            args = [np.concatenate([e[1][i] for e in entries]) for i in range(len(entries[0][1]))]
            r = np.concatenate([e[2] for e in entries])
            flat[where] = -_DEPTH[kind](*args) - r

    def _chunks(self, g: _Group, T: int, poses: dict, far: bool = False):
        """``(t0, t1, pose)`` chunks of a product group: about ``chunk`` pair-samples each, keeping temporaries in cache.

        ``far``: the chunks of the block-bound pass, where only the near blocks are gathered into flat batches
        (a few per cent of the pair-samples): :data:`_FAR_CHUNKS` times longer, so the per-shape work of the
        bounds and the gathers runs over fewer, longer arrays.
        """
        step = max(64, (_FAR_CHUNKS if far else 1) * self.chunk // max(len(g.caps), 1)) // _BLOCK * _BLOCK
        for t0 in range(0, T, step):
            t1 = min(T, t0 + step)
            yield t0, t1, (poses[g.pose_key][t0:t1] if g.pose_key is not None else None)

    @staticmethod
    def _local(g: _Group, a: np.ndarray, d: np.ndarray, pose: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Segment starts and directions ``(3, Cg, n)`` in the frame of the group's shapes."""
        if pose is not None and g.kind == "sphere":  # a ball has no orientation: p - c per sample is enough
            return a - np.ascontiguousarray(pose[:, :3, 3].T)[:, None, :], d
        if pose is not None:  # R^T (p - c) per sample, broadcast over the capsules
            R, c = pose[:, :3, :3], pose[:, :3, 3]
            return np.stack(_to_local(a[0], a[1], a[2], R, c)), np.stack(_to_local(d[0], d[1], d[2], R, c, translate=False))
        if g.rot is not None:
            return np.tensordot(g.rot.T, a, axes=1), np.tensordot(g.rot.T, d, axes=1)  # R^T p: into the shapes' frame
        return a, d

    def _bounds(self, g, balls_all, n_chunk, pose, buf, t0, upper, tight) -> list:
        """Block bounds of a box or cylinder product group for the samples ``t0 ..`` (base frame ``a``, ``d``).

        Per capsule and block of :data:`_BLOCK` samples, the balls ``(c, rho)`` that hold the segment
        midpoints (``rho``: their farthest one plus its half length) and the start and end points. Every
        point of the capsule is then within ``rho + r`` of ``c``, and the capsule holds the ball of radius
        ``r`` about each of those points; ``e`` (the distance outside the shape, 0 inside) is 1-Lipschitz, so
        at every sample of the block::

            e(c_mid) - rho_mid - r  <=  signed distance  <=  min over mid, start, end of e(c) + rho' - r

        (``rho'`` without the half length; the left side is used only where it is positive). A shape that
        moves is bounded by the ball of its centre's path over the block plus its bounding radius. The lower
        bound goes to ``buf`` (and is returned per shape, ``(Cg, blocks)``); the upper bound, over the rows
        ``tight``, lowers ``upper (T,)``.
        """
        n = n_chunk
        b0, nb = t0 // _BLOCK, -(-n // _BLOCK)  # chunks start on a block
        balls = [(c[:, g.caps, b0 : b0 + nb], rho[g.caps, b0 : b0 + nb]) for c, rho in balls_all]
        if pose is not None:  # the shape's centre over each block: a ball about the middle of its extent
            sc = _blocks(np.ascontiguousarray(pose[:, :3, 3].T)[:, None, :], nb)[:, 0]  # (3, nb, B)
            s_c = 0.5 * (sc.min(axis=2) + sc.max(axis=2))
            s_rho = np.sqrt(np.einsum("inb,inb->nb", sc - s_c[..., None], sc - s_c[..., None])).max(axis=1)
            s_rho += _bounding_radius(g.kind, self._size_of(g))
        elif g.rot is not None:
            balls = [(np.tensordot(g.rot.T, c, axes=1), rho) for c, rho in balls]
        r = g.r
        if pose is None:
            return self._static_bounds(g, balls, n, buf, t0, upper, tight)
        out = []
        for s in range(len(g.centre[0])):
            rows = g.rows[s]
            keep = rows >= 0
            if pose is not None:
                e = [np.maximum(np.sqrt(np.einsum("icn,icn->cn", c - s_c[:, None], c - s_c[:, None])) - s_rho, 0.0) for c, _ in balls]
                e_ub = [np.sqrt(np.einsum("icn,icn->cn", c - s_c[:, None], c - s_c[:, None])) + s_rho for c, _ in balls]
            else:
                e = [self._outside(g.kind, c, g, s) for c, _ in balls]
                e_ub = e
            lb = e[0] - balls[0][1] - r
            buf[rows[keep], t0 : t0 + n] = np.repeat(lb[keep], _BLOCK, axis=1)[:, :n]
            out.append(lb)
            if tight is not None:
                sel = keep.copy()
                sel[keep] = tight[rows[keep]]
                if sel.any():
                    ub = np.minimum.reduce([(x + rho)[sel] for x, (_, rho) in zip(e_ub, balls)]) - r[sel]
                    ub = np.repeat(ub.min(axis=0), _BLOCK)[:n]
                    np.minimum(upper[t0 : t0 + n], ub, out=upper[t0 : t0 + n])
        return out

    @staticmethod
    def _static_bounds(g, balls, n, buf, t0, upper, tight) -> list:
        """:meth:`_bounds` for a group of static shapes: every shape at once, ``(S, Cg, blocks)`` arrays."""
        S = len(g.centre[0])
        centre = [np.asarray(v, dtype=_FLOAT)[:, None, None] for v in g.centre]
        size = [np.asarray(v, dtype=_FLOAT)[:, None, None] for v in g.size]
        e = [ProximityKernel._outside_all(g.kind, c, centre, size) for c, _ in balls]
        lb = e[0] - balls[0][1] - g.r  # (S, Cg, nb)
        rows = np.stack(g.rows)  # (S, Cg)
        keep = rows >= 0
        buf[rows[keep], t0 : t0 + n] = np.repeat(lb[keep], _BLOCK, axis=1)[:, :n]
        if tight is not None:
            sel = keep & tight[np.where(keep, rows, 0)]
            if sel.any():
                ub = np.minimum.reduce([(x + rho)[sel] for x, (_, rho) in zip(e, balls)])
                ub -= np.broadcast_to(g.r, (S,) + g.r.shape)[sel]
                ub = np.repeat(ub.min(axis=0), _BLOCK)[:n]
                np.minimum(upper[t0 : t0 + n], ub, out=upper[t0 : t0 + n])
        return list(lb)

    @staticmethod
    def _outside_all(kind: str, p, centre, size) -> np.ndarray:
        """Distance (m) of the points ``p`` (x, y, z in the shapes' frame) outside each shape, 0 inside: ``centre``
        and ``size`` (half sizes) per coordinate, scalars for one shape or ``(S, 1, 1)`` arrays for several."""
        ex = [np.abs(v - ci) for v, ci in zip(p, centre)]
        if kind == "box":
            out = sum(np.maximum(e - h, 0.0) ** 2 for e, h in zip(ex, size))
        else:
            rad = np.maximum(np.sqrt(ex[0] ** 2 + ex[1] ** 2) - size[0], 0.0)
            out = rad * rad + np.maximum(ex[2] - size[1], 0.0) ** 2
        return np.sqrt(out, out=out)

    @staticmethod
    def _size_of(g: _Group) -> list[float]:
        """The size of a moving group's one shape, as :class:`Shape` gives it (full extents, radius, ...)."""
        if g.kind == "box":
            return [2.0 * v[0] for v in g.size]
        if g.kind == "cylinder":
            return [g.size[0][0], 2.0 * g.size[1][0]]
        return [g.size[0][0]]

    @staticmethod
    def _outside(kind: str, p, g: _Group, s: int) -> np.ndarray:
        """Distance (m) of the points ``p`` (x, y, z in the group's frame) outside shape ``s`` of ``g``, 0 inside."""
        return ProximityKernel._outside_all(kind, p, [c[s] for c in g.centre], [v[s] for v in g.size])

    @staticmethod
    def _collect(hits, kind, sq, loc, a, d, c, size, r):
        """Record the samples where a segment meets a shape (``sq == 0``) for the batched depth pass.

        ``loc(ci, ti)``: the flat output indices of the entries ``(ci, ti)`` of ``sq`` (-1: not requested).
        """
        ci, ti = np.nonzero(sq == 0.0)
        where = loc(ci, ti)
        keep = where >= 0
        if not keep.all():
            ci, ti, where = ci[keep], ti[keep], where[keep]
        if not ci.size:
            return
        args = [np.broadcast_to(a[i], sq.shape)[ci, ti] - c[i] for i in range(3)]
        args += [np.broadcast_to(d[i], sq.shape)[ci, ti] for i in range(3)]
        args += [np.broadcast_to(np.asarray(v, dtype=_FLOAT), sq.shape)[ci, ti] for v in size]
        hits.setdefault(kind, []).append((where, args, np.broadcast_to(r, sq.shape)[ci, ti]))

    @staticmethod
    def _defer_inner(hits, pending, loc, r, shape):
        """Record the cylinder pairs whose minimiser is interior for the batched Newton pass."""
        (ci, ti), sub = pending
        where = loc(ci, ti)
        keep = where >= 0
        if not keep.all():
            ci, ti, where, sub = ci[keep], ti[keep], where[keep], [v[keep] for v in sub]
        hits.setdefault("cylinder-inner", []).append((where, sub, np.broadcast_to(r, shape)[ci, ti]))

    def _product(
        self,
        g: _Group,
        P0: np.ndarray,
        D: np.ndarray,
        t0: int,
        t1: int,
        buf: np.ndarray,
        hits: dict,
        cut: np.ndarray | None,
        pose: np.ndarray | None,
        lbs: list | None = None,
    ) -> None:
        """Evaluate one product group for the samples ``t0 .. t1``; ``P0``, ``D``: ``(3, C, T)`` segment starts and
        directions of every capsule.

        ``pose (n, 4, 4)``: the per-sample pose of a moving group's shape. ``cut (n,)``: :meth:`_bounds` has
        written block lower bounds ``lbs`` into ``buf``; only the blocks whose bound is ``<= cut`` somewhere in
        the block are evaluated exactly (gathered into one flat batch per shape), the others keep their bound.
        """
        T = buf.shape[1]
        n = t1 - t0
        r = g.r
        if cut is not None:
            flat = buf.reshape(-1)
            cut_b = _blocks(cut[None], lbs[0].shape[1])[0].max(axis=1)
            # flat takes of the entries straight from (3, C * T): no (3, Cg, n) copy of the group's capsules
            Tp = P0.shape[2]
            a2, d2 = np.ascontiguousarray(P0).reshape(3, -1), np.ascontiguousarray(D).reshape(3, -1)
            base = g.caps * Tp + t0
            for s, lb in enumerate(lbs):
                rows = g.rows[s]
                near = lb <= cut_b
                near &= (rows >= 0)[:, None]
                ci, bi = np.nonzero(near)
                if not ci.size:
                    continue
                ti = (bi[:, None] * _BLOCK + np.arange(_BLOCK)).ravel()
                ci = np.repeat(ci, _BLOCK)
                if n % _BLOCK:  # the last block is short
                    ok = ti < n
                    ci, ti = ci[ok], ti[ok]
                flat_i = base[ci] + ti  # (3, m): one flat batch of (capsule, sample) entries
                ga, gd = np.take(a2, flat_i, axis=1), np.take(d2, flat_i, axis=1)
                if pose is not None:
                    R, c0 = pose[ti, :3, :3], pose[ti, :3, 3]
                    ga, gd = np.stack(_to_local(*ga, R, c0)), np.stack(_to_local(*gd, R, c0, translate=False))
                elif g.rot is not None:
                    ga, gd = g.rot.T @ ga, g.rot.T @ gd
                ga, gd = ga[:, None, :], gd[:, None, :]
                where = rows[ci] * T + t0 + ti
                o = np.empty((1, len(where)))
                c = tuple(v[s] for v in g.centre)
                size = tuple(v[s] for v in g.size)
                self._shape_eval(g.kind, ga, gd, self._prep(g.kind, gd), c, size, r[ci, 0][None], lambda ci, ti: where[ti], hits, o)
                flat[where] = o[0]
            return
        a, d = self._local(g, P0[:, g.caps, t0:t1], D[:, g.caps, t0:t1], pose)
        aux = self._prep(g.kind, d)
        for s in range(len(g.centre[0])):
            c = tuple(ci[s] for ci in g.centre)
            size = tuple(v[s] for v in g.size)
            rows = g.rows[s]
            view = g.views[s]
            o = buf[view, t0 : t0 + n] if view is not None else np.empty((len(rows), n))

            def loc(ci, ti, rows=rows):
                rr = rows[ci]
                return np.where(rr >= 0, rr * T + t0 + ti, -1)

            self._shape_eval(g.kind, a, d, aux, c, size, r, loc, hits, o)
            if view is None:
                keep = rows >= 0
                buf[rows[keep], t0 : t0 + n] = o[keep]

    @staticmethod
    def _prep(kind: str, d: np.ndarray):
        """The per-segment terms of a kind's kernel for directions ``d (3, ...)``."""
        dx, dy, dz = d
        if kind == "box":
            return _box_prep(dx, dy, dz)
        aux = dx * dx
        aux += dy * dy
        if kind == "cylinder":
            return aux
        aux += dz * dz
        aux += 1e-300
        return np.divide(1.0, aux, out=aux)

    def _shape_eval(self, kind, a, d, aux, c, size, r, loc, hits, o) -> None:
        """Signed distances ``o (k, n)`` of segments ``a + t d`` ``(3, k, n)`` (shape frame) to one shape."""
        ax, ay, az = a
        dx, dy, dz = d
        if kind == "box":
            sq = _box_sq(ax, ay, az, dx, dy, dz, aux, *c, *size)
        elif kind == "cylinder":
            sq, pending = _cyl_sq(ax, ay, az, dx, dy, dz, aux, *c, *size, defer=True)
            if pending is not None:
                self._defer_inner(hits, pending, loc, r, sq.shape)
        else:
            sq = _point_seg_sq(*c, ax, ay, az, dx, dy, dz, aux)
        np.sqrt(sq, out=o)
        if kind == "sphere":
            o -= size[0]
        elif sq.min() == 0.0:
            self._collect(hits, kind, sq, loc, a, d, c, size, r)
        o -= r
