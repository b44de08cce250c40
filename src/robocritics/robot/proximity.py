"""Exact signed distances between the robot's capsules and the scene's shapes, vectorised over samples.

Every length is in metres. A **capsule** is a segment ``p0``-``p1`` (base frame)
swept by a ball of radius ``r``; scene shapes are :class:`~robocritics.scene.Shape`
primitives: ``box`` (``size`` = full extents), ``cylinder`` (``size`` =
``[radius, height]``, axis along the shape's local z) and ``sphere``
(``size = [radius]``), each centred at its 4x4 ``pose``. A pose may also vary
per sample (``(T, 4, 4)``): an object carried by the gripper.

**Signed distance.** For two convex sets A, B the signed distance is their
separation distance when they are apart and ``-(penetration depth)`` when they
overlap, the penetration depth being the length of the shortest translation that
separates them (what coal's GJK/EPA reports). For a capsule
``A = S + ball(r)`` around the segment ``S``::

    sd(A, B) = dist(S, B) - r                    if S does not touch B
    sd(A, B) = -(depth(S, B) + r)                if S meets B

(the Minkowski difference ``B - A`` is ``(B - S)`` grown by ``r``, so its
boundary is ``r`` further from the origin in every direction). Hence every
capsule distance below reduces to the exact distance or the exact depth of a
*segment*, and the functions here compute both in closed form or to machine
precision:

* capsule-capsule: closest points of two segments (closed form with clamping,
  robust for parallel and zero-length segments); overlapping segments have depth
  0, so ``segment distance - ra - rb`` is exact everywhere.
* capsule-sphere: point-segment distance minus both radii, exact everywhere.
* capsule-box: in the box frame the squared distance
  ``f(t) = sum_i max(|a_i + t d_i| - h_i, 0)^2`` of the point ``a + t d`` is
  convex and piecewise quadratic, ``f'`` is continuous, piecewise linear and
  non-decreasing. The segment's slab intervals ``[l_i, u_i]`` (where the line is
  between the faces ``+-h_i``) give ``U = min u_i``, ``L = max l_i``: if
  ``L <= U`` the line passes through the box; otherwise the root of ``f'`` lies in
  ``[U, L]`` where only one axis can still switch, and it is
  ``clip(t_mid, t_lo, t_hi)`` of three weighted means (see :func:`_seg_box_sq`),
  then clipped to ``[0, 1]``. No sorting, no iteration. A segment inside the box
  has the depth ``min_n h_Z(n)`` over the face normals of the zonotope
  ``Z = box - segment`` (the box axes ``e_i`` and ``e_i x d``), also closed form.
* capsule-cylinder: ``F(t) = max(rho(t) - R, 0)^2 + max(|z(t)| - H, 0)^2`` is
  convex and C1 (``rho`` is the distance to the axis); its minimiser over
  ``[0, 1]`` is the root of the non-decreasing ``F'`` and is found by Newton's
  method safeguarded by bisection on a bracket, iterated until the bracket or
  the step is below ``1e-12`` (in ``t``; the distance error is second order in
  the ``t`` error, far below ``1e-9`` m). A segment meeting the cylinder gets
  its depth from the candidates of ``min_n h_Z(n)``: the two caps, the radial
  directions of both endpoints, and the directions orthogonal to the segment,
  where the problem becomes the 2-D depth of a point in the cylinder's shadow
  along the segment (a rectangle capped by two half ellipses); the distance to
  a half ellipse uses all stationary points (roots of a quartic, polished by
  Newton's method) and the arc's ends. coal's EPA is *not* used for this: for
  cylinders it is off by up to 1e-4 m with its default settings and fails
  outright with tighter tolerances (see ``tests/test_proximity.py``).

Carried objects: a sphere against anything (and anything against a sphere) is a
point-shape distance minus the radius, closed form everywhere (depth of a point
inside a box or cylinder is its distance to the nearest face). A carried box or
cylinder against a static box or cylinder has no closed form; those pairs are
computed by ``coal.distance`` one sample at a time (about 1-3 us per sample and
pair), optionally culled with the exact lower bound of bounding spheres
(``far_m``).

:class:`ProximityKernel` batches it all for a trajectory: built once from the
capsules, the scene shapes and the pairs, its :meth:`~ProximityKernel.distances`
returns ``(T, K)`` signed distances, grouping the pairs by shape kind and
evaluating each group over all its pairs and samples at once, in cache-sized
chunks.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..scene import Shape

__all__ = [
    "CARRIED",
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

CARRIED = "@carried"
"""Name of the carried object in :class:`ProximityKernel` pairs (not a valid scene id, so it cannot clash)."""

_TINY_D = 1e-150  # |direction component| below this (m) counts as zero
_FLOAT = np.float64


# ----------------------------------------------------------------------------------------------
# flat kernels: component arrays (broadcastable), float64, no Python loop over samples
# ----------------------------------------------------------------------------------------------


def _seg_seg_sq(ax, ay, az, ux, uy, uz, bx, by, bz, vx, vy, vz):
    """Squared distance (m^2) between segments ``a + s u`` and ``b + t v``, ``s, t`` in [0, 1].

    Closed form (Ericson, *Real-Time Collision Detection* 5.1.9): ``s`` from the
    lines' closest points (0 when parallel), ``t`` optimal for ``s`` and clamped,
    ``s`` optimal for that ``t`` and clamped, then ``t`` once more. Each step is an
    exact one-variable minimisation, so the result is never worse than Ericson's,
    which is exact; zero-length segments fall out of the guarded divisions.
    """
    rx, ry, rz = ax - bx, ay - by, az - bz
    a = ux * ux + uy * uy + uz * uz
    e = vx * vx + vy * vy + vz * vz
    b = ux * vx + uy * vy + uz * vz
    c = ux * rx + uy * ry + uz * rz
    f = vx * rx + vy * ry + vz * rz
    denom = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        ok_a = a > 1e-300
        ok_e = e > 1e-300
        inv_a = np.where(ok_a, 1.0 / np.where(ok_a, a, 1.0), 0.0)
        inv_e = np.where(ok_e, 1.0 / np.where(ok_e, e, 1.0), 0.0)
        par = denom <= 1e-14 * a * e
        s = np.where(par, 0.0, (b * f - c * e) / np.where(par, 1.0, denom))
    s = np.clip(s, 0.0, 1.0)
    t = (b * s + f) * inv_e
    t = np.clip(t, 0.0, 1.0)
    s = (b * t - c) * inv_a
    s = np.clip(s, 0.0, 1.0)
    t = (b * s + f) * inv_e
    t = np.clip(t, 0.0, 1.0)
    wx = rx + s * ux - t * vx
    wy = ry + s * uy - t * vy
    wz = rz + s * uz - t * vz
    return wx * wx + wy * wy + wz * wz


def _point_seg_sq(px, py, pz, ax, ay, az, dx, dy, dz):
    """Squared distance (m^2) from points ``p`` to segments ``a + t d``, ``t`` in [0, 1] (exact)."""
    wx, wy, wz = px - ax, py - ay, pz - az
    dd = dx * dx + dy * dy + dz * dz
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (wx * dx + wy * dy + wz * dz) / dd
    t = np.where(dd > 1e-300, t, 0.0)
    t = np.clip(t, 0.0, 1.0)
    wx = wx - t * dx
    wy = wy - t * dy
    wz = wz - t * dz
    return wx * wx + wy * wy + wz * wz


def _seg_box_sq(ax, ay, az, dx, dy, dz, hx, hy, hz):
    """Squared distance (m^2) from segments ``a + t d`` (box frame) to boxes ``|x_i| <= h_i``.

    ``f(t) = sum_i max(|a_i + t d_i| - h_i, 0)^2`` is convex; with the slab
    interval ``[l_i, u_i]`` of axis i (the ``t`` where ``|a_i + t d_i| <= h_i``,
    the whole line when ``d_i = 0``) and weight ``w_i = d_i^2``,
    ``f'(t)/2 = sum_i w_i (t - clip(t, l_i, u_i))``. Let ``U = min u_i``,
    ``L = max l_i``.

    * ``L <= U``: the line crosses the box on ``[L, U]``; the minimiser over
      [0, 1] is any point of ``[L, U] & [0, 1]`` (the midpoint, so that rounding
      keeps it inside), or the nearer end when they do not overlap.
    * ``L > U``: the line misses; ``f' <= 0`` up to ``U`` and ``>= 0`` from ``L``.
      On ``[U, L]`` the axis j with ``u_j = U`` is above its slab, the axis k with
      ``l_k = L`` below, and only the third axis m can change state. With
      ``l'_i, u'_i`` the breakpoints clipped to ``[U, L]`` (equal for j and k),
      ``sum w_i (t - u'_i) <= f'/2 <= sum w_i (t - l'_i)``, so the root lies between
      ``t_lo = sum w_i l'_i / W`` and ``t_hi = sum w_i u'_i / W``; it is ``t_lo`` if
      m is below its slab there, ``t_hi`` if above, else the root ``t_mid`` of the
      axes with ``l'_i = u'_i`` alone, and in all three cases
      ``t* = clip(t_mid, t_lo, t_hi)``.

    The root is clipped to [0, 1] (f is convex) and ``f`` evaluated there, so the
    result is the exact squared distance up to rounding; it is exactly 0 when the
    segment meets the box.
    """
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        ls, us, ws = [], [], []
        for a, d, h in ((ax, dx, hx), (ay, dy, hy), (az, dz, hz)):
            ds = np.where(np.abs(d) < _TINY_D, 1e-300, d)  # w underflows to 0; l, u stay finite
            inv = 1.0 / ds
            t0 = (-h - a) * inv
            t1 = (h - a) * inv
            ls.append(np.minimum(t0, t1))
            us.append(np.maximum(t0, t1))
            ws.append(ds * ds)
        U = np.minimum(np.minimum(us[0], us[1]), us[2])
        L = np.maximum(np.maximum(ls[0], ls[1]), ls[2])
        W = ws[0] + ws[1] + ws[2]
        n_lo = n_hi = n_mid = w_mid = 0.0
        for l, u, w in zip(ls, us, ws):
            lc = np.minimum(np.maximum(l, U), L)
            uc = np.minimum(np.maximum(u, U), L)
            wl = w * lc
            n_lo = n_lo + wl
            n_hi = n_hi + w * uc
            eq = lc == uc
            n_mid = n_mid + np.where(eq, wl, 0.0)
            w_mid = w_mid + np.where(eq, w, 0.0)
        Wp = np.maximum(W, 1e-300)
        t = np.minimum(np.maximum(n_mid / np.maximum(w_mid, 1e-300), n_lo / Wp), n_hi / Wp)
        hit = 0.5 * (np.maximum(L, 0.0) + np.minimum(U, 1.0))
        t = np.where(L > U, t, hit)
    t = np.clip(t, 0.0, 1.0)
    sq = None
    for a, d, h in ((ax, dx, hx), (ay, dy, hy), (az, dz, hz)):
        e = np.maximum(np.abs(a + t * d) - h, 0.0)
        e = e * e
        sq = e if sq is None else sq + e
    return sq


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


def _seg_cyl_sq(ax, ay, az, dx, dy, dz, R, H, tol=1e-12, max_iter=100):
    """Squared distance (m^2) from segments ``a + t d`` (cylinder frame) to cylinders of radius R, half height H.

    ``F(t) = max(rho - R, 0)^2 + max(|z| - H, 0)^2`` with ``rho(t)^2 = A t^2 + 2 B t + C``
    is the squared distance of a convex set along a line: convex and C1 (the radial
    term vanishes near the axis, where ``rho`` is not smooth). ``F' >= 0`` at ``t = 0``
    puts the minimiser there, ``F' <= 0`` at ``t = 1`` puts it at 1; otherwise the
    root of the non-decreasing ``F'`` is bracketed in (0, 1) and found by Newton
    steps (``F''`` of the active terms) that fall back to bisection when they leave
    the bracket, until the bracket or the step is below ``tol``. Because ``F'(t*) = 0``
    the distance error is second order in the ``t`` error.
    """
    shape = np.broadcast(ax, ay, az, dx, dy, dz, R, H).shape
    args = [np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=_FLOAT), shape)).ravel() for v in (ax, ay, az, dx, dy, dz, R, H)]
    ax, ay, az, dx, dy, dz, R, H = args
    A = dx * dx + dy * dy
    B = ax * dx + ay * dy
    C = ax * ax + ay * ay

    def grad(t, ax, az, dz, A, B, C, R, H, hess=True):
        rho2 = (A * t + 2.0 * B) * t + C
        rho = np.sqrt(np.maximum(rho2, 0.0))
        er = np.maximum(rho - R, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            rp = (A * t + B) / np.maximum(rho, 1e-300)
        z = az + t * dz
        ez = z - np.clip(z, -H, H)
        g = er * rp + ez * dz
        if not hess:
            return g, None
        act_r = er > 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            hr = np.where(act_r, rp * rp + er * (A - rp * rp) / np.maximum(rho, 1e-300), 0.0)
        h = hr + np.where(ez != 0.0, dz * dz, 0.0)
        return g, h

    # where the segment meets the cylinder: t in [0, 1], in the z slab and rho(t) <= R
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        ds = np.where(np.abs(dz) < _TINY_D, 1e-300, dz)
        z0 = (-H - az) / ds
        z1 = (H - az) / ds
        lo = np.maximum(np.minimum(z0, z1), 0.0)
        hi = np.minimum(np.maximum(z0, z1), 1.0)
        disc = B * B - A * (C - R * R)
        sq = np.sqrt(np.maximum(disc, 0.0))
        q = -(B + np.where(B >= 0.0, sq, -sq))
        r1 = q / A
        r2 = (C - R * R) / q
        flat = A <= 1e-300
        lo = np.where(flat, np.where(C <= R * R, lo, np.inf), np.maximum(lo, np.minimum(r1, r2)))
        hi = np.where(flat, hi, np.minimum(hi, np.maximum(r1, r2)))
        lo = np.where(~flat & (disc < 0.0), np.inf, lo)
    hit = lo <= hi
    g0, _ = grad(np.zeros_like(ax), ax, az, dz, A, B, C, R, H, hess=False)
    g1, _ = grad(np.ones_like(ax), ax, az, dz, A, B, C, R, H, hess=False)
    t = np.where(g0 >= 0.0, 0.0, 1.0)
    idx = np.flatnonzero((g0 < 0.0) & (g1 > 0.0) & ~hit)
    if idx.size:
        sub = [v[idx] for v in (ax, az, dz, A, B, C, R, H)]
        with np.errstate(divide="ignore", invalid="ignore"):
            t0 = np.clip(-sub[4] / sub[3], 0.0, 1.0)
        t0 = np.where(np.isfinite(t0), t0, 0.5)
        lo = np.zeros(idx.size)
        hi = np.ones(idx.size)
        ti = t0
        for _ in range(max_iter):
            g, h = grad(ti, *sub)
            neg = g <= 0.0
            lo = np.where(neg, np.maximum(lo, ti), lo)
            hi = np.where(neg, hi, np.minimum(hi, ti))
            with np.errstate(divide="ignore", invalid="ignore"):
                tn = ti - g / h
            bad = ~((tn >= lo) & (tn <= hi))  # also NaN (h = 0)
            tn = np.where(bad, 0.5 * (lo + hi), tn)
            done = (np.abs(tn - ti) <= tol) | (hi - lo <= tol) | (g == 0.0)
            ti = tn
            if done.all():
                break
            if done.any():
                t[idx[done]] = ti[done]
                keep = ~done
                idx = idx[keep]
                sub = [v[keep] for v in sub]
                lo, hi, ti = lo[keep], hi[keep], ti[keep]
        t[idx] = ti
    rho = np.sqrt(np.maximum((A * t + 2.0 * B) * t + C, 0.0))
    er = np.maximum(rho - R, 0.0)
    z = az + t * dz
    ez = np.maximum(np.abs(z) - H, 0.0)
    return np.where(hit, 0.0, er * er + ez * ez).reshape(shape)


def _dist_upper_half_ellipse(qx, qy, a, b):
    """Distance (m) from points q to the arcs ``(a cos p, b sin p)``, ``p`` in [0, pi] (a > 0, 0 <= b <= a).

    The nearest point is an arc end or a stationary point of
    ``g(p) = (a cos p - qx)^2 + (b sin p - qy)^2``, i.e. ``sin p (A cos p + a qx) = b qy cos p``
    with ``A = b^2 - a^2``; squaring gives a quartic in ``c = cos p`` whose roots (companion
    matrix eigenvalues) and a few seeds are polished by damped Newton steps on g' that only
    accept decreases. Every candidate is a point of the arc, so the minimum over them is
    never below the true distance, and it contains the true minimiser.
    """
    qx = np.asarray(qx, dtype=_FLOAT) / a
    qy = np.asarray(qy, dtype=_FLOAT) / a
    m = np.asarray(b, dtype=_FLOAT) / a
    n = qx.size
    A = m * m - 1.0  # <= 0
    Bq = qx
    Cq = m * qy
    seeds = [
        np.zeros(n),
        np.full(n, np.pi),
        np.full(n, 0.5 * np.pi),
        np.clip(np.arctan2(qy, np.where(m > 0, qx * m, qx)), 0.0, np.pi),
        np.arccos(np.clip(qx, -1.0, 1.0)),
    ]
    lead = A * A
    scale = np.maximum(np.maximum(lead, Bq * Bq + Cq * Cq), 1e-300)
    good = lead > 1e-14 * scale
    if good.any():
        i = np.flatnonzero(good)
        Ai, Bi, Ci = A[i], Bq[i], Cq[i]
        # -A^2 c^4 - 2AB c^3 + (A^2 - B^2 - C^2) c^2 + 2AB c + B^2 = 0, made monic
        c3 = 2.0 * Bi / Ai
        c2 = -(Ai * Ai - Bi * Bi - Ci * Ci) / (Ai * Ai)
        c1 = -2.0 * Bi / Ai
        c0 = -(Bi * Bi) / (Ai * Ai)
        M = np.zeros((i.size, 4, 4))
        M[:, 0, :] = -np.stack([c3, c2, c1, c0], axis=1)
        M[:, 1, 0] = M[:, 2, 1] = M[:, 3, 2] = 1.0
        roots = np.linalg.eigvals(M).real
        for k in range(4):
            s = seeds[2].copy()
            s[i] = np.arccos(np.clip(roots[:, k], -1.0, 1.0))
            seeds.append(s)

    def g_of(p):
        return (np.cos(p) - qx) ** 2 + (m * np.sin(p) - qy) ** 2

    best = None
    for p in seeds:
        g = g_of(p)
        lam = np.ones(n)
        for _ in range(12):
            c, s = np.cos(p), np.sin(p)
            d1 = A * s * c + qx * s - m * qy * c
            d2 = A * (c * c - s * s) + qx * c + m * qy * s
            with np.errstate(divide="ignore", invalid="ignore"):
                step = np.where(d2 > 0.0, -d1 / d2, -np.sign(d1) * 0.1)
            step = np.where(np.isfinite(step), step, 0.0)
            pn = np.clip(p + lam * step, 0.0, np.pi)
            gn = g_of(pn)
            acc = gn < g
            p = np.where(acc, pn, p)
            g = np.where(acc, gn, g)
            lam = np.where(acc, 1.0, 0.5 * lam)
        best = g if best is None else np.minimum(best, g)
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
    ok = np.flatnonzero(dxy > 1e-12 * np.maximum(dn, 1e-300))
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
    R, c = _pose_parts(pose)
    x0, y0, z0 = _xyz(p0)
    x1, y1, z1 = _xyz(p1)
    a = _to_local(x0, y0, z0, R, c)
    d = _to_local(x1 - x0, y1 - y0, z1 - z0, R, c, translate=False)
    return a, d


def segment_distance(a0: Any, a1: Any, b0: Any, b1: Any) -> np.ndarray:
    """Distance (m) between segments ``a0-a1`` and ``b0-b1``; arrays ``(..., 3)`` broadcast, result ``(...)``."""
    ax, ay, az = _xyz(a0)
    bx, by, bz = _xyz(b0)
    x1, y1, z1 = _xyz(a1)
    x2, y2, z2 = _xyz(b1)
    return np.sqrt(_seg_seg_sq(ax, ay, az, x1 - ax, y1 - ay, z1 - az, bx, by, bz, x2 - bx, y2 - by, z2 - bz))


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
    x0, y0, z0 = _xyz(p0)
    x1, y1, z1 = _xyz(p1)
    cx, cy, cz = _xyz(center)
    return np.sqrt(_point_seg_sq(cx, cy, cz, x0, y0, z0, x1 - x0, y1 - y0, z1 - z0)) - r - radius


def _signed_from_sq(sq, depth_fn, args, r):
    out = np.sqrt(sq)
    hit = np.flatnonzero(sq.ravel() == 0.0)
    if hit.size:
        flat = out.reshape(-1)
        sub = [np.broadcast_to(np.asarray(v, dtype=_FLOAT), sq.shape).reshape(-1)[hit] for v in args]
        flat[hit] = -depth_fn(*sub)
    return out - r


def capsule_box(p0: Any, p1: Any, r: Any, size: Any, pose: Any) -> np.ndarray:
    """Signed distance (m) between capsules ``(p0-p1, r)`` ``(T, 3)`` and a box.

    ``size`` is the box's full extents ``[x, y, z]`` (m); ``pose`` its centre's 4x4
    transform, static ``(4, 4)`` or per sample ``(T, 4, 4)``. Exact separation by the
    piecewise-quadratic root of :func:`_seg_box_sq`; exact depth (closed form,
    :func:`_seg_box_depth`) where the segment meets the box.
    """
    (ax, ay, az), (dx, dy, dz) = _local_segment(p0, p1, pose)
    h = np.asarray(size, dtype=_FLOAT) * 0.5
    args = (ax, ay, az, dx, dy, dz, h[..., 0], h[..., 1], h[..., 2])
    return _signed_from_sq(_seg_box_sq(*args), _seg_box_depth, args, r)


def capsule_cylinder(p0: Any, p1: Any, r: Any, radius: Any, height: Any, pose: Any) -> np.ndarray:
    """Signed distance (m) between capsules ``(p0-p1, r)`` ``(T, 3)`` and a cylinder.

    ``radius`` and full ``height`` in m, axis along the pose's z; ``pose`` ``(4, 4)`` or
    ``(T, 4, 4)``. Separation by safeguarded Newton on the convex ``F(t)``
    (:func:`_seg_cyl_sq`), depth exact where the segment meets the cylinder
    (:func:`_seg_cyl_depth`).
    """
    (ax, ay, az), (dx, dy, dz) = _local_segment(p0, p1, pose)
    R = np.asarray(radius, dtype=_FLOAT)
    H = np.asarray(height, dtype=_FLOAT) * 0.5
    args = (ax, ay, az, dx, dy, dz, R, H)
    return _signed_from_sq(_seg_cyl_sq(*args), _seg_cyl_depth, args, r)


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
    raise ValueError(f"unknown shape kind {kind!r}; use box, cylinder or sphere")


def _bounding_radius(kind: str, size: Sequence[float]) -> float:
    if kind == "box":
        return 0.5 * float(np.linalg.norm(size))
    if kind == "cylinder":
        return float(np.hypot(size[0], 0.5 * size[1]))
    return float(size[0])


def shape_shape(a: Shape, b: Shape, pose_a: Any = None, pose_b: Any = None, far_m: float | None = None) -> np.ndarray:
    """Signed distance (m) between two scene shapes whose poses may vary per sample (``(T, 4, 4)``).

    Exact in closed form when either is a sphere (point-shape distance minus the
    radius). Box/cylinder against box/cylinder: ``coal.distance`` per sample (GJK when
    apart, EPA when overlapping; about 1-3 us per sample). With ``far_m`` set,
    samples whose bounding spheres are more than ``far_m`` apart are not sent to coal
    and get that bounding-sphere gap instead: an exact *lower bound* (> ``far_m``), not
    the distance. Result shape ``(T,)`` (``(1,)`` for two static poses).
    """
    pose_a = a.pose if pose_a is None else np.asarray(pose_a, dtype=_FLOAT)
    pose_b = b.pose if pose_b is None else np.asarray(pose_b, dtype=_FLOAT)
    if a.kind == "sphere" or b.kind == "sphere":
        if a.kind != "sphere":
            a, b, pose_a, pose_b = b, a, pose_b, pose_a
        _, c = _pose_parts(pose_a)
        return np.atleast_1d(sphere_shape(c, a.size[0], b, pose_b))
    import coal

    Pa = pose_a.reshape(-1, 4, 4)
    Pb = pose_b.reshape(-1, 4, 4)
    T = max(len(Pa), len(Pb))
    Pa = np.broadcast_to(Pa, (T, 4, 4))
    Pb = np.broadcast_to(Pb, (T, 4, 4))
    out = np.empty(T)
    todo = np.arange(T)
    if far_m is not None:
        gap = np.linalg.norm(Pa[:, :3, 3] - Pb[:, :3, 3], axis=1) - _bounding_radius(a.kind, a.size) - _bounding_radius(b.kind, b.size)
        far = gap > far_m
        out[far] = gap[far]
        todo = np.flatnonzero(~far)
    ga, gb = _coal_geometry(a.kind, a.size), _coal_geometry(b.kind, b.size)
    solver = coal.ComputeDistance(ga, gb)
    req = coal.DistanceRequest()
    res = coal.DistanceResult()
    ta, tb = coal.Transform3s(), coal.Transform3s()
    static_a, static_b = pose_a.ndim == 2, pose_b.ndim == 2
    if static_a:
        ta.setRotation(Pa[0, :3, :3].copy())
        ta.setTranslation(Pa[0, :3, 3].copy())
    if static_b:
        tb.setRotation(Pb[0, :3, :3].copy())
        tb.setTranslation(Pb[0, :3, 3].copy())
    for i in todo:
        if not static_a:
            ta.setRotation(Pa[i, :3, :3].copy())
            ta.setTranslation(Pa[i, :3, 3].copy())
        if not static_b:
            tb.setRotation(Pb[i, :3, :3].copy())
            tb.setTranslation(Pb[i, :3, 3].copy())
        res.clear()
        out[i] = solver(ta, tb, req, res)
    return out


# ----------------------------------------------------------------------------------------------
# batch API
# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CapsuleSpec:
    """A robot capsule: its name and radius (m). Endpoints come per call."""

    name: str
    radius: float


@dataclass(frozen=True)
class _Group:
    kind: str  # "box", "cyl", "sphere", "cap", "box@", "cyl@", "sphere@" (against the carried pose), "carried"
    cols: np.ndarray  # output columns
    ia: np.ndarray  # capsule index (a side)
    ib: np.ndarray  # capsule index (b side, kind "cap") or shape index
    consts: dict[str, np.ndarray] = field(default_factory=dict)


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


class ProximityKernel:
    """Signed distances (m) of many capsule/shape pairs over a whole trajectory, exact and vectorised.

    Built once from the capsules (``CapsuleSpec`` or ``(name, radius)``), the scene
    shapes and ``pairs`` of names ``(a, b)``:

    * ``(capsule, shape)``: a capsule against a static scene shape;
    * ``(capsule, capsule)``: a self pair;
    * ``(capsule, CARRIED)``: a capsule against the carried object (pose per sample);
    * ``(CARRIED, shape)``: the carried object against a static shape.

    ``carried`` is the carried object's :class:`Shape` (its pose is ignored; the pose
    per sample is passed to :meth:`distances`). Names must be unique across capsules
    and shapes. Column k of the result is ``pairs[k]``; ``owners[k]`` is the entity
    (``Shape.owner``, or the capsule name) of its b side, and :meth:`groups` gives
    the columns per ``(a, owner)`` for :func:`reduce_min`.
    """

    def __init__(
        self,
        capsules: Sequence[CapsuleSpec | tuple[str, float]],
        shapes: Sequence[Shape],
        pairs: Sequence[tuple[str, str]],
        carried: Shape | None = None,
        chunk: int = 8192,
    ):
        self.capsules = tuple(c if isinstance(c, CapsuleSpec) else CapsuleSpec(str(c[0]), float(c[1])) for c in capsules)
        self.shapes = tuple(shapes)
        self.carried = carried
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
        for s in (*self.shapes, *([carried] if carried is not None else [])):
            if s.kind not in ("box", "cylinder", "sphere"):
                raise ValueError(f"shape {s.name!r}: unknown kind {s.kind!r}; use box, cylinder or sphere")
        self.radii = np.array([c.radius for c in self.capsules], dtype=_FLOAT)
        self.pairs = tuple((str(a), str(b)) for a, b in pairs)
        owners: list[str] = []
        buckets: dict[str, list[tuple[int, int, int]]] = {}
        for k, (a, b) in enumerate(self.pairs):
            if a == CARRIED:
                if carried is None:
                    raise ValueError(f"pair {k} {(a, b)}: no carried object was given")
                if b not in shape_index:
                    raise ValueError(f"pair {k} {(a, b)}: the carried object pairs only with a scene shape")
                buckets.setdefault("carried", []).append((k, -1, shape_index[b]))
                owners.append(self.shapes[shape_index[b]].owner)
                continue
            if a not in cap_index:
                raise ValueError(f"pair {k} {(a, b)}: {a!r} is not a capsule (have {', '.join(cap_index)})")
            ia = cap_index[a]
            if b == CARRIED:
                if carried is None:
                    raise ValueError(f"pair {k} {(a, b)}: no carried object was given")
                kind = {"box": "box@", "cylinder": "cyl@", "sphere": "sphere@"}[carried.kind]
                buckets.setdefault(kind, []).append((k, ia, -1))
                owners.append(carried.owner)
            elif b in cap_index:
                buckets.setdefault("cap", []).append((k, ia, cap_index[b]))
                owners.append(b)
            elif b in shape_index:
                s = self.shapes[shape_index[b]]
                if s.kind == "box":
                    rot = not np.allclose(np.asarray(s.pose)[:3, :3], np.eye(3), rtol=0.0, atol=0.0)
                    kind = "box" if rot else "box_aa"
                else:
                    kind = {"cylinder": "cyl", "sphere": "sphere"}[s.kind]
                buckets.setdefault(kind, []).append((k, ia, shape_index[b]))
                owners.append(s.owner)
            else:
                raise ValueError(f"pair {k} {(a, b)}: {b!r} is neither a capsule nor a scene shape")
        self.owners = tuple(owners)
        self._groups: list[_Group] = []
        for kind, rows in buckets.items():
            cols = np.array([r[0] for r in rows])
            ia = np.array([r[1] for r in rows])
            ib = np.array([r[2] for r in rows])
            consts: dict[str, np.ndarray] = {}
            if kind in ("box", "box_aa", "cyl", "sphere"):
                poses = np.array([np.asarray(self.shapes[j].pose, dtype=_FLOAT) for j in ib])
                consts["R"] = poses[:, :3, :3].copy()
                consts["c"] = poses[:, :3, 3].copy()
                consts["r"] = self.radii[ia]
                if kind in ("box", "box_aa"):
                    consts["h"] = np.array([self.shapes[j].size for j in ib], dtype=_FLOAT) * 0.5
                elif kind == "cyl":
                    consts["R_cyl"] = np.array([self.shapes[j].size[0] for j in ib], dtype=_FLOAT)
                    consts["H"] = np.array([self.shapes[j].size[1] for j in ib], dtype=_FLOAT) * 0.5
                else:
                    consts["rad"] = np.array([self.shapes[j].size[0] for j in ib], dtype=_FLOAT)
            elif kind == "cap":
                consts["r"] = self.radii[ia] + self.radii[ib]
            elif kind in ("box@", "cyl@", "sphere@"):
                consts["r"] = self.radii[ia]
            self._groups.append(_Group(kind, cols, ia, ib, consts))

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
        carried_pose: Any = None,
        far_m: float | None = None,
    ) -> np.ndarray:
        """Signed distances ``(T, K)`` in m for capsule endpoints ``p0``, ``p1`` ``(T, C, 3)`` (base frame).

        ``carried_pose`` ``(T, 4, 4)`` is needed when a pair involves :data:`CARRIED`.
        ``far_m`` only affects carried-object/shape pairs that go through coal (box or
        cylinder against box or cylinder): see :func:`shape_shape`. Every other value
        is exact.
        """
        p0 = np.asarray(p0, dtype=_FLOAT)
        p1 = np.asarray(p1, dtype=_FLOAT)
        C = len(self.capsules)
        if p0.ndim != 3 or p0.shape[1:] != (C, 3) or p1.shape != p0.shape:
            raise ValueError(f"p0 and p1 must both be (T, {C}, 3) (one segment per capsule), got {p0.shape} and {p1.shape}")
        T = p0.shape[0]
        K = len(self.pairs)
        out = np.empty((T, K))
        if carried_pose is not None:
            carried_pose = np.asarray(carried_pose, dtype=_FLOAT)
            if carried_pose.shape != (T, 4, 4):
                raise ValueError(f"carried_pose must be (T, 4, 4) = ({T}, 4, 4), got {carried_pose.shape}")
        # structure of arrays: (3, T, C), contiguous per coordinate
        P0 = np.ascontiguousarray(p0.transpose(2, 0, 1))
        D = np.ascontiguousarray((p1 - p0).transpose(2, 0, 1))
        for g in self._groups:
            if g.kind == "carried":
                for col, j in zip(g.cols, g.ib):
                    if carried_pose is None:
                        raise ValueError("carried_pose is needed: the kernel has pairs with the carried object")
                    out[:, col] = shape_shape(self.carried, self.shapes[j], carried_pose, None, far_m=far_m)
                continue
            if g.kind.endswith("@") and carried_pose is None:
                raise ValueError("carried_pose is needed: the kernel has pairs with the carried object")
            Kg = len(g.cols)
            step = max(1, self.chunk // Kg)
            res = np.empty((T, Kg))
            for t0 in range(0, T, step):
                t1 = min(T, t0 + step)
                res[t0:t1] = self._eval(g, P0[:, t0:t1][:, :, g.ia], D[:, t0:t1][:, :, g.ia], P0[:, t0:t1], D[:, t0:t1], carried_pose[t0:t1] if carried_pose is not None else None)
            out[:, g.cols] = res
        return out

    def _eval(self, g: _Group, a: np.ndarray, d: np.ndarray, P0c: np.ndarray, Dc: np.ndarray, cpose: np.ndarray | None) -> np.ndarray:
        """One chunk of one group: ``a``, ``d`` are ``(3, n, Kg)`` segment starts and directions."""
        cs = g.consts
        kind = g.kind
        if kind == "cap":
            b = P0c[:, :, g.ib]
            e = Dc[:, :, g.ib]
            return np.sqrt(_seg_seg_sq(a[0], a[1], a[2], d[0], d[1], d[2], b[0], b[1], b[2], e[0], e[1], e[2])) - cs["r"]
        if kind == "sphere":
            c = cs["c"]
            return np.sqrt(_point_seg_sq(c[:, 0], c[:, 1], c[:, 2], a[0], a[1], a[2], d[0], d[1], d[2])) - cs["r"] - cs["rad"]
        if kind.endswith("@"):
            R = cpose[:, None, :3, :3]
            c = cpose[:, None, :3, 3]
            r = cs["r"]
            sh = self.carried
            if kind == "sphere@":
                return np.sqrt(_point_seg_sq(c[..., 0], c[..., 1], c[..., 2], a[0], a[1], a[2], d[0], d[1], d[2])) - r - sh.size[0]
        else:
            R = cs["R"]
            c = cs["c"]
            r = cs["r"]
        if kind == "box_aa":
            la = (a[0] - c[:, 0], a[1] - c[:, 1], a[2] - c[:, 2])
            ld = (d[0], d[1], d[2])
        else:
            la = _to_local(a[0], a[1], a[2], R, c)
            ld = _to_local(d[0], d[1], d[2], R, c, translate=False)
        if kind in ("box", "box_aa", "box@"):
            h = cs["h"] if kind != "box@" else 0.5 * np.asarray(self.carried.size, dtype=_FLOAT)[None, :]
            args = (*la, *ld, h[..., 0], h[..., 1], h[..., 2])
            return _signed_from_sq(_seg_box_sq(*args), _seg_box_depth, args, r)
        if kind in ("cyl", "cyl@"):
            if kind == "cyl":
                Rc, H = cs["R_cyl"], cs["H"]
            else:
                Rc, H = _FLOAT(self.carried.size[0]), _FLOAT(0.5 * self.carried.size[1])
            args = (*la, *ld, Rc, H)
            return _signed_from_sq(_seg_cyl_sq(*args), _seg_cyl_depth, args, r)
        raise AssertionError(kind)
