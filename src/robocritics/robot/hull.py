r"""Convex hull volume, area and vertices of a 3-D point set, without scipy.

``convex_hull(P)`` for ``P (N, 3)`` (m) returns the hull's volume (m^3), surface area (m^2) and the ascending
indices of the input points that are its vertices (the first of equal points).

Two implementations, one answer:

* coal's Qhull (``coal.ConvexBase.convexHull``; coal is loaded anyway for proximity), the fast path. It is
  fragile: on a flat input it crashes the process instead of raising, and it refuses a hull with a vertex of
  more than 255 neighbours ("Too many neighbors", a fan of thin triangles around a point).
* :func:`quickhull`, a plain incremental hull in numpy (Clarkson-Shor / Barber et al. with conflict lists):
  used when coal refuses, and the reference coal is tested against (with scipy's Qhull as a third).

Flat sets never reach either: if the smallest singular value of the centred points is below
:data:`FLAT_RATIO` times the largest (all points on one plane, line or point, to that relative precision), the
set has no volume and the result is ``(0, 0, [])``; such a set's true volume is below
``FLAT_RATIO * extent^3 * sqrt(N)``. This matches scipy's "initial simplex is flat" error, which callers
treated as volume 0. Non-finite coordinates give the same empty hull (scipy raised ``ValueError`` for them).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["Hull", "FLAT_RATIO", "convex_hull", "quickhull"]

FLAT_RATIO = 1e-5
"""Point sets whose centred points' smallest/largest singular value is below this are flat: volume 0. coal 3.0's
Qhull crashes on a set 1e-9 (relative) thick and copes at 1e-6; 1e-5 keeps a margin. A robot's swept hull is
centimetres thick in every direction (ratio above 1e-2)."""

_EPS = 1e-12
"""Relative distance tolerance of :func:`quickhull`: a point within ``_EPS * extent`` of a facet's plane is on it
(not outside), so coplanar points do not become vertices."""


class Hull(NamedTuple):
    volume_m3: float
    area_m2: float
    vertices: np.ndarray  # (V,) int64, ascending indices into the input points


def _empty() -> Hull:
    return Hull(0.0, 0.0, np.arange(0, dtype=np.int64))


def _is_flat(P: np.ndarray) -> bool:
    centred = P - P.mean(axis=0)
    sv2 = np.linalg.eigvalsh(centred.T @ centred)  # squared singular values, ascending
    return not sv2[-1] > 0 or sv2[0] < FLAT_RATIO**2 * sv2[-1]


def convex_hull(P: np.ndarray) -> Hull:
    """Volume (m^3), area (m^2) and vertex indices of ``conv(P)``, ``P (N, 3)`` in m; flat or tiny sets: empty."""
    P = np.ascontiguousarray(P, dtype=float).reshape(-1, 3)
    if len(P) < 4 or not np.isfinite(P).all() or _is_flat(P):
        return _empty()
    import coal  # noqa: PLC0415 - the proximity model loads it; kept out of this module's import

    points = coal.StdVec_Vec3s()
    points.extend(P)
    try:
        hull = coal.ConvexBase.convexHull(points, True, None)  # keepTriangles: a coal.Convex of outward triangles
    except RuntimeError:  # "Too many neighbors": a vertex with more than 255 hull neighbours
        return quickhull(P)
    V = np.array(hull.points(), dtype=float)
    tri = np.array([(t[0], t[1], t[2]) for t in map(hull.polygons, range(hull.num_polygons))], dtype=np.int64)
    a, b, c = V[tri[:, 0]], V[tri[:, 1]], V[tri[:, 2]]
    area = 0.5 * float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())
    # coal's hull points are bit-exact copies of input points: find candidates by x, confirm the whole row, keep
    # the first of equal points; the candidates are about as few as the vertices
    hull_rows = set(map(tuple, V.tolist()))
    vertices, seen = [], set()
    for i in np.flatnonzero(np.isin(P[:, 0], V[:, 0])).tolist():
        key = tuple(P[i].tolist())
        if key in hull_rows and key not in seen:
            seen.add(key)
            vertices.append(i)
    return Hull(float(hull.computeVolume()), area, np.array(vertices, dtype=np.int64))


def quickhull(P: np.ndarray) -> Hull:
    """The hull by incremental construction with conflict lists, in numpy (the reference; slower than coal).

    Start from a tetrahedron of extreme points; every point outside some facet (signed distance above
    ``_EPS * extent``) is assigned to the facet it is farthest outside. Repeatedly take a facet's farthest
    point ``p``, delete the facets ``p`` sees, join ``p`` to the horizon (edges of deleted facets whose twin
    was kept) and reassign the deleted facets' points to the new facets. Volume
    ``sum_f det(a_f - o, b_f - o, c_f - o) / 6`` for an interior point ``o``, area ``sum_f |(b-a) x (c-a)| / 2``.
    """
    P = np.ascontiguousarray(P, dtype=float).reshape(-1, 3)
    if len(P) < 4 or not np.isfinite(P).all() or _is_flat(P):
        return _empty()
    extent = float(np.max(P.max(axis=0) - P.min(axis=0)))
    eps = _EPS * max(extent, float(np.abs(P).max()))

    # --- initial tetrahedron: extreme in x, farthest from it, from their line, from their plane
    i0 = int(np.argmin(P[:, 0]))
    i1 = int(np.argmax(np.einsum("ij,ij->i", P - P[i0], P - P[i0])))
    u = P[i1] - P[i0]
    cr = np.cross(P - P[i0], u)
    i2 = int(np.argmax(np.einsum("ij,ij->i", cr, cr)))
    n = np.cross(P[i1] - P[i0], P[i2] - P[i0])
    h = (P - P[i0]) @ n
    i3 = int(np.argmax(np.abs(h)))
    if abs(h[i3]) <= eps * np.linalg.norm(n):
        return _empty()
    inside = P[[i0, i1, i2, i3]].mean(axis=0)

    facets: list[tuple[int, int, int]] = []
    for f in ((i0, i1, i2), (i0, i1, i3), (i0, i2, i3), (i1, i2, i3)):
        a, b, c = P[list(f)]
        if np.dot(np.cross(b - a, c - a), inside - a) > 0:  # orient outward (normal away from the interior)
            f = (f[0], f[2], f[1])
        facets.append(f)

    cap = 64
    F = np.zeros((cap, 3), dtype=np.int64)  # every facet made so far; alive marks the current ones
    normals = np.zeros((cap, 3))
    offsets = np.zeros(cap)
    alive = np.zeros(cap, dtype=bool)
    edge_facet: dict[tuple[int, int], int] = {}  # directed edge (a, b) of a live facet -> that facet
    count = 0

    def add(new: np.ndarray) -> np.ndarray:
        """Append facets ``new (m, 3)`` (outward order); returns their ids."""
        nonlocal F, normals, offsets, alive, count, cap
        m = len(new)
        while count + m > cap:
            cap *= 2
            F, normals, offsets, alive = (np.resize(x, (cap,) + x.shape[1:]) for x in (F, normals, offsets, alive))
            alive[count:] = False
        ids = np.arange(count, count + m)
        a, b, c = P[new[:, 0]], P[new[:, 1]], P[new[:, 2]]
        nrm = np.cross(b - a, c - a)
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
        F[ids], normals[ids], offsets[ids], alive[ids] = new, nrm, np.einsum("ij,ij->i", nrm, a), True
        for fid, (u, v, w) in zip(ids.tolist(), new.tolist()):
            edge_facet[(u, v)] = edge_facet[(v, w)] = edge_facet[(w, u)] = fid
        count += m
        return ids

    def assign(idx: np.ndarray, cand: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Points ``idx`` against candidate facets ``cand``: (outside points, their facet, their distance)."""
        d = P[idx] @ normals[cand].T - offsets[cand]
        best = np.argmax(d, axis=1)
        dist = d[np.arange(len(idx)), best]
        out = dist > eps
        return idx[out], cand[best[out]], dist[out]

    pts, owner, dist = assign(np.arange(len(P)), add(np.array(facets, dtype=np.int64)))
    while len(pts):
        k = int(np.argmax(dist))  # the farthest outside point of all: keeps the hull well shaped
        p = int(pts[k])
        height = P[p] @ normals[:count].T - offsets[:count]  # signed distance of p to every facet made so far
        # visible region: facets p sees, grown from p's own facet across shared edges (connected, so its
        # boundary, the horizon, is one loop even when rounding makes a far facet look visible)
        start = int(owner[k])
        visible, stack, horizon = {start}, [start], []
        while stack:
            f = stack.pop()
            u, v, w = F[f].tolist()
            for a, b in ((u, v), (v, w), (w, u)):
                g = edge_facet[(b, a)]
                if g in visible:
                    continue
                if height[g] > eps:
                    visible.add(g)
                    stack.append(g)
                else:
                    horizon.append((a, b))
        vis = np.fromiter(visible, dtype=np.int64, count=len(visible))
        for f in vis.tolist():
            u, v, w = F[f].tolist()
            for e in ((u, v), (v, w), (w, u)):
                del edge_facet[e]
        alive[vis] = False
        ids = add(np.array([(a, b, p) for a, b in horizon], dtype=np.int64))
        was_visible = np.zeros(count, dtype=bool)
        was_visible[vis] = True
        orphan = was_visible[owner]
        keep = ~orphan
        orphan[k] = keep[k] = False  # p is now a vertex
        new_pts, new_owner, new_dist = assign(pts[orphan], ids)
        pts = np.concatenate([pts[keep], new_pts])
        owner = np.concatenate([owner[keep], new_owner])
        dist = np.concatenate([dist[keep], new_dist])

    F = F[:count]
    alive = alive[:count]
    Fa = F[alive]
    a, b, c = P[Fa[:, 0]], P[Fa[:, 1]], P[Fa[:, 2]]
    cr = np.cross(b - a, c - a)
    volume = float(np.einsum("ij,ij->i", cr, a - inside).sum()) / 6.0
    area = 0.5 * float(np.linalg.norm(cr, axis=1).sum())
    # the first of equal points: a vertex's index may be a later duplicate of an earlier point
    verts = np.unique(Fa)
    _, first_of = np.unique(P, axis=0, return_index=True)
    key = {tuple(P[i].tolist()): int(i) for i in first_of}
    vertices = np.unique([key[tuple(P[i].tolist())] for i in verts.tolist()]).astype(np.int64)
    return Hull(volume, area, vertices)
