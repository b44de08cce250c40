"""Exact distances of a robot link's own collision mesh near contact. Metres.

A vendor arm's links are triangle meshes; the proximity kernel (:mod:`robocritics.geometry.proximity`) measures
the capsules fitted around them (:mod:`robocritics.robot.fit`): capsule ``i`` encloses the piece ``M_i`` of its
link's mesh (``robot.capsule_meshes[i]``, link frame) and, for anything ``A`` outside it,

    d(A, M_i) - slack_i  <=  d(A, capsule_i)  <=  d(A, M_i).

:func:`refine_near_contact` replaces a kernel row's value by the signed distance of the piece itself wherever
the capsule value is at most ``within_m``. The rule is that simple because the capsule distance is never above
the mesh's: every sample whose mesh distance is at most ``within_m`` has a capsule distance at most ``within_m``
and is refined. So after it

* every value at or below ``within_m`` is the mesh's (a threshold test up to ``within_m``, contact included,
  reads the mesh), and so is the least of a sample's values wherever that least is at most ``within_m``;
* every value above ``within_m`` is a lower bound of the mesh's: the capsule's (at most ``slack_i`` below),
  or a larger bound from the last exact value (:func:`_signed`).

The exact work is bounded by the slack: only samples whose mesh distance is below ``within_m + slack_i`` are
looked at (the others' capsules are farther than ``within_m``), and of those coal measures only the samples
that the last exact value and the motion since cannot prove farther than ``within_m``.

What is measured (coal, ``coal.distance``): the piece's bounding-volume hierarchy at the link's pose against
the other side of the pair: a scene primitive (box, cylinder, sphere) at its pose of that sample, a scene mesh
fixture's hierarchy, a capsule without a mesh (the tool's), or another link's piece (self pairs). Apart: the
exact distance (to :data:`GJK_TOLERANCE`); the least over a link's capsules is then the distance of its whole
mesh. Where the capsules are apart it is found through the pieces' hierarchies of hulls
(:mod:`robocritics.geometry.hull_tree`: a few hull calls and coal on a leaf's own triangles, the same value as
coal's call on the piece); a scene mesh fixture, and every sample whose capsules overlap, take coal's call. Crossing: coal's depth past the deepest touched triangle of the link's **whole** mesh (negative; the
other side's whole mesh too for a self pair), as coal reads the raw mesh: depth does not split over pieces
(part of a triangle can be shallower than the triangle).

A shape touching no triangle of the other side may still be wholly inside it: coal measures a piece and a
fixture as surfaces. Where the capsule value is at most 0 (the capsules overlap, so containment is possible:
each piece lies inside its capsule) and the mesh distance ``d`` is positive, the containment test of
:mod:`robocritics.geometry.meshes` (the winding number, for closed meshes) decides:

* the other side wholly inside this link's closed mesh (``robot.link_meshes``): ``-(d + 2 rho)``, the form
  a capsule in a closed fixture reads (``rho`` the radius of a ball it holds; 0 for a piece of mesh; ``d`` is
  measured to this capsule's piece, so the depth is a reading of the overlap, not a bound of it);
* this piece wholly inside a closed fixture or another link's closed mesh: ``-d`` (a surface holds no ball:
  every point of it is at least ``d`` deep, so no shorter translation takes it out).

Either way the value is below 0: a collision, as the capsules said.

Only rows of robot capsules are refined; the built-in arms' capsules are their geometry (no meshes), so their
values are untouched.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..scene import Shape
from .meshes import capsule_frames, inscribed_radius, is_closed, mesh_model, winding_numbers
from .pairs import coal_geometry
from .hull_tree import HullTree, hull_tree, primitive_tree, tree_distance

__all__ = ["refine_near_contact", "mesh_parts", "SAME_POSE_M", "GJK_TOLERANCE"]

#: A piece that moved by at most this much [m] relative to the other side since its last exact value keeps that
#: value (a self pair whose joints between held still, an arm at rest): below coal's GJK tolerance (1e-6 m).
SAME_POSE_M = 1e-9

#: coal's GJK tolerance for the exact values: against a cylinder, sphere or capsule they are good to ~1e-10 m
#: (against boxes and meshes GJK ends on the exact simplex anyway).
GJK_TOLERANCE = 1e-10


@dataclass(frozen=True)
class _Side:
    """One side of a pair over the refined samples: a coal ``geometry``, its ``poses (n, 4, 4)`` (base frame), the ``solid`` (vertices, triangles) a containment test may look
    inside (own frame; None: coal already treats it as solid, or it is open), the ``points (P, 3)`` (own
    frame) whose containment decides whether it is inside the other side, and ``rho`` (m) the radius of a
    ball about those points that it holds."""

    geometry: object
    poses: np.ndarray
    solid: tuple[np.ndarray, np.ndarray] | None
    points: np.ndarray
    rho: float
    piece: np.ndarray | None = None  # a piece's vertices (own frame), for its bounding ball
    whole: object = None  # a link's whole mesh (coal), measured instead of the piece where they overlap
    tree: HullTree | None = None  # a piece's hierarchy of hulls, or a primitive's one node: the fast path


_CACHE: dict[tuple[int, str], tuple[object, object]] = {}


def _cached(obj, make, what: str = ""):
    """``make()`` once per object and ``what`` (held, so its id stays its own)."""
    hit = _CACHE.get((id(obj), what))
    if hit is None or hit[0] is not obj:
        if len(_CACHE) > 512:
            _CACHE.clear()
        hit = _CACHE[(id(obj), what)] = (obj, make())
    return hit[1]


def _component_points(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """One vertex of every connected part of a triangle mesh ``(P, 3)``: a piece wholly on one side of a
    surface has each part on one side, so each part's vertex decides for it."""
    label = np.arange(len(vertices))
    while True:  # min-label propagation over the triangles, with pointer jumping: a few passes
        low = label[triangles].min(axis=1)
        new = label.copy()
        for k in range(3):
            np.minimum.at(new, triangles[:, k], low)
        new = new[new]
        if np.array_equal(new, label):
            break
        label = new
    used = np.unique(triangles)
    return vertices[np.unique(label[used])]


def mesh_parts(robot) -> list[tuple | None]:
    """Per capsule of ``robot``: ``(piece, link mesh)``, the piece of its link's mesh it encloses and that whole
    mesh (objects with ``vertices`` and ``triangles``, link frame), or None for a capsule that is its own
    geometry."""
    pieces = getattr(robot, "capsule_meshes", ())
    links = getattr(robot, "link_meshes", {})
    return [None if piece is None else (piece, links.get(capsule.frame, piece)) for capsule, piece in zip(robot.capsules, pieces)]


def refine_near_contact(
    rows: np.ndarray,
    pairs: Sequence[tuple[str, str]],
    robot,
    frames: np.ndarray,
    p0: np.ndarray,
    p1: np.ndarray,
    shapes: Sequence[Shape],
    poses: Mapping[str, np.ndarray],
    within_m: float,
) -> int:
    """Replace, in place, the values ``rows (K, T)`` (m; row k is ``pairs[k]``, a capsule name against a
    capsule or scene shape name, as :class:`~robocritics.geometry.proximity.ProximityKernel` takes them)
    that are at most ``within_m`` and belong to a capsule with a mesh piece by the piece's signed distance
    (the module docstring). ``frames (T, L, 4, 4)`` are the robot's link poses, ``p0``, ``p1`` ``(T, C, 3)``
    its capsule segments, ``poses`` the per-sample poses of moving shapes (by shape name or owner). Returns
    the number of values replaced."""
    parts = mesh_parts(robot)
    if not any(p is not None for p in parts):
        return 0
    capsule_index = {name: i for i, name in enumerate(robot.capsule_names)}
    frame_of = [robot.frame_names.index(c.frame) for c in robot.capsules]
    shape_of = {s.name: s for s in shapes}
    count = 0
    for k, (a, b) in enumerate(pairs):
        ia, ib = capsule_index.get(a), capsule_index.get(b)
        if ia is None:
            continue  # a carried object against the scene: no link in it
        if parts[ia] is None:
            if ib is None or parts[ib] is None:
                continue
            ia, ib = ib, ia
        near = np.flatnonzero(rows[k] <= within_m)
        if not len(near):
            continue
        this = _link_side(parts[ia], frames[near, frame_of[ia]])
        if ib is not None and parts[ib] is not None:
            other = _link_side(parts[ib], frames[near, frame_of[ib]])
        elif ib is not None:
            other = _capsule_side(p0[near, ib], p1[near, ib], float(robot.capsule_radii[ib]))
        else:
            other = _shape_side(shape_of[b], poses, near)
        rows[k, near] = _signed(this, other, rows[k, near], within_m)
        count += len(near)
    return count


def _link_side(part: tuple, poses: np.ndarray) -> _Side:
    piece, whole = part
    geometry = _cached(piece, lambda: coal_geometry("mesh", (piece.vertices, piece.triangles)))
    whole_geometry = _cached(whole, lambda: coal_geometry("mesh", (whole.vertices, whole.triangles)))
    closed = _cached(whole.triangles, lambda: is_closed(whole.vertices, whole.triangles))
    points = _cached(piece.triangles, lambda: _component_points(piece.vertices, piece.triangles))
    tree = _cached(piece, lambda: hull_tree(piece.vertices, piece.triangles), "tree")
    return _Side(geometry, poses, (whole.vertices, whole.triangles) if closed else None, points, 0.0,
                 piece=piece.vertices, whole=whole_geometry, tree=tree)


def _capsule_side(p0: np.ndarray, p1: np.ndarray, radius_m: float) -> _Side:
    """A capsule without a mesh: its frame per sample (z along the segment, origin at its middle)."""
    import coal

    rotations, centres, lengths = capsule_frames(p0, p1)
    poses = np.zeros((len(p0), 4, 4))
    poses[:, :3, :3], poses[:, :3, 3], poses[:, 3, 3] = rotations, centres, 1.0
    # a capsule is rigid (a finger's slides, keeping its length): one geometry, its length the mean (FK rounding)
    capsule = coal.Capsule(radius_m, float(lengths.mean()))
    return _Side(capsule, poses, None, np.zeros((1, 3)), radius_m, tree=primitive_tree(capsule))


def _shape_side(shape: Shape, poses: Mapping[str, np.ndarray], near: np.ndarray) -> _Side:
    key = shape.name if shape.name in poses else shape.owner
    at = np.asarray(poses[key], dtype=float)[near] if key in poses else np.broadcast_to(np.asarray(shape.pose, dtype=float), (len(near), 4, 4))
    if shape.kind == "mesh":
        vertices, triangles = shape.mesh
        solid = (vertices, triangles) if is_closed(vertices, triangles) else None
        return _Side(mesh_model(shape), at, solid, np.zeros((0, 3)), 0.0)
    geometry = coal_geometry(shape.kind, shape.size)
    return _Side(geometry, at, None, np.zeros((1, 3)), inscribed_radius(shape.kind, shape.size), tree=primitive_tree(geometry))


def _signed(this: _Side, other: _Side, capsule: np.ndarray, within_m: float) -> np.ndarray:
    """coal's signed distances ``(n,)`` of ``this`` (a piece) against ``other`` per sample, with the containment
    rule of the module docstring where ``capsule`` (the capsule values) is at most 0.

    Not every sample calls coal. With ``G_t`` the piece's pose in the other side's frame, between two samples
    every point of the piece moves by at most ``|R_t - R_s|_F rho + |G_t c - G_s c|`` (``c``, ``rho``: the
    centre and radius of a ball holding the piece), and the sum of those steps since the last exact value
    ``d`` bounds its motion ``m`` since then; distance is 1-Lipschitz, so the distance now is in
    ``[d - m, d + m]``. A sample keeps ``d`` when ``m <= SAME_POSE_M`` (the joints between held still), and the
    larger of ``d - m`` and its capsule value (lower bounds both) when ``d - m > within_m`` (the contract of
    :func:`refine_near_contact`: a value above ``within_m`` may be a lower bound); coal measures the others."""
    import coal

    n = len(this.poses)
    relative = np.linalg.inv(other.poses) @ this.poses  # (n, 4, 4): the piece in the other side's frame
    centre, rho = _ball(this)
    moved = relative[:, :3, :3] @ centre + relative[:, :3, 3]
    steps = np.zeros(n)
    steps[1:] = np.sqrt(((relative[1:, :3, :3] - relative[:-1, :3, :3]) ** 2).sum(axis=(1, 2))) * rho \
        + np.linalg.norm(moved[1:] - moved[:-1], axis=1)
    travelled = np.cumsum(steps).tolist()
    values = np.empty(n)
    request, result, identity = coal.DistanceRequest(), coal.DistanceResult(), coal.Transform3s()
    request.gjk_tolerance = GJK_TOLERANCE  # coal's default (1e-6) leaves ~1e-7 m against curved shapes
    last, d_last = -1, -np.inf
    for t in range(n):
        if last >= 0:
            motion = travelled[t] - travelled[last]
            if motion <= SAME_POSE_M:  # the joints between them held still (or the arm did)
                values[t] = d_last
                continue
            bound = d_last - motion  # the distance now is at least this
            if bound > within_m:
                values[t] = max(float(capsule[t]), bound)
                continue
        where = coal.Transform3s(np.ascontiguousarray(relative[t, :3, :3]), np.ascontiguousarray(relative[t, :3, 3]))
        # capsules apart (no containment to decide): the hierarchies of hulls (hull_tree), exact or a bound
        fast = None
        if capsule[t] > 0.0 and this.tree is not None and other.tree is not None:
            fast = tree_distance(this.tree, other.tree, relative[t], where, request, result, within_m)
        if fast is not None:
            # exact (the least over pairs of leaves), else a lower bound above within_m
            values[t] = d_last = fast[0] if fast[1] else max(float(capsule[t]), fast[0])
            last = t
            continue
        result.clear()
        d_last = coal.distance(this.geometry, where, other.geometry, identity, request, result)
        if d_last < 0:  # crossing: the link's whole triangles (a triangle split between pieces is deeper whole)
            result.clear()
            d_last = coal.distance(this.whole, where, other.whole or other.geometry, identity, request, result)
        if d_last > 0 and capsule[t] <= 0.0:  # touching nothing, yet the capsules overlap: inside?
            if _inside(other, this, t):  # the other side within this link's closed mesh
                d_last = -(d_last + 2.0 * other.rho)
            elif _inside(this, other, t):  # this piece within a closed fixture or another link's closed mesh
                d_last = -d_last
        values[t], last = d_last, t
    return values


def _ball(side: _Side) -> tuple[np.ndarray, float]:
    """Centre (own frame) and radius (m) of a ball holding a piece's vertices."""
    vertices = side.piece

    def make():
        middle = (vertices.max(axis=0) + vertices.min(axis=0)) / 2
        return middle, float(np.sqrt(((vertices - middle) ** 2).sum(axis=1).max()))

    return _cached(vertices, make)


def _inside(inner: _Side, outer: _Side, t: int) -> bool:
    """Whether any of ``inner``'s points is inside ``outer``'s closed solid at sample ``t``."""
    if outer.solid is None or not len(inner.points):
        return False
    vertices, triangles = outer.solid
    pa, pb = inner.poses[t], outer.poses[t]
    world = inner.points @ pa[:3, :3].T + pa[:3, 3]
    local = (world - pb[:3, 3]) @ pb[:3, :3]
    box = ((local >= vertices.min(axis=0)) & (local <= vertices.max(axis=0))).all(axis=1)
    return bool(box.any() and (np.abs(winding_numbers(local[box], vertices[triangles])) > 0.5).any())
