"""Exact distances from the robot's capsules (and carried shapes) to a scene's mesh fixtures, with coal. Metres.

A mesh fixture (:class:`~robocritics.scene.Shape` of kind ``mesh``) is a static triangle soup: coal's
``BVHModelOBBRSS`` of its triangles, and ``coal.distance`` against a capsule (GJK per triangle pair the
bounding-volume hierarchy cannot rule out) gives the distance to the surface, exact to coal's GJK tolerance
when apart, and a negative value (the capsule's depth past the nearest touched triangle) when the capsule
crosses the surface. A capsule wholly *inside* a closed mesh, touching no triangle, is reported at its
positive distance to the surface: a triangle soup has no inside (a CAD export need not be watertight).

Far samples never call coal: the distance of the capsule's segment to the mesh's bounding ball (centre the
bounding box's, radius its farthest vertex) minus both radii is a lower bound, used where it is above the
caller's cutoff (the contract of :meth:`robocritics.geometry.proximity.ProximityKernel.distances`).
"""

from __future__ import annotations

import numpy as np

from ..scene import Shape
from .pairs import coal_geometry

__all__ = ["mesh_model", "mesh_ball", "capsule_mesh", "shape_mesh"]


def mesh_model(shape: Shape):
    """coal's bounding-volume hierarchy of a mesh shape's triangles (in the shape frame)."""
    if shape.mesh is None:
        raise ValueError(f"shape {shape.name!r} ({shape.kind}) has no triangles")
    return coal_geometry("mesh", shape.mesh)


def mesh_ball(shape: Shape) -> tuple[np.ndarray, float]:
    """Centre (m, base frame) and radius (m) of a ball holding every vertex of a mesh shape."""
    vertices = shape.mesh[0]
    middle = (vertices.max(axis=0) + vertices.min(axis=0)) / 2
    radius = float(np.sqrt(((vertices - middle) ** 2).sum(axis=1).max()))
    pose = np.asarray(shape.pose, dtype=float)
    return pose[:3, :3] @ middle + pose[:3, 3], radius


def _segment_point(p0: np.ndarray, p1: np.ndarray, c: np.ndarray) -> np.ndarray:
    d = p1 - p0
    dd = (d * d).sum(axis=1)
    t = np.clip(((c - p0) * d).sum(axis=1) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    return np.linalg.norm(p0 + t[:, None] * d - c, axis=1)


def _transform(pose: np.ndarray):
    import coal

    return coal.Transform3s(np.ascontiguousarray(pose[:3, :3]), np.ascontiguousarray(pose[:3, 3]))


def capsule_mesh(p0, p1, radius_m: float, shape: Shape, model=None, cut=None) -> np.ndarray:
    """Signed distances ``(T,)`` (m) of the capsules ``p0``-``p1`` ``(T, 3)`` of radius ``radius_m`` to the mesh
    ``shape`` (see the module docstring). With ``cut`` (m, ``(T,)``), a sample whose bounding-ball bound is
    above its cutoff gets that lower bound instead of coal's value; ``cut=None``: every value exact."""
    import coal

    p0, p1 = np.asarray(p0, dtype=float), np.asarray(p1, dtype=float)
    centre, ball = mesh_ball(shape)
    out = _segment_point(p0, p1, centre) - ball - radius_m
    exact = np.ones(len(p0), dtype=bool) if cut is None else out <= np.asarray(cut)
    model = mesh_model(shape) if model is None else model
    where = _transform(np.asarray(shape.pose, dtype=float))
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    at = np.flatnonzero(exact)
    if len(at) == 0:
        return out
    # an arm standing still: one call per run of equal segments
    ends = np.concatenate([p0[at], p1[at]], axis=1)
    new = np.ones(len(at), dtype=bool)
    new[1:] = (ends[1:] != ends[:-1]).any(axis=1)
    firsts = at[new]
    rotations, centres, lengths = _capsule_frames(p0[firsts], p1[firsts])
    values = np.empty(len(firsts))
    transform = coal.Transform3s()
    for n in range(len(firsts)):
        transform.setRotation(rotations[n])
        transform.setTranslation(centres[n])
        result.clear()
        values[n] = coal.distance(coal.Capsule(radius_m, float(lengths[n])), transform, model, where, request, result)
    out[at] = values[np.cumsum(new) - 1]
    return out


def _capsule_frames(p0: np.ndarray, p1: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`~robocritics.geometry.pairs.capsule_pose` for ``N`` segments at once: rotations ``(N, 3, 3)`` whose
    z runs along ``p0 -> p1``, the midpoints ``(N, 3)`` and the lengths ``(N,)``, m."""
    axis = p1 - p0
    lengths = np.linalg.norm(axis, axis=1)
    z = np.where(lengths[:, None] > 1e-12, axis / np.where(lengths > 1e-12, lengths, 1.0)[:, None], [0.0, 0.0, 1.0])
    helper = np.where((np.abs(z[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    rotations = np.ascontiguousarray(np.stack([x, np.cross(z, x), z], axis=2))
    return rotations, np.ascontiguousarray((p0 + p1) / 2), lengths


def shape_mesh(a: Shape, b: Shape, Pa: np.ndarray, Pb: np.ndarray) -> np.ndarray:
    """Signed distances ``(T,)`` (m) of a primitive ``a`` at poses ``Pa`` ``(1 or T, 4, 4)`` to a mesh ``b``
    (static, ``Pb`` ``(1, 4, 4)``): coal, once per run of equal poses."""
    import coal

    if a.kind == "mesh":
        raise ValueError(f"shapes {a.name!r} and {b.name!r}: two meshes are not measured (a mesh is a fixture)")
    geometry, model = coal_geometry(a.kind, a.size), mesh_model(b)
    where = _transform(np.asarray(Pb[0], dtype=float))
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    out = np.empty(len(Pa))
    for t in range(len(Pa)):
        if t and np.array_equal(Pa[t], Pa[t - 1]):
            out[t] = out[t - 1]
            continue
        result.clear()
        out[t] = coal.distance(geometry, _transform(Pa[t]), model, where, request, result)
    return out
