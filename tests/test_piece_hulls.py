"""The convex hull of a piece of link mesh as the fast first look at its distance (geometry.piece_hulls): a lower
bound of coal's distance on the raw triangles always, and that distance itself (to 1e-9 m) wherever the witness
is certified on the piece; the certificate checked against brute-force point-triangle distances. hypothesis
places primitives around a non-convex piece (a tube with a housing across its end: the dent between them is
where the hull's witness is off the mesh)."""

from __future__ import annotations

from dataclasses import replace

import coal
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics.geometry.hull import convex_hull, hull_triangles
from robocritics.geometry.pairs import coal_geometry
from robocritics.geometry.piece_hulls import ON_PIECE_M, piece_hull
from robocritics.geometry.triangle_grid import ENTRIES_PER_TRIANGLE, triangle_grid

from mesh_reference import bumpy_sphere, point_triangle


def _boxes(boxes) -> tuple[np.ndarray, np.ndarray]:
    """Closed triangle meshes of axis-aligned boxes ``(lo, hi)``, joined (vertices shared within a box)."""
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]  # fmt: skip
    V, F = [], []
    for lo, hi in boxes:
        F += [tuple(len(V) + i for i in f) for f in faces]
        V += [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    return np.array(V, float), np.array(F, np.int64)


#: a 0.36 m tube along x and a housing across its far end (m): non-convex
PIECE = _boxes([((0.0, -0.03, -0.03), (0.36, 0.03, 0.03)), ((0.30, -0.09, -0.07), (0.42, 0.09, 0.07))])
HULL = piece_hull(*PIECE)


def _rotation(rpy) -> np.ndarray:
    r, p, y = rpy
    Rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    Ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    Rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _distances(shape, R, t) -> tuple[float, float, bool]:
    """(coal on the raw triangles, the hull's distance, whether its witness is certified on the piece) of the
    piece at the identity against ``shape`` at ``(R, t)``."""
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    request.gjk_tolerance = 1e-10
    at = coal.Transform3s(np.ascontiguousarray(R), np.ascontiguousarray(t))
    raw = coal.distance(coal_geometry("mesh", PIECE), coal.Transform3s(), shape, at, request, result)
    result.clear()
    hull = coal.distance(HULL.convex, coal.Transform3s(), shape, at, request, result)
    witness = np.asarray(result.getNearestPoint1())
    return raw, hull, hull > 0 and HULL.on_piece(witness)


SHAPES = {"sphere": lambda s: coal.Sphere(s), "box": lambda s: coal.Box(s, 0.8 * s, 0.5 * s),
          "capsule": lambda s: coal.Capsule(0.4 * s, s), "cylinder": lambda s: coal.Cylinder(0.5 * s, s)}


@settings(max_examples=200, deadline=None)
@given(
    kind=st.sampled_from(sorted(SHAPES)),
    size=st.floats(0.01, 0.08),
    where=st.tuples(st.floats(-0.1, 0.5), st.floats(-0.2, 0.2), st.floats(-0.2, 0.2)),
    rpy=st.tuples(st.floats(-3.0, 3.0), st.floats(-1.5, 1.5), st.floats(-3.0, 3.0)),
)
def test_the_hull_distance_is_a_lower_bound_and_certified_it_is_the_mesh_distance(kind, size, where, rpy):
    raw, hull, certified = _distances(SHAPES[kind](size), _rotation(rpy), np.array(where))
    if raw <= 0:  # crossing: the hull (holding the piece) crosses too
        assert hull <= 1e-9
        return
    assert hull <= raw + 1e-9  # conv(M) holds M
    if certified:
        assert hull == pytest.approx(raw, abs=1e-9)


def test_the_certificate_holds_outside_and_fails_in_the_dent():
    """A ball beside the tube's end, above the housing's face: outside the piece's convex part the witness is on
    the mesh; in the dent between tube and housing (under the hull's bridging facet) it is not, and the hull's
    distance is below the mesh's there."""
    ball = coal.Sphere(0.01)
    raw, hull, certified = _distances(ball, np.eye(3), np.array([0.48, 0.0, 0.0]))  # past the housing's end face
    assert certified and hull == pytest.approx(raw, abs=1e-9) and raw == pytest.approx(0.05, abs=1e-9)
    raw, hull, certified = _distances(ball, np.eye(3), np.array([0.2, 0.0, 0.06]))  # above the tube, in the dent
    assert not certified and hull < raw - 1e-3


@settings(max_examples=200, deadline=None)
@given(
    face=st.integers(0, len(PIECE[1]) - 1),
    weights=st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.floats(0.0, 1.0)),
    lift=st.sampled_from([0.0, 1e-11, 1e-9, 1e-6, 1e-3]),
)
def test_on_piece_agrees_with_the_brute_force_point_triangle_distance(face, weights, lift):
    V, F = PIECE
    w = np.array(weights) + 1e-3
    tri = V[F[face]]
    normal = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    p = (w / w.sum()) @ tri + lift * normal / np.linalg.norm(normal)
    brute = point_triangle(p, V[F]).min()
    if HULL.on_piece(p):
        assert brute <= ON_PIECE_M + 1e-15  # never certifies a point off the mesh
    if lift <= 1e-11 and _on_hull_surface(tri):  # on a face of the hull's surface: certified
        assert HULL.on_piece(p)
    if lift >= 1e-9:
        assert not HULL.on_piece(p) or brute <= ON_PIECE_M


def _on_hull_surface(tri: np.ndarray) -> bool:
    """Whether every corner of ``tri`` is a vertex or on a facet plane of the piece's hull (brute force)."""
    index, facets = hull_triangles(PIECE[0])
    corners = PIECE[0][index]
    a, b, c = corners[facets[:, 0]], corners[facets[:, 1]], corners[facets[:, 2]]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return all((np.abs(((v - a) * n).sum(axis=1)) <= 1e-12).any() for v in tri)


def test_hull_triangles_has_the_convex_hull_vertices_and_encloses_every_point():
    rng = np.random.default_rng(4)
    for P in (rng.normal(size=(400, 3)), rng.normal(size=(300, 3)) * [1.0, 1.0, 1e-7], PIECE[0]):
        index, facets = hull_triangles(P)
        assert np.array_equal(np.sort(index), convex_hull(P).vertices)
        corners = P[index]
        a, b, c = corners[facets[:, 0]], corners[facets[:, 1]], corners[facets[:, 2]]
        n = np.cross(b - a, c - a)
        keep = np.linalg.norm(n, axis=1) > 1e-12 * np.ptp(P, axis=0).max() ** 2
        n = n[keep] / np.linalg.norm(n[keep], axis=1, keepdims=True)
        n *= np.where(((corners.mean(axis=0) - a[keep]) * n).sum(axis=1) > 0, -1.0, 1.0)[:, None]
        assert ((P @ n.T - (a[keep] * n).sum(axis=1)) <= 1e-9 * np.ptp(P, axis=0).max()).all()  # all inside


BUMPY = bumpy_sphere()
BUMPY_HULL = piece_hull(*BUMPY)
#: the same hull with grids of one cell holding every triangle and vertex: on_piece then scans them all (the old rule)
BUMPY_FULL_SCAN = replace(
    BUMPY_HULL,
    grid=triangle_grid(np.stack([BUMPY_HULL.a, BUMPY_HULL.a + BUMPY_HULL.e1, BUMPY_HULL.a + BUMPY_HULL.e2], axis=1), 1.0),
    corner_grid=triangle_grid(np.repeat(BUMPY_HULL.corners[:, None], 3, axis=1), 1.0))


@settings(max_examples=300, deadline=None)
@given(
    face=st.integers(0, len(BUMPY[1]) - 1),
    weights=st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.floats(0.0, 1.0)),
    lift=st.sampled_from([0.0, 3e-11, -3e-11, 1e-10, 2e-10, 1e-9, 1e-6, 1e-3]),
    corner=st.booleans(),
)
def test_on_piece_through_the_grid_is_the_full_scan(face, weights, lift, corner):
    """The grid only skips triangles farther than ON_PIECE_M: the answer is the full scan's, on and off the mesh."""
    V, F = BUMPY
    w = np.array(weights) + 1e-3
    tri = V[F[face]]
    normal = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    p = (tri[0] if corner else (w / w.sum()) @ tri) + lift * normal / np.linalg.norm(normal)  # a corner: a vertex
    assert len(BUMPY_FULL_SCAN.grid.near(p)) == len(BUMPY_HULL.a)
    assert len(BUMPY_FULL_SCAN.corner_grid.near(p)) == len(BUMPY_HULL.corners)
    assert BUMPY_HULL.on_piece(p) == BUMPY_FULL_SCAN.on_piece(p)


BUMPY_GRIDS = {margin: triangle_grid(BUMPY[0][BUMPY[1]], margin) for margin in (1e-10, 1e-3, 1e-2)}


@settings(max_examples=200, deadline=None)
@given(
    p=st.tuples(st.floats(-0.07, 0.07), st.floats(-0.07, 0.07), st.floats(-0.07, 0.07)),
    margin=st.sampled_from(sorted(BUMPY_GRIDS)),
)
def test_the_grid_holds_every_triangle_within_its_margin(p, margin):
    V, F = BUMPY
    grid = BUMPY_GRIDS[margin]
    within = set(np.flatnonzero(point_triangle(np.array(p), V[F]) <= margin).tolist())
    assert within <= set(grid.near(np.array(p)).tolist())
    assert sum(len(m) for m in grid.cells.values()) <= ENTRIES_PER_TRIANGLE * len(F)
