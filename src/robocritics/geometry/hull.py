r"""Convex hull volume, area and vertices of a 3-D point set.

``convex_hull(P)`` for ``P (N, 3)`` (m) returns the hull's volume (m^3), surface area (m^2) and the ascending
indices of the input points that are its vertices (the first of equal points; on the coal path, of points equal
after the snapping below).

Two implementations, one answer:

* coal's Qhull (``coal.ConvexBase.convexHull``, reached through ``BVHModel.buildConvexHull``; coal is loaded
  anyway for proximity), the fast path. It is fragile: this build's Qhull writes every message (an error such as
  "initial simplex is flat", a precision warning such as "point above twisted facet", the output of an option such
  as ``Tv``) through a ``FILE *`` it never opened, so any message kills the process with a segfault instead of
  raising; and coal refuses a hull with a vertex of more than 254 neighbours ("Too many neighbors", a fan of thin
  triangles around a point, as a robot turning its base sweeps), after building it and without freeing it: about
  0.5 MB lost per refusal of a 3000-point fan (benchmarks/bench_hull.py's sweep is refused even decimated).
* :func:`quickhull`, a plain incremental hull in numpy (Clarkson-Shor / Barber et al. with conflict lists):
  used for every set coal might crash on or refuses, and the reference coal is tested against (with scipy's
  Qhull as a third).

Both see the points *normalised*: ``Q = (P 2^-a - m) 2^-b`` with ``m`` the bounding-box centre of the scaled
points and powers of two ``2^a``, ``2^b`` chosen so that ``|P 2^-a| < 1`` and ``|Q| < 1``. Scaling by a power
of two is exact, and for a set far from the origin (``|P| >> extent``) so is the subtraction (Sterbenz), so
``Q`` is the input moved and scaled, not rounded: a 1 mm motion 1000 km from the origin is measured as well as
one at the origin (Qhull on the raw coordinates loses the digits to the offset, gives volumes off by orders of
magnitude or negative, and crashes). The volume is ``vol(Q) 2^{3(a+b)}``, the area ``area(Q) 2^{2(a+b)}``.

What keeps Qhull quiet (so coal alive), each found by a crash:

* thin sets never reach it: if the smallest singular value of the mean-centred ``Q`` is at most
  :data:`FLAT_RATIO` times the largest, quickhull measures the set (a straight-line tool path, 0.5 mm^3, is not
  rounded to 0);
* coal sees ``Q`` snapped to multiples of ``2^-40`` (:data:`_GRID_EXP`), so distinct points are at least that
  far apart: clusters of points 1e-13 apart made Qhull merge facets into twisted ones and warn;
* options ``Pp`` (no precision warnings) and ``Q12`` (no error on a wide merge).

Volume and area are measured from the triangles as signed sums, the triangles of a face oriented as one
surface (:func:`_orient_merged`, :func:`_face_normals`): both Qhull's fan over a merged face and quickhull's cone
over coplanar facets can fold triangles back over each other.

Accuracy: coal's result is Qhull's to ~1e-12 relative (the snapping); quickhull leaves out points within
``_EPS`` of the extent (or a sliver's plane rounding) of a facet, so its volume is short by at most about
``4 _EPS extent area + 1e-12 extent^3``, and reports volume 0 when no point is more than ``_EPS`` off the plane
of its initial triangle: sets flat to rounding (three points, all points on one plane or line, one point
repeated) give ``(0, 0, [])``. Non-finite coordinates give the same empty hull (scipy raised ``ValueError``);
coordinates near 1e300 m give an infinite volume. tests/test_hull_attacks.py holds the hostile sets.
"""

from __future__ import annotations

import heapq
from typing import NamedTuple

import numpy as np

from .._arrays import equal_row_groups, first_of_equal_rows

__all__ = ["Hull", "FLAT_RATIO", "convex_hull", "hull_triangles", "quickhull"]

FLAT_RATIO = 1e-5
"""Sets whose mean-centred normalised points have smallest/largest singular value at most this are thin: they go
to :func:`quickhull`, never to coal. coal 3.0's Qhull crashes on a set 1e-9 (relative) thick and copes at 1e-6;
1e-5 keeps a margin. A robot's swept hull of all its frames is centimetres thick in every direction (ratio above
1e-2); a single frame moving along a line is thin."""

_EPS = 1e-12
"""Distance tolerance of :func:`quickhull` in normalised coordinates (``|Q| < 1``, so relative to the set's
extent): a point within ``_EPS`` of a facet's plane is on it (not outside), so coplanar points do not become
vertices, and a set within ``_EPS`` of a plane has no volume. Rounding in a facet's plane is ~1e-16."""

_U = 2.0**-53
"""Unit roundoff of float64."""

_GRID_EXP = -40
"""coal sees the normalised points rounded to multiples of 2^-40 (9.1e-13, about _EPS)."""

_QHULL_OPTIONS = "Qt Pp Q12"
"""Qt: triangulated output (coal needs triangles). Pp: do not print precision warnings (every print crashes).
Q12: do not stop with an error on a wide merge (nearly coincident points)."""


class Hull(NamedTuple):
    volume_m3: float
    area_m2: float
    vertices: np.ndarray  # (V,) int64, ascending indices into the input points


def _empty() -> Hull:
    return Hull(0.0, 0.0, np.arange(0, dtype=np.int64))


def _points(P: np.ndarray) -> np.ndarray:
    """``P (..., 3)`` as a contiguous ``(N, 3)`` float array; ValueError naming the shape otherwise."""
    P = np.asarray(P, dtype=float)
    if P.ndim == 0 or P.shape[-1] != 3:
        raise ValueError(f"hull points must have shape (N, 3) (m), got shape {P.shape}")
    return np.ascontiguousarray(P.reshape(-1, 3))


def _times_pow2(x, k: int):
    """``x 2^k``, exactly as ``np.ldexp(x, k)`` (one rounding, only where the result is subnormal): a multiply by
    the float ``2.0**k`` where that is a normal number, else ``np.ldexp`` (an order of magnitude slower on an
    array with a scalar exponent)."""
    return x * 2.0**k if -1022 <= k <= 1023 else np.ldexp(x, k)


def _normalised(P: np.ndarray) -> tuple[np.ndarray, int] | None:
    """``(Q, e)`` with ``Q = (P - c) 2^-e`` for a centre ``c`` and ``|Q| < 1`` (see the module docstring); None if
    there are fewer than 4 points, a non-finite coordinate, or all points are equal."""
    if len(P) < 4 or not np.isfinite(P).all():
        return None
    # per-coordinate extremes from a (3, N) copy: a reduction along axis 0 of an (N, 3) array runs 3-wide
    # and costs 30x more. Scaling by a power of two and subtracting a constant round monotonically, so the
    # extremes of S and C below are the scaled and shifted extremes of P, bit for bit.
    Pt = np.ascontiguousarray(P.T)
    lo, hi = Pt.min(axis=1), Pt.max(axis=1)
    a = int(np.frexp(max(-lo.min(), hi.max()))[1])  # 2^(a-1) <= max|P| < 2^a
    S = _times_pow2(P, -a)  # exact: scaling by a power of two; |S| < 1, so the centring below cannot overflow
    lo, hi = _times_pow2(lo, -a), _times_pow2(hi, -a)
    m = lo + (hi - lo) / 2  # bounding-box centre, computed without overflow
    C = S - m
    top = float(max(np.abs(lo - m).max(), np.abs(hi - m).max()))  # max |C|
    if top == 0.0:
        return None
    b = int(np.frexp(top)[1])
    return _times_pow2(C, -b), a + b


def _thin(Q: np.ndarray) -> bool:
    """Whether the smallest singular value of the mean-centred ``Q`` is at most :data:`FLAT_RATIO` times the
    largest: from the eigenvalues ``s_i^2`` of its 3x3 Gram matrix (a tenth of the SVD of the ``(3, N)`` array).
    Their rounding is ~1e-16 of ``s_0^2``, a millionth of the ``FLAT_RATIO^2 s_0^2`` compared against."""
    Qt = np.ascontiguousarray(Q.T)  # (3, N): the mean along contiguous rows is 10x faster than along axis 0
    C = Qt - Qt.mean(axis=1, keepdims=True)
    lam = np.linalg.eigvalsh(C @ C.T)  # ascending; Q is O(1)
    return not lam[0] > FLAT_RATIO**2 * lam[2]


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``u x v`` of ``(N, 3)`` arrays, written out as ``np.cross`` computes it (``u1 v2 - u2 v1``, ..., bit for bit)
    without its axis handling, which costs more than the products for a hull's few hundred triangles."""
    out = np.empty(np.broadcast_shapes(u.shape, v.shape))
    out[:, 0] = u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1]
    out[:, 1] = u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2]
    out[:, 2] = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    return out


def _measure(V: np.ndarray, tri: np.ndarray, normals: np.ndarray) -> tuple[float, float]:
    """Volume and area of the closed, consistently oriented triangle mesh ``V[tri]`` of a convex body whose
    triangle ``f`` lies in a face with outward unit normal ``normals[f]``.

    Volume ``sum_f det(a_f - o, b_f - o, c_f - o) / 6`` for ``o`` the mean of the vertices, area
    ``sum_f n_f . ((b_f - a_f) x (c_f - a_f)) / 2``: both signed, so a triangle that folds back over its face
    (a fan over a merged face whose vertices are not in convex position) cancels what it covers twice.
    """
    o = V.mean(axis=0)
    a, b, c = V[tri[:, 0]] - o, V[tri[:, 1]] - o, V[tri[:, 2]] - o
    volume = float(np.einsum("ij,ij->i", _cross(b, c), a).sum()) / 6.0
    area = 0.5 * float(np.einsum("ij,ij->i", _cross(b - a, c - a), normals).sum())
    return volume, area


def _orient_merged(V: np.ndarray, tri: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """coal's triangles, oriented as one surface.

    coal turns each triangle to face away from the hull's centre, one by one. That is right for a hull facet,
    but Qhull merges nearly coplanar facets and (option Qt) triangulates the merged face as a fan, whose
    triangles may fold back over each other; turned one by one they all count positively and the volume and
    area come out too large (4e-4 relative on jittered box faces). The triangles of a merged face share its
    hyperplane bit for bit: within each such group, orient the triangles consistently across shared edges
    (an edge is walked in opposite directions by its two triangles) and then the whole group so its signed
    area along the face's normal is positive.
    """
    group, counts = equal_row_groups(normals)
    merged = np.flatnonzero(counts[group] > 1)
    if merged.size == 0:
        return tri
    tri = tri.copy()
    by_edge: dict[tuple[int, int], list[int]] = {}  # undirected edge -> merged triangles of the same group
    for f in merged.tolist():
        u, v, w = tri[f].tolist()
        for a, b in ((u, v), (v, w), (w, u)):
            by_edge.setdefault((min(a, b), max(a, b), group[f]), []).append(f)
    done = np.zeros(len(tri), dtype=bool)
    for seed in merged.tolist():
        if done[seed]:
            continue
        done[seed] = True
        component, stack = [seed], [seed]
        while stack:
            f = stack.pop()
            u, v, w = tri[f].tolist()
            for a, b in ((u, v), (v, w), (w, u)):
                for g in by_edge[(min(a, b), max(a, b), group[f])]:
                    if done[g]:
                        continue
                    x, y, z = tri[g].tolist()
                    if (a, b) in ((x, y), (y, z), (z, x)):  # walks the edge the same way: turn it over
                        tri[g] = (x, z, y)
                    done[g] = True
                    component.append(g)
                    stack.append(g)
        idx = np.array(component)
        a, b, c = V[tri[idx, 0]], V[tri[idx, 1]], V[tri[idx, 2]]
        if np.einsum("ij,ij->i", _cross(b - a, c - a), normals[idx]).sum() < 0:
            tri[idx] = tri[idx][:, [0, 2, 1]]
    return tri


def _hull(Q: np.ndarray, e: int, V: np.ndarray, tri: np.ndarray, normals: np.ndarray) -> Hull:
    """The hull of ``Q 2^e`` from its triangles ``V[tri]`` (``V``: rows of ``Q``, the vertices; see _measure)."""
    volume, area = _measure(V, tri, normals)
    return Hull(float(np.ldexp(volume, 3 * e)), float(np.ldexp(area, 2 * e)), first_of_equal_rows(Q, V))


def convex_hull(P: np.ndarray) -> Hull:
    """Volume (m^3), area (m^2) and vertex indices of ``conv(P)``, ``P (N, 3)`` in m; flat or tiny sets: empty."""
    P = _points(P)
    norm = _normalised(P)
    if norm is None:
        return _empty()
    Q, e = norm
    mesh = _coal_triangles(Q)
    if mesh is None:
        return _quickhull(Q, e)
    S, V, tri, normals = mesh
    return _hull(S, e, V, _orient_merged(V, tri, normals), normals)


def hull_triangles(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``conv(P)`` of ``P (N, 3)`` (m) as a closed triangle mesh: the indices ``(V,)`` into ``P`` of its vertices
    (the first of equal points) and its triangles ``(F, 3)`` indexing those (not oriented; coplanar facets
    triangulated, possibly folded over each other). Flat or tiny sets: two empty arrays. The same hull as
    :func:`convex_hull` (coal's Qhull where it is safe, else :func:`quickhull`)."""
    P = _points(P)
    norm = _normalised(P)
    empty = (np.zeros(0, dtype=np.int64), np.zeros((0, 3), dtype=np.int64))
    if norm is None:
        return empty
    Q, e = norm
    mesh = _coal_triangles(Q)
    if mesh is None:
        mesh = _quickhull_triangles(Q)
        if mesh is None:
            return empty
        S, (V, tri) = Q, mesh
    else:
        S, V, tri, _ = mesh
    first: dict[tuple, int] = {}
    for i, row in enumerate(map(tuple, S.tolist())):
        first.setdefault(row, i)
    return np.array([first[tuple(v)] for v in V.tolist()], dtype=np.int64), tri


def _coal_triangles(Q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """coal's Qhull on the normalised points ``Q``: ``(S, V, tri, normals)``, ``S`` the points snapped as Qhull
    saw them, ``V`` its vertices (rows of ``S``), ``tri`` its triangles and their outward unit normals; None where
    Qhull might crash (a thin set) or refuses the hull (the module docstring)."""
    if _thin(Q):  # coal's Qhull may crash the process on it
        return None
    import coal  # noqa: PLC0415 - the proximity model loads it; kept out of this module's import

    # nearly coincident points (1e-15 apart) make Qhull merge facets into twisted ones and print a precision
    # warning (a crash): snap to a grid of _GRID, so distinct points are at least _GRID apart; this moves a
    # point by at most _GRID / 2, as little as quickhull's tolerance leaves out
    S = np.rint(Q * 2.0**-_GRID_EXP) * 2.0**_GRID_EXP  # exact scalings (|Q| < 1); rint: half to even, as round
    # the points reach Qhull through a BVH model: addVertices converts the (N, 3) array in one call, where a
    # StdVec_Vec3s converts row by row (0.7 ms for 4000 points); convexHull sees the same vector of points
    model = coal.BVHModelOBBRSS()
    model.beginModel(0, len(S))
    model.addVertices(S)
    try:
        model.buildConvexHull(True, _QHULL_OPTIONS)  # a coal.Convex of triangles, in model.convex
    except RuntimeError:  # "Too many neighbors": a vertex with more than 254 hull neighbours
        return None
    hull = model.convex
    V = np.array(hull.points(), dtype=float)  # the vertices: bit-exact copies of rows of S
    tri = np.array([(t[0], t[1], t[2]) for t in map(hull.polygons, range(hull.num_polygons))], dtype=np.int64)
    normals = np.array(hull.normals(), dtype=float).reshape(-1, 3)  # Qhull's outward unit normal of each triangle
    return S, V, tri, normals


def quickhull(P: np.ndarray) -> Hull:
    """The hull by incremental construction with conflict lists, in numpy (the reference; slower than coal).

    On the normalised points ``Q`` (module docstring): start from a tetrahedron of extreme points; every point
    outside some facet (signed distance above ``_EPS``) is in the conflict list of the facet it is farthest
    outside. Repeatedly take the point farthest outside its facet, over all facets, ``p``; delete the facets
    ``p`` sees (grown from its own facet across shared edges); join ``p`` to the horizon (edges of deleted
    facets whose twin was kept) and share the deleted facets' conflict points among the new facets. Each step
    costs the points it moves, not all points. Volume and area: :func:`_measure`.
    """
    P = _points(P)
    norm = _normalised(P)
    if norm is None:
        return _empty()
    return _quickhull(*norm)


def _initial_tetrahedron(Q: np.ndarray, eps: float) -> list[tuple[int, int, int]] | None:
    """The outward facets of the first tetrahedron of the points ``Q``, or None when they are all within ``eps``
    of a line or a plane."""
    # --- initial tetrahedron: extreme in x, farthest from it, from their line, from their plane
    i0 = int(np.argmin(Q[:, 0]))
    d = Q - Q[i0]
    i1 = int(np.argmax(np.einsum("ij,ij->i", d, d)))
    u = Q[i1] - Q[i0]
    cr = np.cross(d, u)
    cr2 = np.einsum("ij,ij->i", cr, cr)
    i2 = int(np.argmax(cr2))
    if not np.sqrt(cr2[i2]) > eps * np.linalg.norm(u):  # all points within eps of a line (|Q| < 1, so |u| <= 2)
        return None
    n = np.cross(u, d[i2])  # its direction is good to ~1e-16 / eps: the triangle is more than eps wide
    h = d @ (n / np.linalg.norm(n))
    i3 = int(np.argmax(np.abs(h)))
    if abs(h[i3]) <= eps:  # all points within eps of a plane
        return None
    if h[i3] < 0:  # make (i0, i1, i2, i3) positively oriented: i3 on the side of (i1 - i0) x (i2 - i0)
        i1, i2 = i2, i1
    # outward faces of a positive tetrahedron, consistent by construction (each edge walked both ways); the
    # only geometric decision is the sign of h[i3], which is more than eps from 0
    return [(i0, i2, i1), (i0, i1, i3), (i1, i2, i3), (i0, i3, i2)]


def _visible_region(start: int, point, F, edge_facet, normals, offsets, tols) -> tuple[set[int], list[tuple[int, int]]]:
    """The facets ``point`` sees, grown from facet ``start`` across shared edges, and the directed edges of the
    region's boundary (the horizon)."""
    px, py, pz = point
    visible, stack, horizon = {start}, [start], []
    while stack:
        f = stack.pop()
        u, v, w = F[f]
        for a, b in ((u, v), (v, w), (w, u)):
            g = edge_facet[(b, a)]
            if g in visible:
                continue
            nx, ny, nz = normals[g]
            if px * nx + py * ny + pz * nz - offsets[g] > tols[g]:
                visible.add(g)
                stack.append(g)
            else:
                horizon.append((a, b))
    return visible, horizon


def _quickhull(Q: np.ndarray, e: int) -> Hull:
    mesh = _quickhull_triangles(Q)
    if mesh is None:  # all points within eps of a line or a plane
        return _empty()
    V, tri = mesh
    return _hull(Q, e, V, tri, _face_normals(V, tri))


def _quickhull_triangles(Q: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`quickhull`'s vertices (rows of ``Q``) and outward triangles of the normalised points ``Q``; None
    for a set within ``_EPS`` of a line or a plane."""
    eps = _EPS
    facets = _initial_tetrahedron(Q, eps)
    if facets is None:
        return None

    F: list[tuple[int, int, int]] = []  # every facet made so far; dead ones stay (ids are list positions)
    normals: list[list[float]] = []  # unit outward normals
    offsets: list[float] = []
    tols: list[float] = []  # a facet's distance tolerance: eps, or its plane's rounding error if larger
    alive: list[bool] = []
    edge_facet: dict[tuple[int, int], int] = {}  # directed edge (a, b) of a live facet -> that facet
    conflict: dict[int, np.ndarray] = {}  # live facet -> the points farthest outside it (point indices)
    heap: list[tuple[float, int, int]] = []  # (-distance, facet, point): the farthest point of each conflict list

    def add(new: list[tuple[int, int, int]], pts: np.ndarray) -> None:
        """Append facets ``new`` (outward order) and share ``pts`` among them (each to the facet it is farthest
        outside, if more than that facet's tolerance)."""
        ids = list(range(len(F), len(F) + len(new)))
        T = Q[np.array(new, dtype=np.int64)]  # (m, 3 corners, 3)
        e1, e2 = T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]
        nrm = np.empty_like(e1)  # e1 x e2, written out: np.cross costs more than the rest for a few facets
        nrm[:, 0] = e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1]
        nrm[:, 1] = e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2]
        nrm[:, 2] = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        length = np.sqrt((nrm * nrm).sum(axis=1))
        positive = length > 0
        nrm[positive] /= length[positive, None]
        nrm[~positive] = 0.0  # a zero-area facet sees nothing
        off = (nrm * T[:, 0]).sum(axis=1)
        # the cross product's rounding error is ~3u |e1||e2|, so the unit normal's is that over |e1 x e2| and a
        # distance (|Q| < 1: lever arm <= 2) is off by ~8u |e1||e2| / |e1 x e2|: large for a sliver, whose
        # plane then decides nothing; the volume this can miss is ~tol * area = 4u |e1||e2| per facet
        spread = np.sqrt((e1 * e1).sum(axis=1) * (e2 * e2).sum(axis=1))
        tol = np.full(len(new), np.inf)
        tol[positive] = np.maximum(eps, 8 * _U * spread[positive] / length[positive])
        for fid, f, m, o, t in zip(ids, new, nrm.tolist(), off.tolist(), tol.tolist()):
            F.append(f)
            normals.append(m)
            offsets.append(o)
            tols.append(t)
            alive.append(True)
            u, v, w = f
            edge_facet[(u, v)] = edge_facet[(v, w)] = edge_facet[(w, u)] = fid
        if len(pts) == 0:
            return
        dist = Q[pts] @ nrm.T - (off + tol)  # beyond the tolerance
        best = np.argmax(dist, axis=1)
        bd = dist[np.arange(len(pts)), best]
        out = bd > 0
        if not out.any():
            return
        pts, best, bd = pts[out], best[out], bd[out]
        order = np.argsort(best, kind="stable")
        pts, best, bd = pts[order], best[order], bd[order]
        bounds = [0, *(np.flatnonzero(best[1:] != best[:-1]) + 1).tolist(), len(pts)]
        for lo, hi in zip(bounds[:-1], bounds[1:]):
            fid = ids[int(best[lo])]
            group = pts[lo:hi]
            conflict[fid] = group
            k = int(np.argmax(bd[lo:hi]))
            heapq.heappush(heap, (-float(bd[lo + k]), fid, int(group[k])))

    add(facets, np.arange(len(Q)))
    while heap:
        _, start, p = heapq.heappop(heap)
        if not alive[start]:
            continue
        px, py, pz = Q[p].tolist()
        # visible region: facets p sees, grown from p's own facet across shared edges (connected, so its
        # boundary, the horizon, is one loop even when rounding makes a far facet look visible). Coning p to
        # the edge of a coplanar facet may fold the new triangle over it: _face_normals measures such faces.
        # (Counting facets p is within eps of as seen instead deletes and re-cones faces of a grid: +2.5 %)
        visible, horizon = _visible_region(start, (px, py, pz), F, edge_facet, normals, offsets, tols)
        if not _one_loop(horizon):
            horizon = _mend(visible, horizon, F, edge_facet)
        if not horizon:  # no consistent cone from p: leave p out (it is within rounding of the hull)
            rest = conflict.pop(start)
            rest = rest[rest != p]
            if len(rest):
                conflict[start] = rest
                dr = Q[rest] @ np.array(normals[start]) - offsets[start] - tols[start]
                k = int(np.argmax(dr))
                heapq.heappush(heap, (-float(dr[k]), start, int(rest[k])))
            continue
        orphans = [conflict.pop(f) for f in visible if f in conflict]
        for f in visible:
            alive[f] = False
            u, v, w = F[f]
            del edge_facet[(u, v)], edge_facet[(v, w)], edge_facet[(w, u)]
        pts = np.concatenate(orphans) if orphans else np.arange(0, dtype=np.int64)
        add([(a, b, p) for a, b in horizon], pts[pts != p])

    live = [i for i, x in enumerate(alive) if x]
    used, tri = np.unique(np.array([F[i] for i in live], dtype=np.int64), return_inverse=True)
    return Q[used], tri.reshape(-1, 3)


def _one_loop(horizon: list[tuple[int, int]]) -> bool:
    """Whether the directed edges ``horizon`` form one simple cycle (each vertex once)."""
    nxt = dict(horizon)
    if not horizon or len(nxt) != len(horizon):
        return False
    first = x = horizon[0][0]
    for i in range(len(horizon)):
        x = nxt.get(x)
        if x is None or (x == first) != (i == len(horizon) - 1):
            return False
    return True


def _mend(visible: set[int], horizon: list[tuple[int, int]], F: list, edge_facet: dict) -> list[tuple[int, int]]:
    """A horizon that is one simple loop, by adding facets to ``visible`` (in place); [] if none is found.

    With exact arithmetic the facets a point sees form a disk. With the eps test, facets nearly coplanar with
    the point may be seen or not in a pattern that pinches the region at a vertex (the vertex is twice on the
    horizon) or leaves an unseen island in it (two loops); coning either to the point would make a surface
    that is not a sphere. Those facets are within rounding of being seen: add the unseen facets across the
    horizon edges at the offending vertices (for two loops, the vertices of all but the longest loop) and
    look again, a few times.
    """
    for _ in range(8):
        nxt: dict[int, list[int]] = {}
        for a, b in horizon:
            nxt.setdefault(a, []).append(b)
        bad = {a for a, bs in nxt.items() if len(bs) > 1}
        if not bad:  # loops without pinches: keep the longest
            loops, seen = [], set()
            for a, _b in horizon:
                if a in seen:
                    continue
                loop, x = [], a
                while x not in seen:
                    seen.add(x)
                    loop.append(x)
                    x = nxt[x][0]
                loops.append(loop)
            loops.sort(key=len)
            bad = {x for loop in loops[:-1] for x in loop}
        visible.update(edge_facet[(b, a)] for a, b in horizon if a in bad or b in bad)
        horizon = [
            (a, b) for f in visible for a, b in ((F[f][0], F[f][1]), (F[f][1], F[f][2]), (F[f][2], F[f][0]))
            if edge_facet[(b, a)] not in visible
        ]
        if _one_loop(horizon):
            return horizon
    return []


def _face_normals(V: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """The outward unit normal of the face each triangle of the closed, consistently oriented mesh lies in.

    A face is a set of edge-connected triangles with parallel normals (to 1e-15 in the cosine, 4.5e-8 rad: a
    fold needs facets within a tolerance ~1e-12 of coplanar; looser, a chain of slightly bent facets of a
    finely sampled curved surface joins and its area shrinks), or antiparallel ones where one faces the inside
    (a fold), zero-area triangles joining any. quickhull cones a
    point to the edge of the coplanar facets around it, and where that region is not star-shaped from the
    point the new triangles fold back over each other in the plane: each is a triangle of the face, but the
    face's area is ``|sum of the triangles' oriented area vectors|`` (the folds cancel), its normal that sum's
    direction. Signed areas along it (_measure) then add up to the face's area.
    """
    a, b, c = V[tri[:, 0]], V[tri[:, 1]], V[tri[:, 2]]
    G = _cross(b - a, c - a)  # oriented area vectors (twice the area)
    L = np.linalg.norm(G, axis=1)
    N = np.divide(G, L[:, None], out=np.zeros_like(G), where=L[:, None] > 0)
    parent = list(range(len(tri)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    owner = {}
    for f, (u, v, w) in enumerate(tri.tolist()):
        for edge in ((u, v), (v, w), (w, u)):
            owner[edge] = f
    # a fold faces the body's inside; a thin body's two sides (also antiparallel across its rim) both face out.
    # Only a clear answer counts: a sliver's normal is off by up to its tolerance (see _quickhull's add)
    e1, e2 = b - a, c - a
    with np.errstate(divide="ignore", invalid="ignore"):
        tol = np.maximum(_EPS, 8 * _U * np.sqrt((e1 * e1).sum(axis=1) * (e2 * e2).sum(axis=1)) / L)
    inward = np.einsum("ij,ij->i", N, a - V.mean(axis=0)) < -tol
    for (u, v), f in owner.items():
        g = owner.get((v, u))
        if g is None or f > g:
            continue
        cos = float(N[f] @ N[g])
        if L[f] == 0 or L[g] == 0 or cos > 1 - 1e-15 or (cos < 1e-15 - 1 and (inward[f] or inward[g])):
            parent[root(f)] = root(g)
    comp = np.array([root(f) for f in range(len(tri))])
    S = np.zeros_like(G)
    np.add.at(S, comp, G)
    S = S[comp]
    length = np.linalg.norm(S, axis=1, keepdims=True)
    return np.divide(S, length, out=np.zeros_like(S), where=length > 0)
