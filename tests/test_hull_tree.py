"""The hierarchy of hulls over a piece of mesh (geometry.hull_tree) against coal's call on the whole mesh: the
same distance (to 1e-9 m; it is the least over the same triangles) for a piece against primitives and against
another piece, at any pose where they are apart; below ``within_m``'s reach a lower bound, never above the
mesh's. hypothesis places the shapes around a bumpy, stretched sphere (dents where a hull's witness is off
the mesh) split down to 32-triangle leaves, so the search goes several levels deep."""

from __future__ import annotations

import coal
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics.geometry.hull_tree import hull_tree, primitive_tree, tree_distance
from robocritics.geometry.pairs import coal_geometry

from mesh_reference import bumpy_sphere

V, F = bumpy_sphere(20)
V = V * [3.0, 1.0, 0.7]  # 0.3 m long: the median splits cut along x first
TREE = hull_tree(V, F, leaf_triangles=32)
MESH = coal_geometry("mesh", (V, F))
SHAPES = {"sphere": lambda s: coal.Sphere(s), "box": lambda s: coal.Box(s, 0.8 * s, 0.5 * s),
          "capsule": lambda s: coal.Capsule(0.4 * s, s), "cylinder": lambda s: coal.Cylinder(0.5 * s, s)}
poses = st.tuples(st.tuples(st.floats(-0.2, 0.2), st.floats(-0.1, 0.1), st.floats(-0.1, 0.1)),
                  st.tuples(st.floats(-3.0, 3.0), st.floats(-1.5, 1.5), st.floats(-3.0, 3.0)))


def _pose(where, rpy) -> np.ndarray:
    r, p, y = rpy
    Rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    Ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    Rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = Rz @ Ry @ Rx, where
    return T


def _both(tree_b, geometry_b, relative, within_m=np.inf):
    """(coal on the whole meshes, the tree search) for the piece at ``relative`` in b's frame."""
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    request.gjk_tolerance = 1e-10
    where = coal.Transform3s(np.ascontiguousarray(relative[:3, :3]), np.ascontiguousarray(relative[:3, 3]))
    whole = coal.distance(MESH, where, geometry_b, coal.Transform3s(), request, result)
    return whole, tree_distance(TREE, tree_b, relative, where, request, result, within_m)


@settings(max_examples=300, deadline=None)
@given(kind=st.sampled_from(sorted(SHAPES)), size=st.floats(0.005, 0.08), pose=poses)
def test_the_tree_gives_coals_whole_mesh_distance_against_a_primitive(kind, size, pose):
    shape = SHAPES[kind](size)
    whole, fast = _both(primitive_tree(shape), shape, np.linalg.inv(_pose(*pose)))
    if whole <= 1e-6:  # crossing or touching: the tree may give up (None), never a positive value past it
        assert fast is None or fast[0] <= whole + 1e-9
        return
    assert fast is not None and fast[1]
    assert fast[0] == pytest.approx(whole, abs=1e-9)


@settings(max_examples=150, deadline=None)
@given(pose=poses, within_m=st.sampled_from([np.inf, 0.02, 0.0]))
def test_the_tree_gives_coals_whole_mesh_distance_against_another_piece(pose, within_m):
    """Two copies of the piece; with a finite ``within_m`` the value above it may be a lower bound."""
    whole, fast = _both(TREE, MESH, _pose(*pose), within_m)
    if whole <= 1e-6:
        assert fast is None or fast[0] <= whole + 1e-9
        return
    assert fast is not None
    if fast[1]:
        assert fast[0] == pytest.approx(whole, abs=1e-9)
    else:
        assert within_m < fast[0] <= whole + 1e-9


def test_the_tree_splits_every_triangle_once_and_its_hulls_hold_their_triangles():
    leaves = [n for n in TREE.nodes if n.children is None]
    assert sum(n.size for n in leaves) == len(F) and all(n.size <= 32 for n in leaves) and len(leaves) >= 16
    for node in leaves:
        inside = np.asarray(node.hull.convex.points()) if node.hull else None
        assert inside is None or len(inside) >= 4


def test_a_flat_piece_has_no_tree():
    flat = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]), np.array([[0, 1, 2], [1, 3, 2]])
    assert hull_tree(*flat) is None
