"""The convex hull of a piece of link mesh, and when its distance is the piece's own. Metres.

coal measures a triangle mesh (a bounding-volume hierarchy) against a shape at a cost that grows with the
triangle count: ~0.6-5 ms a call for the SO-100's 2,000-7,000-triangle link pieces against a capsule, wherever
the capsule is (benchmarks/bench_vendor_arms.py, the SO-100 row). Against the piece's convex hull ``H`` (a
``coal.Convex``: GJK on its support function) the same call costs ~10-20 us. ``H`` holds the piece ``M``, so for
anything ``A`` apart from ``H``

    d(A, H)  <=  d(A, M),

and if the witness point ``p`` of ``H`` (the point of ``H`` nearest ``A``, next to ``a`` on ``A``) lies within
``e`` of ``M``, at some ``m``, then ``d(A, M) <= |a - m| <= |a - p| + e = d(A, H) + e``: the hull's distance is
the piece's, to ``e`` (:data:`ON_PIECE_M`). That happens wherever the nearest part of the piece is on its
outside (a convex patch, an edge, a corner): the usual case for a link near another link or an object. A
witness in a dent of the piece (``p`` on a hull facet that bridges it) is not on ``M``: then only the bound holds.

:meth:`PieceHull.on_piece` tests ``p`` against the mesh triangles whose three corners are on the hull's surface
(every triangle that can lie on it, a flat face's with its inner vertices; one whose corners are on different
faces, a chord inside, does no harm: ``p`` near it is near ``M``) and against the hull's vertices (each a vertex
of the mesh). A hull built from the vertices drops none farther
than ~1e-12 of the piece's extent outside it (:mod:`robocritics.geometry.hull`), so the bound holds to that.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .hull import hull_triangles
from .triangle_grid import TriangleGrid, triangle_grid

__all__ = ["ON_PIECE_M", "PieceHull", "piece_hull"]

#: A witness point within this distance [m] of a mesh triangle is on the piece: the hull's distance is then the
#: piece's to this (coal's GJK tolerance for the exact values is 1e-10 m; tests/test_piece_hulls.py checks).
ON_PIECE_M = 1e-10


@dataclass(frozen=True)
class PieceHull:
    """``convex``: the hull as a ``coal.Convex`` (the piece's frame); ``corners (H, 3)`` its vertices;
    ``a``, ``e1``, ``e2``, ``normal`` ``(F, 3)``: the mesh triangles with all corners on the hull's surface (corner
    ``a``, edges ``e1 = b - a``, ``e2 = c - a``, unit normal); ``grid`` those triangles and ``corner_grid`` the hull's
    vertices bucketed for points within ``2 ON_PIECE_M`` (twice: rounding in the tests below cannot pass one the
    grid left out)."""

    convex: object
    corners: np.ndarray
    a: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    normal: np.ndarray
    grid: TriangleGrid
    corner_grid: TriangleGrid

    def on_piece(self, p: np.ndarray) -> bool:
        """Whether the point ``p (3,)`` (m, the piece's frame) is within :data:`ON_PIECE_M` of the piece."""
        corners = self.corner_grid.near(p)  # the vertices within 2 ON_PIECE_M of p's cell (few, mostly none)
        if len(corners) and np.min(((self.corners[corners] - p) ** 2).sum(axis=1)) <= ON_PIECE_M**2:
            return True
        near = self.grid.near(p)  # the triangles whose grown boxes hold p: the others are farther than ON_PIECE_M
        if not len(near):
            return False
        near = near[np.abs(((p - self.a[near]) * self.normal[near]).sum(axis=1)) <= ON_PIECE_M]  # in a triangle's plane
        if not len(near):
            return False
        return bool(_point_triangle(p - self.a[near], self.e1[near], self.e2[near]).min() <= ON_PIECE_M)


def _point_triangle(w: np.ndarray, e1: np.ndarray, e2: np.ndarray) -> np.ndarray:
    """Distances ``(F,)`` of points ``a + w`` from the triangles ``(a, a + e1, a + e2)`` (Ericson's closest point
    by Voronoi regions, as barycentric coordinates clamped to the triangle)."""
    d00, d01, d11 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    d20, d21 = (w * e1).sum(1), (w * e2).sum(1)
    det = d00 * d11 - d01 * d01
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.clip((d11 * d20 - d01 * d21) / det, 0.0, 1.0)
        t = np.clip((d00 * d21 - d01 * d20) / det, 0.0, 1.0)
    over = s + t > 1.0
    s[over], t[over] = s[over] / (s + t)[over], t[over] / (s + t)[over]
    # the clamped point is in the triangle but may not be the nearest one: the nearest of it and the three edges
    best = np.linalg.norm(w - s[:, None] * e1 - t[:, None] * e2, axis=1)
    for start, edge in ((np.zeros_like(w), e1), (np.zeros_like(w), e2), (e1, e2 - e1)):
        u = np.clip(((w - start) * edge).sum(1) / np.maximum((edge * edge).sum(1), 1e-300), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(w - start - u[:, None] * edge, axis=1))
    return best


def piece_hull(vertices: np.ndarray, triangles: np.ndarray) -> PieceHull | None:
    """The :class:`PieceHull` of the mesh ``vertices (N, 3)`` (m), ``triangles (F, 3)``; None for a flat piece
    (no hull with volume: coal measures it as it is)."""
    import coal

    vertices = np.asarray(vertices, dtype=float)
    index, facets = hull_triangles(vertices)
    if not len(index):
        return None
    corners = vertices[index]
    points, polygons = coal.StdVec_Vec3s(), coal.StdVec_Triangle()
    points.extend(list(corners))
    polygons.extend([coal.Triangle(*f) for f in facets.tolist()])
    convex = coal.Convex(points, polygons)
    # the mesh triangles whose corners are all on the hull's surface (a flat face's triangles, inner vertices
    # and all): within ON_PIECE_M of a facet's plane, the facet facing away from the hull's centroid
    fa, fb, fc = corners[facets[:, 0]], corners[facets[:, 1]], corners[facets[:, 2]]
    normals = np.cross(fb - fa, fc - fa)
    normals /= np.maximum(np.linalg.norm(normals, axis=1), 1e-300)[:, None]
    normals *= np.where(((corners.mean(axis=0) - fa) * normals).sum(axis=1) > 0, -1.0, 1.0)[:, None]
    height = np.full(len(vertices), -np.inf)  # each vertex's largest signed distance from a facet's plane
    for lo in range(0, len(facets), 256):  # (N, 256) at a time
        part = slice(lo, lo + 256)
        height = np.maximum(height, (vertices @ normals[part].T - (fa[part] * normals[part]).sum(axis=1)).max(axis=1))
    on_hull = height >= -ON_PIECE_M
    outer = np.asarray(triangles)[on_hull[np.asarray(triangles)].all(axis=1)]
    a, b, c = vertices[outer[:, 0]], vertices[outer[:, 1]], vertices[outer[:, 2]]
    normal = np.cross(b - a, c - a)
    length = np.linalg.norm(normal, axis=1)
    keep = length > 0  # a zero-area triangle lies on its neighbours' edges
    normal = normal[keep] / length[keep, None]
    return PieceHull(convex, corners, a[keep], (b - a)[keep], (c - a)[keep], normal,
                     triangle_grid(np.stack([a, b, c], axis=1)[keep], 2 * ON_PIECE_M),
                     triangle_grid(np.repeat(corners[:, None], 3, axis=1), 2 * ON_PIECE_M))
