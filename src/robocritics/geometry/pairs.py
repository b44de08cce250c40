"""Shape against shape (an object the gripper carries against the others): closed-form bounds that settle most
placements, coal (GJK/EPA) for the rest, once per run of samples in which neither pose changes. Metres.

See :mod:`robocritics.geometry.proximity` for the method and its accuracy.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..scene import Shape
__all__ = ["shape_shape", "closest_points", "capsule_pose", "coal_geometry"]

from .kernels import _FLOAT, _point_box, _point_cyl, _pose_parts, sphere_shape


# ----------------------------------------------------------------------------------------------
# shape-shape (carried object against the scene)
# ----------------------------------------------------------------------------------------------


def coal_geometry(kind: str, size: Sequence[float]):
    """coal's primitive of a scene shape ``kind`` of ``size`` (as :class:`~robocritics.scene.Shape`), or a capsule;
    for ``mesh``, ``size`` is the shape's ``(vertices (V, 3), triangles (F, 3))`` and the result a BVH of them."""
    import coal

    if kind == "mesh":
        vertices, triangles = size
        model = coal.BVHModelOBBRSS()
        model.beginModel(len(triangles), len(vertices))
        model.addVertices(np.ascontiguousarray(vertices, dtype=float))
        model.addTriangles(np.ascontiguousarray(triangles, dtype=np.int64))
        model.endModel()
        return model

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

    ga, gb = coal_geometry(a.kind, a.size), coal_geometry(b.kind, b.size)
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


def closest_points(a_kind: str, a_size, a_pose, b_kind: str, b_size, b_pose) -> tuple[np.ndarray, np.ndarray, float]:
    """Closest points (m, base frame) between two shapes and their distance [m], with coal.

    Kinds: ``"capsule"`` (size ``(radius, length)``, axis z of its pose), ``"box"``
    (extents), ``"cylinder"`` (radius, height), ``"sphere"`` (radius), ``"mesh"`` (size: its
    ``(vertices, triangles)``, :func:`coal_geometry`). Poses are 4x4.
    The distance is negative on penetration (coal's signed distance); the points
    are then the witness points of the penetration.
    """
    import coal

    def transform(pose):
        pose = np.asarray(pose, float)
        return coal.Transform3s(pose[:3, :3].copy(), pose[:3, 3].copy())

    request, result = coal.DistanceRequest(), coal.DistanceResult()
    request.enable_signed_distance = True
    distance = coal.distance(coal_geometry(a_kind, a_size), transform(a_pose), coal_geometry(b_kind, b_size), transform(b_pose),
                             request, result)  # fmt: skip
    return np.array(result.getNearestPoint1()), np.array(result.getNearestPoint2()), float(distance)


def capsule_pose(p0: np.ndarray, p1: np.ndarray) -> tuple[np.ndarray, float]:
    """A pose whose z axis runs along ``p0 -> p1``, centred between them, and the segment length [m]."""
    axis = p1 - p0
    length = float(np.linalg.norm(axis))
    z = axis / length if length > 1e-12 else np.array([0.0, 0.0, 1.0])
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    pose = np.eye(4)
    pose[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    pose[:3, 3] = (p0 + p1) / 2
    return pose, length
