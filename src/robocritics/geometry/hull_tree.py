"""A hierarchy of convex hulls over a piece of link mesh: its exact distance from a few small hull calls. Metres.

coal measures a mesh of ``F`` triangles (its bounding-volume hierarchy) against a shape in ~0.5-2.5 ms for the
SO-100's 2,000-7,000-triangle pieces, and a convex hull against a shape in ~15 us
(:mod:`robocritics.geometry.piece_hulls`). The piece's hull alone gives the piece's distance only where its
witness is on the piece; in a dent it is only a lower bound. So the triangles are split: each node of a
:class:`HullTree` holds a set of triangles, its children the two halves of a median split of their centroids
along the longest axis of their box, down to leaves of at most :data:`LEAF_TRIANGLES`; each node has the
convex hull of its triangles (a :class:`~robocritics.geometry.piece_hulls.PieceHull`), which holds them, so

    d(A, hull(node))  <=  d(A, triangles(node))          (A apart from the hull)

and the piece's distance is the least over its leaves. :func:`tree_distance` searches best first over pairs of
nodes (one tree per side; a primitive is a tree of one node, its own hull, every witness on it): it takes the
pair of least lower bound; a pair whose two witnesses are on their nodes' triangles (``PieceHull.on_piece``)
has that bound as its exact distance (to :data:`~robocritics.geometry.piece_hulls.ON_PIECE_M`); a pair of leaves
not certified is measured by coal on the leaves' own triangles (a small hierarchy); any other pair is split
(its node of more triangles) into its children's pairs. It stops when the next lower bound is at least the
least exact value found: that value is the pieces' distance, the least over every pair of leaves.

Only pieces apart are measured: where a leaf pair crosses (coal's value at most 0) the search gives up (None),
and the caller measures the whole mesh (crossing depth is the whole mesh's, not a piece's).
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass

import numpy as np

from .piece_hulls import PieceHull, piece_hull

__all__ = ["HullNode", "HullTree", "hull_tree", "primitive_tree", "tree_distance", "LEAF_TRIANGLES"]

#: a node of at most this many triangles is a leaf, measured by coal on its own triangles when not certified
#: (SO-100 bench, one run each: 128 -> 1.37 s, 512 -> 1.18 s, 1024 -> 1.36 s per program; coal on 512 triangles
#: costs ~60 us, less than the Python of the pairs a deeper tree takes)
LEAF_TRIANGLES = 512


@dataclass(frozen=True)
class HullNode:
    """``hull``: the convex hull of the node's triangles and its certificate (None: they are flat, no hull with
    volume); ``geometry``: coal's geometry of the node's own triangles (a leaf's; for a primitive, the primitive);
    ``children``: indices of the two halves (None for a leaf); ``size``: its triangle count; ``exact``: every
    witness on its hull is on it (a primitive: the hull is the shape)."""

    hull: PieceHull | None
    geometry: object
    children: tuple[int, int] | None
    size: int
    exact: bool = False


@dataclass(frozen=True)
class HullTree:
    """The nodes of a piece, the root first."""

    nodes: tuple[HullNode, ...]


def hull_tree(vertices: np.ndarray, triangles: np.ndarray, leaf_triangles: int = LEAF_TRIANGLES) -> HullTree | None:
    """The :class:`HullTree` of the mesh ``vertices (N, 3)`` (m), ``triangles (F, 3)``; None for a flat piece."""
    from .pairs import coal_geometry

    vertices, triangles = np.asarray(vertices, dtype=float), np.asarray(triangles, dtype=np.int64)
    if piece_hull(vertices, triangles) is None:
        return None
    centroids = vertices[triangles].mean(axis=1)
    nodes: list[HullNode | None] = []

    def build(members: np.ndarray) -> int:
        index = len(nodes)
        nodes.append(None)
        used, local = np.unique(triangles[members], return_inverse=True)
        own = (vertices[used], local.reshape(-1, 3))
        hull = piece_hull(*own)
        if len(members) <= leaf_triangles:
            nodes[index] = HullNode(hull, coal_geometry("mesh", own), None, len(members))
            return index
        spread = np.ptp(centroids[members], axis=0)
        order = members[np.argsort(centroids[members, int(np.argmax(spread))], kind="stable")]
        half = len(order) // 2
        left, right = build(order[:half]), build(order[half:])
        nodes[index] = HullNode(hull, None, (left, right), len(members))
        return index

    build(np.arange(len(triangles)))
    return HullTree(tuple(nodes))


def primitive_tree(geometry) -> HullTree:
    """A convex coal primitive (box, cylinder, sphere, capsule) as a tree of one node: its own hull, exact."""
    return HullTree((HullNode(None, geometry, None, 1, exact=True),))


def tree_distance(a: HullTree, b: HullTree, relative: np.ndarray, where, request, result, within_m: float) -> tuple[float, bool] | None:
    """``(d, exact)``: the distance ``d`` (m) of the piece of ``a`` at ``where`` (a ``coal.Transform3s``, the pose
    ``relative (4, 4)`` of ``a``'s frame in ``b``'s) from ``b``'s piece, exact when ``exact`` (the module
    docstring); else ``d > within_m`` is a lower bound (the search stops once every pair left is farther than
    ``within_m``). None where a pair of leaves crosses. ``request``, ``result``: coal's, reused.

    A pair's witnesses are checked on its triangles only when it is taken from the queue (most pairs never are)."""
    import coal

    identity = coal.Transform3s()
    rotation, shift = relative[:3, :3], relative[:3, 3]

    def pair(i: int, j: int, floor: float) -> tuple[float, np.ndarray | None, np.ndarray | None]:
        """Pair (i, j)'s lower bound and its hulls' witnesses (in b's frame); ``floor`` and None where a side has
        no hull (flat triangles) or the hulls cross."""
        hp, q = a.nodes[i].hull, b.nodes[j]
        hq = q.geometry if q.exact else (q.hull.convex if q.hull else None)
        if hp is None or hq is None:
            return floor, None, None
        result.clear()
        d = coal.distance(hp.convex, where, hq, identity, request, result)
        if not d > 0:
            return floor, None, None
        # (a child's hull is inside its parent's: d >= floor but for rounding)
        return float(d), np.asarray(result.getNearestPoint1()), np.asarray(result.getNearestPoint2())

    best, order = np.inf, 0
    d, wa, wb = pair(0, 0, -np.inf)
    heap = [(d, 0, 0, 0, wa, wb)]  # (lower bound, tie-break, node of a, node of b, witnesses)
    while heap:
        low, _, i, j, pa, pb = heapq.heappop(heap)
        if low >= best:
            break
        if low > within_m:  # every pair left is farther than within_m: a lower bound is enough
            return low, False
        p, q = a.nodes[i], b.nodes[j]
        if pa is not None and p.hull.on_piece(rotation.T @ (pa - shift)) and (q.exact or q.hull.on_piece(pb)):
            best = low  # both witnesses on their triangles: the hulls' distance is the pair's
            continue
        if p.children is None and q.children is None:
            result.clear()
            d = coal.distance(p.geometry, where, q.geometry, identity, request, result)
            if not d > 0:
                return None
            best = min(best, float(d))
            continue
        split_a = q.children is None or (p.children is not None and p.size >= q.size)
        for child in (p.children if split_a else q.children):
            ci, cj = (child, j) if split_a else (i, child)
            d, wa, wb = pair(ci, cj, low)
            order += 1
            heapq.heappush(heap, (d, order, ci, cj, wa, wb))
    return best, True
