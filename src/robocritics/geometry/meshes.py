"""Exact distances from the robot's capsules (and carried shapes) to a scene's mesh fixtures, with coal. Metres.

A mesh fixture (:class:`~robocritics.scene.Shape` of kind ``mesh``) is a triangle mesh that does not move:
coal's ``BVHModelOBBRSS`` of its triangles, and ``coal.distance`` against a capsule (GJK per triangle pair the
bounding-volume hierarchy cannot rule out) gives the distance to the surface, exact to coal's GJK tolerance
when apart, and a negative value (the capsule's depth past the nearest touched triangle) when the capsule
crosses the surface.

Inside a closed mesh
--------------------
A mesh is **closed** when its surface has no boundary: every edge is walked as often from ``u`` to ``v`` as
from ``v`` to ``u`` by the triangles (:func:`is_closed`; a watertight, consistently oriented export, or several
such shells, touching or overlapping). A closed mesh has an inside: the points of non-zero winding number
(:func:`winding_numbers`, the triangles' solid angles summed over 4 pi: 1 inside a shell, 0 outside, whatever
the shells' overlaps). A shape that touches no triangle lies wholly on one side of the surface, so one of its
points decides: a capsule (or a carried shape) wholly inside a closed mesh reads

    -(d + 2 rho)

where ``d > 0`` is coal's distance from its surface to the mesh's and ``rho`` the radius of a ball it holds (a
capsule's or sphere's radius, a box's least half size, a cylinder's least of radius and half height). That
ball's centre is ``d + rho`` deep, so no translation shorter than ``d + 2 rho`` takes the shape out: the value
is never deeper than the true penetration, exactly it for a ball in a convex solid (as the closed-form box
kernels report a ball inside a box, :mod:`robocritics.geometry.kernels`), and always below 0 (a collision). A
mesh that is not closed (an open shell, a single face, a CAD export with gaps) has no inside: a shape behind
it reads its positive distance to the surface.

Far samples never call coal: the distance of the capsule's segment to the mesh's bounding ball (centre the
bounding box's, radius its farthest vertex) minus both radii is a lower bound (a capsule outside the ball is
outside the mesh too), used where it is above the caller's cutoff (the contract of
:meth:`robocritics.geometry.proximity.ProximityKernel.distances`).
"""

from __future__ import annotations

import numpy as np

from ..scene import Shape
from .pairs import coal_geometry

__all__ = ["mesh_model", "mesh_ball", "capsule_mesh", "shape_mesh", "capsule_frames", "is_closed", "winding_numbers", "inside_closed",
           "inscribed_radius"]

#: Point-triangle terms per block of :func:`winding_numbers` (a few MB of temporaries).
_WINDING_BLOCK = 200_000


_MODELS: dict[tuple[int, int], tuple[np.ndarray, np.ndarray, object]] = {}


def mesh_model(shape: Shape):
    """coal's bounding-volume hierarchy of a mesh shape's triangles (in the shape frame), built once per pair of
    arrays (scene meshes share their file's arrays)."""
    if shape.mesh is None:
        raise ValueError(f"shape {shape.name!r} ({shape.kind}) has no triangles")
    vertices, triangles = shape.mesh
    hit = _MODELS.get((id(vertices), id(triangles)))
    if hit is None or hit[0] is not vertices or hit[1] is not triangles:
        if len(_MODELS) > 64:
            _MODELS.clear()
        hit = _MODELS[id(vertices), id(triangles)] = (vertices, triangles, coal_geometry("mesh", shape.mesh))
    return hit[2]


def mesh_ball(shape: Shape) -> tuple[np.ndarray, float]:
    """Centre (m, base frame) and radius (m) of a ball holding every vertex of a mesh shape."""
    vertices = shape.mesh[0]
    middle = (vertices.max(axis=0) + vertices.min(axis=0)) / 2
    radius = float(np.sqrt(((vertices - middle) ** 2).sum(axis=1).max()))
    pose = np.asarray(shape.pose, dtype=float)
    return pose[:3, :3] @ middle + pose[:3, 3], radius


def is_closed(vertices: np.ndarray, triangles: np.ndarray) -> bool:
    """True when the surface of ``triangles (F, 3)`` (indices into ``vertices (V, 3)``) has no boundary: every
    directed edge ``u -> v`` occurs as often as ``v -> u`` (then the winding number is an integer off the
    surface). Vertices are compared by index: a mesh whose copies of a corner are not merged is open."""
    triangles = np.asarray(triangles, dtype=np.int64)
    if not len(triangles):
        return False
    n = int(len(vertices))
    u = triangles.reshape(-1)
    v = np.roll(triangles, -1, axis=1).reshape(-1)
    return bool(np.array_equal(np.sort(u * n + v), np.sort(v * n + u)))


def winding_numbers(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Generalised winding numbers ``(P,)`` of ``points (P, 3)`` for the triangles ``corners (F, 3, 3)`` (same
    frame): ``sum_f Omega_f(p) / (4 pi)``, the solid angle of each triangle seen from ``p`` by Van Oosterom and
    Strackee's formula ``tan(Omega / 2) = a . (b x c) / (|a||b||c| + (a.b)|c| + (a.c)|b| + (b.c)|a|)`` with
    ``a, b, c`` the corners relative to ``p``. For a closed mesh: the number of shells around ``p`` (signed by
    their orientation), 0 outside."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    corners = np.asarray(corners, dtype=float)
    out = np.zeros(len(points))
    step = max(1, _WINDING_BLOCK // max(len(corners), 1))
    for start in range(0, len(points), step):
        p = points[start : start + step, None, None, :]  # (P', 1, 1, 3)
        rel = corners[None] - p  # (P', F, 3, 3)
        a, b, c = rel[:, :, 0], rel[:, :, 1], rel[:, :, 2]
        la, lb, lc = (np.sqrt(np.einsum("pfi,pfi->pf", x, x)) for x in (a, b, c))
        det = np.einsum("pfi,pfi->pf", a, np.cross(b, c))
        den = la * lb * lc + np.einsum("pfi,pfi->pf", a, b) * lc + np.einsum("pfi,pfi->pf", a, c) * lb \
            + np.einsum("pfi,pfi->pf", b, c) * la
        out[start : start + step] = np.arctan2(det, den).sum(axis=1) / (2 * np.pi)
    return out


_CLOSED: dict[tuple[int, int], tuple[np.ndarray, np.ndarray, bool]] = {}


def _closed(vertices: np.ndarray, triangles: np.ndarray) -> bool:
    """:func:`is_closed`, once per pair of arrays (scene meshes share their file's arrays)."""
    key = (id(vertices), id(triangles))
    hit = _CLOSED.get(key)
    if hit is None or hit[0] is not vertices or hit[1] is not triangles:
        if len(_CLOSED) > 64:
            _CLOSED.clear()
        hit = _CLOSED[key] = (vertices, triangles, is_closed(vertices, triangles))  # the arrays held: ids stay theirs
    return hit[2]


def inside_closed(points: np.ndarray, shape: Shape) -> np.ndarray:
    """Which of ``points (P, 3)`` (m, base frame) are inside the mesh ``shape`` (bool ``(P,)``): a non-zero
    winding number of a closed mesh (:func:`is_closed`); all False for an open one (it has no inside)."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    vertices, triangles = shape.mesh
    out = np.zeros(len(points), dtype=bool)
    if not len(points) or not _closed(vertices, triangles):
        return out
    pose = np.asarray(shape.pose, dtype=float)
    local = (points - pose[:3, 3]) @ pose[:3, :3]  # R^T (p - c), row by row
    box = ((local >= vertices.min(axis=0)) & (local <= vertices.max(axis=0))).all(axis=1)
    if box.any():
        out[box] = np.abs(winding_numbers(local[box], vertices[triangles])) > 0.5
    return out


def inscribed_radius(kind: str, size) -> float:
    """The radius (m) of a ball that a primitive of ``kind`` and ``size`` (as :class:`Shape`) holds about its
    centre: a sphere's radius, a box's least half size, a cylinder's least of radius and half height."""
    if kind == "box":
        return 0.5 * float(min(size))
    if kind == "cylinder":
        return float(min(size[0], 0.5 * size[1]))
    return float(size[0])


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
    ``shape`` (see the module docstring: wholly inside a closed mesh, ``-(d + 2 radius_m)``). With ``cut`` (m, ``(T,)``), a sample whose bounding-ball bound is
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
    rotations, centres, lengths = capsule_frames(p0[firsts], p1[firsts])
    values = np.empty(len(firsts))
    transform = coal.Transform3s()
    for n in range(len(firsts)):
        transform.setRotation(rotations[n])
        transform.setTranslation(centres[n])
        result.clear()
        values[n] = coal.distance(coal.Capsule(radius_m, float(lengths[n])), transform, model, where, request, result)
    apart = values > 0  # touching no triangle: wholly inside or wholly outside, as its axis's start is
    if apart.any():
        deep = np.flatnonzero(apart)[inside_closed(p0[firsts[apart]], shape)]
        values[deep] = -(values[deep] + 2.0 * radius_m)
    out[at] = values[np.cumsum(new) - 1]
    return out


def capsule_frames(p0: np.ndarray, p1: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
    (static, ``Pb`` ``(1, 4, 4)``): coal, once per run of equal poses; wholly inside a closed mesh, the depth
    of the module docstring."""
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
    apart = np.flatnonzero(out > 0)
    if len(apart):  # touching no triangle: wholly inside or outside, as its centre is
        deep = apart[inside_closed(np.asarray(Pa, dtype=float)[apart, :3, 3], b)]
        out[deep] = -(out[deep] + 2.0 * inscribed_radius(a.kind, a.size))
    return out
