"""Collision meshes and the capsules fitted to them.

A vendor URDF gives each link a triangle mesh (STL, DAE or OBJ); robocritics' distance kernels work on capsules.
:func:`load_mesh` reads a mesh with coal's loader (assimp: the three formats, a DAE's units) within
:data:`MAX_TRIANGLES`; :func:`fit_capsules` encloses a link's triangles in one to :data:`MAX_CAPSULES_PER_LINK`
capsules, split along the link's long axis where one capsule would be loose.

The error bound
---------------
Every fitted capsule **encloses its piece** of the mesh: the triangles clipped to the capsule's slab across the
link's long axis (:attr:`FittedCapsule.mesh`; the pieces together are the whole mesh, a triangle across a cut
split between the two sides). Capsules are convex and each holds every corner of its clipped triangles, so for
anything ``A`` outside a capsule

    d(A, piece) - slack_m  <=  d(A, capsule)  <=  d(A, piece)

where ``slack_m`` is the largest distance from a point of the capsule's surface to its piece (the closest point
of the capsule to ``A`` is on its surface, and from there the piece is at most ``slack_m`` away). Taking the
least over a link's capsules, the same holds for the whole mesh with the largest slack: the capsule distance
never misses a contact (it is never larger than the mesh distance) and reports a gap at most ``slack_m``
smaller than the mesh's. ``slack_m`` is measured on a grid over each capsule's surface (:data:`SLACK_GRID_M`
apart) with coal's point-to-mesh distance, plus the grid spacing (distance is 1-Lipschitz, so between grid
points it cannot grow by more). tests/test_robot_vendor.py checks both inequalities with hypothesis against a
plain point-to-triangle reference.

Near contact the pieces themselves are measured (:mod:`robocritics.geometry.link_meshes`): the slack then only
decides which samples are worth the exact work.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import RobotModelError

__all__ = ["Mesh", "FittedCapsule", "load_mesh", "box_mesh", "fit_capsules", "fit_capsules_uncached", "MAX_TRIANGLES", "MAX_CAPSULES_PER_LINK", "SLACK_GRID_M"]

#: Most triangles of one mesh file (vendor collision meshes have 100-20,000, visual OBJs ~20,000; fitting
#: 300,000 takes a few seconds of CPU).
MAX_TRIANGLES = 300_000
#: Most capsules fitted to one link.
MAX_CAPSULES_PER_LINK = 3
#: A split must shrink the capsules' volume by this fraction for each capsule it adds (fewer pairs to check).
SPLIT_GAIN = 0.1
#: Positions tried for each cut across a link's long axis (equally spaced).
CUT_GRID = 16
#: Spacing of the grid on which a capsule's slack is measured [m]; added to the measured slack.
SLACK_GRID_M = 0.006


@dataclass(frozen=True)
class Mesh:
    """Triangles: ``vertices (V, 3)`` m and ``triangles (F, 3)`` vertex indices."""

    vertices: np.ndarray
    triangles: np.ndarray

    def transformed(self, pose: np.ndarray) -> "Mesh":
        """This mesh moved by the 4x4 ``pose``."""
        return Mesh(self.vertices @ pose[:3, :3].T + pose[:3, 3], self.triangles)

    @staticmethod
    def union(meshes: list["Mesh"]) -> "Mesh":
        offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
        return Mesh(
            np.concatenate([m.vertices for m in meshes]),
            np.concatenate([m.triangles + o for m, o in zip(meshes, offsets)]),
        )


@dataclass(frozen=True)
class FittedCapsule:
    """Segment ``p0``-``p1`` and ``radius_m`` (m, link frame); ``mesh``: the piece of the link's mesh it encloses
    (link frame); ``slack_m``: the largest distance from its surface to that piece (the module docstring)."""

    p0: tuple[float, float, float]
    p1: tuple[float, float, float]
    radius_m: float
    slack_m: float
    mesh: Mesh | None = field(default=None, compare=False, repr=False)


def load_mesh(path: Path, scale=(1.0, 1.0, 1.0), max_triangles: int = MAX_TRIANGLES) -> Mesh:
    """The triangles of the mesh file ``path`` (STL, DAE or OBJ), scaled by ``scale``; a
    :class:`RobotModelError` for another format, a file coal cannot read, no triangles or too many."""
    import coal

    suffix = path.suffix.lower()
    if suffix not in (".stl", ".dae", ".obj"):
        raise RobotModelError(f"mesh {str(path)!r}: robocritics reads STL, DAE and OBJ meshes, not {suffix or 'this file'}")
    if suffix == ".dae":  # COLLADA is XML: no DTD reaches assimp's parser (entity expansion, external entities)
        with open(path, "rb") as f:
            head = f.read(1 << 16).upper()
        if b"<!DOCTYPE" in head or b"<!ENTITY" in head:
            raise RobotModelError(f"mesh {str(path)!r} has a DOCTYPE or ENTITY declaration; a COLLADA mesh needs neither")
    try:
        model = coal.MeshLoader().load(str(path), np.asarray(scale, dtype=float))
    except Exception as exc:  # assimp's errors arrive as RuntimeError or ValueError, with its text
        raise RobotModelError(f"mesh {str(path)!r} cannot be read: {str(exc)[:200]}") from None
    F = int(model.num_tris)
    if F == 0:
        raise RobotModelError(f"mesh {str(path)!r} has no triangles")
    if F > max_triangles:
        raise RobotModelError(f"mesh {str(path)!r} has {F:,} triangles; robocritics reads at most {max_triangles:,}")
    vertices = np.array(model.vertices(), dtype=float).reshape(-1, 3)
    triangles = np.array([[t[0], t[1], t[2]] for t in (model.tri_indices(i) for i in range(F))], dtype=np.int64)
    if not np.isfinite(vertices).all() or triangles.min() < 0 or triangles.max() >= len(vertices):
        raise RobotModelError(f"mesh {str(path)!r} has non-finite vertices or triangles that name no vertex")
    # an STL repeats each vertex for every triangle around it: one copy each (the surface is the same)
    vertices, inverse = np.unique(vertices, axis=0, return_inverse=True)
    return Mesh(vertices, inverse.reshape(-1)[triangles])


def box_mesh(size) -> Mesh:
    """A box of ``size`` (3 lengths, m) centred at the origin, as 12 triangles."""
    half = np.asarray(size, float) / 2
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float) * half
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    return Mesh(corners, np.array(faces, dtype=np.int64))


_DIRECTIONS_2D = np.stack([np.cos(np.linspace(0, 2 * math.pi, 64, endpoint=False)),
                           np.sin(np.linspace(0, 2 * math.pi, 64, endpoint=False))])


def _volume(radius: float, length: float) -> float:
    return math.pi * radius * radius * length + 4.0 / 3.0 * math.pi * radius**3


def _enclosing(points: np.ndarray, axis: np.ndarray, iterations: int = 40) -> tuple[np.ndarray, np.ndarray, float]:
    """The capsule along ``axis`` (unit) enclosing ``points``: its axis line through the centre of a near-
    smallest circle around the points projected across the axis, radius the largest distance from that line,
    and the shortest segment whose caps still hold every point."""
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    flat = np.stack([points @ u, points @ v], axis=1)
    centre = (flat.min(axis=0) + flat.max(axis=0)) / 2
    # Badoiu-Clarkson: step towards the farthest point; converges to the smallest enclosing circle's centre.
    # The farthest point is always on the hull, so the steps look only at the extreme points in 64 directions
    # (the radius below is still measured over every point, so the capsule encloses them all)
    extreme = flat[np.unique(np.argmax(flat @ _DIRECTIONS_2D, axis=0))]
    for i in range(1, iterations):
        far = extreme[int(np.argmax(np.einsum("ij,ij->i", extreme - centre, extreme - centre)))]
        centre = centre + (far - centre) / (i + 1)
    across = flat - centre
    rho2 = np.einsum("ij,ij->i", across, across)
    radius = float(np.sqrt(rho2.max()))
    t = points @ axis
    reach = np.sqrt(np.maximum(radius * radius - rho2, 0.0))
    lo, hi = float(np.min(t + reach)), float(np.max(t - reach))
    origin = centre[0] * u + centre[1] * v
    if lo > hi:  # a ball: caps alone hold everything
        lo = hi = (lo + hi) / 2
    radius *= 1 + 1e-9  # rounding: the points sit on the surface, not outside it
    return origin + lo * axis, origin + hi * axis, radius


def _best_single(points: np.ndarray, iterations: int = 40) -> tuple[np.ndarray, np.ndarray, float]:
    centred = points - points.mean(axis=0)
    _, _, axes = np.linalg.svd(centred[:: max(1, len(centred) // 5000)], full_matrices=False)
    best = None
    for axis in axes:
        p0, p1, r = _enclosing(points, axis / np.linalg.norm(axis), iterations)
        volume = _volume(r, float(np.linalg.norm(p1 - p0)))
        if best is None or volume < best[0]:
            best = (volume, p0, p1, r)
    return best[1], best[2], best[3]


_FITTED: dict[bytes, list] = {}


def fit_capsules(mesh: Mesh, max_capsules: int = MAX_CAPSULES_PER_LINK) -> list[FittedCapsule]:
    """:func:`fit_capsules_uncached`, once per mesh (by content) and ``max_capsules`` in a process."""
    import hashlib

    key = hashlib.sha256(mesh.vertices.tobytes() + mesh.triangles.tobytes() + bytes([max_capsules])).digest()
    fitted = _FITTED.get(key)
    if fitted is None:
        if len(_FITTED) > 512:
            _FITTED.clear()
        fitted = _FITTED[key] = fit_capsules_uncached(mesh, max_capsules)
    return list(fitted)


def fit_capsules_uncached(mesh: Mesh, max_capsules: int = MAX_CAPSULES_PER_LINK) -> list[FittedCapsule]:
    """One to ``max_capsules`` capsules that together enclose every triangle of ``mesh`` (link frame, m).

    The mesh is cut across its long axis into slabs (each cut the best of :data:`CUT_GRID` positions given the
    cuts before it, judged on a subsample of the vertices); each capsule encloses the triangles that reach into its slab (a
    triangle across a cut belongs to both sides, so it lies wholly inside one capsule). A split is taken when
    each capsule it adds shrinks the total volume by :data:`SPLIT_GAIN`: a link with a housing at each end of
    a thinner tube gets three capsules, a plain tube one.
    """
    used = np.unique(mesh.triangles)
    points = mesh.vertices[used]
    centred = points - points.mean(axis=0)
    _, _, axes = np.linalg.svd(centred[:: max(1, len(centred) // 5000)], full_matrices=False)
    long_axis = axes[0] / np.linalg.norm(axes[0])
    t_points = points @ long_axis
    edges = np.unique(np.sort(np.concatenate([mesh.triangles[:, [0, 1]], mesh.triangles[:, [1, 2]], mesh.triangles[:, [2, 0]]]), axis=1), axis=0)
    grid = np.linspace(t_points.min(), t_points.max(), CUT_GRID + 1)[1:-1]
    crossings = {c: _crossing(mesh.vertices, edges, long_axis, c) for c in grid.tolist()}
    step = max(1, len(points) // 1500)

    def piece_points(a: float, b: float, stride: int = 1) -> np.ndarray:
        """The mesh between the planes t = a and t = b: its vertices there and where its edges cross them
        (every triangle clipped to the slab is the convex hull of these points)."""
        inside = points[::stride][(t_points[::stride] >= a) & (t_points[::stride] <= b)]
        return np.concatenate([inside, *(crossings[c] for c in (a, b) if c in crossings)])

    def pieces_for(cuts, stride: int) -> list | None:
        bounds = [-np.inf, *cuts, np.inf]
        out = []
        for a, b in zip(bounds[:-1], bounds[1:]):
            piece = piece_points(a, b, stride)
            if len(piece) < 2:
                return None
            out.append(_best_single(piece, 40 if stride == 1 else 6))
        return out

    def volume(pieces) -> float:
        return math.inf if pieces is None else sum(_volume(r, float(np.linalg.norm(p1 - p0))) for p0, p1, r in pieces)

    # cuts chosen greedily: the best one, then the best next one given it (a housing at each end of a tube
    # needs both), each split kept when it shrinks the volume by SPLIT_GAIN per added capsule
    best_cuts: tuple = ()
    best_volume = volume(pieces_for((), step))
    cuts: tuple = ()
    for k in range(2, max_capsules + 1):
        options = [tuple(sorted((*cuts, c))) for c in grid.tolist() if c not in cuts]
        if not options:
            break
        estimate, cuts = min(((volume(pieces_for(c, step)), c) for c in options), key=lambda option: option[0])
        if estimate < best_volume * (1 - SPLIT_GAIN) ** (k - 1 - len(best_cuts)):
            best_volume, best_cuts = estimate, cuts
    pieces = pieces_for(best_cuts, 1)
    bounds = [-np.inf, *best_cuts, np.inf]
    parts = [_clip_to_slab(mesh, long_axis, a, b) for a, b in zip(bounds[:-1], bounds[1:])]
    # a slab that only grazes the mesh at a corner holds nothing of area: no capsule for it
    pieces, parts = zip(*[(piece, part) for piece, part in zip(pieces, parts) if len(part.triangles)])
    slacks = _slacks(parts, pieces)
    return [
        FittedCapsule(tuple(float(x) for x in p0), tuple(float(x) for x in p1), float(r), s, part)
        for (p0, p1, r), s, part in zip(pieces, slacks, parts)
    ]


def _clip_to_slab(mesh: Mesh, axis: np.ndarray, a: float, b: float) -> Mesh:
    """The triangles of ``mesh`` clipped to the slab ``a <= vertices @ axis <= b`` (m; either side may be
    infinite). A triangle across a plane becomes the convex polygon of its corners inside the slab and its
    edges' crossings of the planes (the very points the slab's capsule was fitted to, by :func:`_crossing`'s
    formula), as a fan of triangles."""
    t = mesh.vertices @ axis
    tt = t[mesh.triangles]
    inside = ((tt >= a) & (tt <= b)).all(axis=1)
    outside = (tt < a).all(axis=1) | (tt > b).all(axis=1)
    kept = [mesh.vertices[mesh.triangles[inside]]]  # (F', 3, 3) corners
    for tri in mesh.triangles[~inside & ~outside]:
        corners, ts = mesh.vertices[tri], t[tri]
        points = [corners[k] for k in range(3) if a <= ts[k] <= b]
        for i, j in ((0, 1), (1, 2), (2, 0)):
            for c in (a, b):
                ti, tj = ts[i] - c, ts[j] - c
                if math.isfinite(c) and ti * tj < 0:
                    points.append(corners[i] + ti / (ti - tj) * (corners[j] - corners[i]))
        if len(points) < 3:
            continue  # the slab only grazes the triangle at a corner or an edge: nothing of area inside
        points = np.array(points)
        u = corners[1] - corners[0]
        normal = np.cross(u, corners[2] - corners[0])
        v = np.cross(normal, u)
        middle = points.mean(axis=0)
        order = np.argsort(np.arctan2((points - middle) @ v, (points - middle) @ u))
        ring = points[order]
        kept.append(np.stack([np.repeat(ring[:1], len(ring) - 2, axis=0), ring[1:-1], ring[2:]], axis=1))
    corners = np.concatenate(kept).reshape(-1, 3)
    if not len(corners):
        return Mesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
    vertices, index = np.unique(corners, axis=0, return_inverse=True)
    return Mesh(vertices, index.reshape(-1, 3).astype(np.int64))


def _crossing(vertices: np.ndarray, edges: np.ndarray, axis: np.ndarray, c: float) -> np.ndarray:
    """Where the ``edges`` (E, 2) of a mesh cross the plane ``vertices @ axis = c``."""
    a, b = vertices[edges[:, 0]], vertices[edges[:, 1]]
    ta, tb = a @ axis - c, b @ axis - c
    cross = ta * tb < 0
    w = (ta[cross] / (ta[cross] - tb[cross]))[:, None]
    return a[cross] + w * (b[cross] - a[cross])


def capsule_surface(p0: np.ndarray, p1: np.ndarray, radius: float, spacing: float) -> np.ndarray:
    """Points on the surface of a capsule at most about ``spacing`` apart (m)."""
    axis = p1 - p0
    length = float(np.linalg.norm(axis))
    w = axis / length if length > 0 else np.array([0.0, 0.0, 1.0])
    helper = np.eye(3)[int(np.argmin(np.abs(w)))]
    u = np.cross(w, helper)
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    n_ring = max(8, int(math.ceil(2 * math.pi * radius / spacing)))
    phi = np.linspace(0, 2 * math.pi, n_ring, endpoint=False)
    ring = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v  # (R, 3)
    n_len = max(2, int(math.ceil(length / spacing)) + 1)
    s = np.linspace(0, length, n_len)
    side = p0 + s[:, None, None] * w + radius * ring[None]
    n_lat = max(2, int(math.ceil(math.pi / 2 * radius / spacing)) + 1)
    theta = np.linspace(0, math.pi / 2, n_lat)
    caps = []
    for end, sign in ((p0, -1.0), (p1, 1.0)):
        caps.append(end + radius * (np.cos(theta)[:, None, None] * ring[None] + sign * np.sin(theta)[:, None, None] * w))
    return np.concatenate([side.reshape(-1, 3), caps[0].reshape(-1, 3), caps[1].reshape(-1, 3)])


def _slacks(parts: list[Mesh], capsules) -> list[float]:
    """Per capsule: the largest distance from its surface to its piece ``parts[i]`` [m] on a
    :data:`SLACK_GRID_M` grid, plus the grid spacing (see the module docstring)."""
    import coal

    point = coal.Sphere(1e-12)
    request, identity = coal.DistanceRequest(), coal.Transform3s()
    out = []
    for mesh, (p0, p1, r) in zip(parts, capsules):
        model = coal.BVHModelOBBRSS()
        model.beginModel(len(mesh.triangles), len(mesh.vertices))
        model.addVertices(np.ascontiguousarray(mesh.vertices, dtype=float))
        model.addTriangles(np.ascontiguousarray(mesh.triangles, dtype=np.int64))
        model.endModel()
        vertices = mesh.vertices[np.unique(mesh.triangles)]
        # any subset of the vertices bounds the distance from above: 2,000 of them keep the matrix below small
        vertices = vertices[:: max(1, len(vertices) // 2000)]
        v2 = np.einsum("ij,ij->i", vertices, vertices)
        spacing = max(SLACK_GRID_M, 2 * math.pi * r / 48)  # a bounded number of points per ring
        surface = capsule_surface(np.asarray(p0), np.asarray(p1), r, spacing)
        # the distance to the nearest vertex bounds the distance to the mesh from above: visit the surface
        # points in falling order of it and stop where it cannot beat the largest mesh distance found
        upper = np.empty(len(surface))
        for start in range(0, len(surface), 256):
            chunk = surface[start : start + 256]
            d2 = np.einsum("ij,ij->i", chunk, chunk)[:, None] + v2[None, :] - 2.0 * chunk @ vertices.T
            upper[start : start + 256] = np.sqrt(np.maximum(d2.min(axis=1), 0.0))
        worst = 0.0
        for i in np.argsort(-upper):
            if upper[i] <= worst:
                break
            result = coal.DistanceResult()
            coal.distance(point, coal.Transform3s(np.eye(3), surface[i]), model, identity, request, result)
            worst = max(worst, min(result.min_distance, upper[i]))
        out.append(float(worst + spacing))
    return out
