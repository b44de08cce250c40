"""Distance kernels in closed form, vectorised over samples: segment/segment, point/segment, capsule against
capsule, sphere, box and cylinder (signed: minus the penetration depth when they overlap), all lengths in metres.

The mathematics of each kernel is explained in :mod:`robocritics.geometry.proximity`; the flat kernels take
component arrays (broadcastable, float64) and loop over no sample in Python.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..scene import Shape

__all__ = [
    "segment_distance",
    "capsule_capsule",
    "capsule_sphere",
    "capsule_box",
    "capsule_cylinder",
    "capsule_shape",
    "point_shape",
    "sphere_shape",
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
