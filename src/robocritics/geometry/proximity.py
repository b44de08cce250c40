"""Exact signed distances between the robot's capsules and the scene's shapes, vectorised over samples.

Every length is in metres. A **capsule** is a segment ``p0``-``p1`` (base frame)
swept by a ball of radius ``r``; scene shapes are :class:`~robocritics.scene.Shape`
primitives: ``box`` (``size`` = full extents), ``cylinder`` (``size`` =
``[radius, height]``, axis along the shape's local z) and ``sphere``
(``size = [radius]``), each centred at its 4x4 ``pose``. A pose may also vary
per sample (``(T, 4, 4)``): an object the program moves.

**Signed distance.** For two convex sets A, B the signed distance is their
separation distance when they are apart and ``-(penetration depth)`` when they
overlap, the penetration depth being the length of the shortest translation that
separates them (coal's convention too). For a capsule ``A = S + ball(r)`` around
the segment ``S``::

    sd(A, B) = dist(S, B) - r                    if S does not touch B
    sd(A, B) = -(depth(S, B) + r)                if S meets B

(the Minkowski difference ``B - A`` is ``B - S`` grown by ``r``, so its boundary
is ``r`` further from the origin in every direction). Every capsule distance
thus reduces to the distance or the depth of a *segment*, computed here in
closed form or to machine precision:

* capsule-capsule: closest points of two segments (closed form with clamping,
  robust for parallel and zero-length segments); segments that meet have depth
  0, so ``segment distance - ra - rb`` is exact everywhere.
* capsule-sphere: point-segment distance minus both radii, exact everywhere.
* capsule-box: in the box frame ``f(t) = sum_i max(|a_i + t d_i| - h_i, 0)^2``
  (squared distance of the point ``a + t d``) is convex and piecewise quadratic,
  ``f'`` continuous, piecewise linear and non-decreasing. The slab intervals
  ``[l_i, u_i]`` (where the line is between the faces ``+-h_i``) give
  ``U = min u_i``, ``L = max l_i``: if ``L <= U`` the line passes through the box;
  otherwise the root of ``f'`` lies in ``[U, L]``, where only one axis can still
  switch, and is ``clip(t_mid, t_lo, t_hi)`` of three weighted means
  (:func:`_box_sq`), then clipped to [0, 1]: no sorting, no iteration. A segment
  meeting the box has the depth ``min_n h_Z(n)`` over the facet normals of the
  zonotope ``Z = box - segment`` (the box axes ``e_i`` and ``e_i x d``), also
  closed form (:func:`_seg_box_depth`).
* capsule-cylinder: ``F(t) = max(rho(t) - R, 0)^2 + max(|z(t)| - H, 0)^2`` is
  convex and C1 (``rho`` the distance to the axis). ``F'`` at the ends decides
  most pairs (closest point at an end of the segment); otherwise the root of the
  non-decreasing ``F'`` is found by Newton steps kept in a shrinking bracket
  (false position, then bisection, where Newton leaves it), to ``1e-12`` in ``t``
  or until ``F`` is provably within ``2e-24`` m^2 of its minimum: the distance is
  then good to ~1e-12 m (:func:`_cyl_sq`, :func:`_cyl_sq_inner`). A segment
  meeting the cylinder gets its depth from the finite candidate set of
  ``min_n h_Z(n)``: the caps, the radial directions of both endpoints, and the
  directions orthogonal to the segment, where the problem is the 2-D depth of
  a point in the cylinder's shadow along the segment (a rectangle capped by two
  half ellipses), the distance to a half ellipse using all stationary points
  (roots of a quartic, Newton-polished) and the arc's ends
  (:func:`_seg_cyl_depth`). coal's EPA is not used for this: on cylinders it is
  off by up to ~1e-4 m with its default settings (and by decimetres when its
  tolerance is tightened below 1e-6), and puts a sphere at a cylinder's centre
  out through the side when a cap is nearer.

Measured against coal (GJK at a 1e-12 tolerance; EPA for boxes and capsules)
the closed forms agree to ~1e-15 m, and against brute-force minimisation of the
support function to ~1e-12 m (``tests/test_proximity.py``).

Shape against shape (an object the gripper carries against the others): a
sphere against anything is a point-shape distance minus the radius, closed form
everywhere (a point inside a box or cylinder has the depth of its nearest
face). Box or cylinder against box or cylinder has no closed form in general,
but two closed-form bounds settle most real placements (:func:`_convex_bounds`):
the projection gap ``n.(c_B - c_A) - h_A(n) - h_B(n)`` along any unit ``n`` is
a lower bound of the signed distance (which is the maximum of the gap over
``n``), and the signed distance of any point of one shape to the other an upper
bound. Along the face normals and centre directions, with the support points of
the best one (and a round of alternating projections, :func:`_refine_bounds`),
the two meet to 1e-12 m whenever the nearest feature of one shape is a face of
the other: an object carried over the table, lowered into a bin or set on a
plate. The rest (a rim against an
edge, overlapping cylinders) goes to ``coal.distance``, once per run of samples
in which neither pose changes (~3 us per call), GJK to 1e-10 m when apart, EPA
when overlapping (boxes exact; cylinders to ~1e-5 m): on the six bundled
programs 3,551 of the 12,460 samples coal used to see (:func:`_shape_runs`).

:class:`ProximityKernel` batches it all for a trajectory: built once from the
capsules, the scene shapes, the pairs and the names of the shapes that move,
its :meth:`~ProximityKernel.distances` returns ``(T, K)`` signed distances for
capsule endpoints ``(T, C, 3)``. On a 10,000-sample UR3e trajectory (10
capsules, 27 self pairs, 150 capsule-shape pairs in the breakfast scene) it
takes about 40 ms on one core, and about 30 ms with ``far_m=0.1``
(``benchmarks/bench_proximity.py``: random motions, where most pairs are near).

**Far pairs** (``far_m``): per capsule and block of 32 samples, bounding balls of
the segments (:mod:`~robocritics.geometry.blocks`) give a lower bound of every
capsule/shape and capsule/capsule pair's distance; a pair is evaluated exactly only
in the blocks where that bound is within the cutoff, so on a real program (a few
per cent of the pairs near) most of the exact work is skipped. The cutoff rises per
sample to an upper bound of the least distance of each chosen column set
(``exact_min_of``: the trace's arm pairs and its self pairs), which keeps each
set's minimum exact: see :meth:`ProximityKernel.distances`. The near entries of
every capsule/shape group are gathered and evaluated in one kernel call per shape
kind (elementwise, so the numbers are those of a call per pair, bit for bit:
``tests/test_proximity_sets.py`` checks the pruned kernel against the plain one),
:data:`~robocritics.geometry.blocks.BATCH` entries at a time: the gathered copies and
their temporaries stay a few MB however long the run and however many of its blocks
are near, so the pruned kernel takes no more memory than the plain one (which works
in chunks), also with every block near (``far_m`` infinite).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .._arrays import unique_values
from ..scene import Shape
from .kernels import (
    _EYE3,
    _FLOAT,
    _box_prep,
    _box_sq,
    _cyl_sq,
    _cyl_sq_inner,
    _point_seg_sq,
    _seg_box_depth,
    _seg_cyl_depth,
    _seg_seg_sq,
    _to_local,
)
from .blocks import BATCH, BLOCK, blocks, capsule_balls, column_sets, fill_rows, lower_upper, near_entries, self_bounds
from .pairs import _bounding_radius, _pose_changes, _shape_runs, shape_shape

__all__ = ["CapsuleSpec", "ProximityKernel", "reduce_min"]

# ----------------------------------------------------------------------------------------------
# batch API
# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CapsuleSpec:
    """A robot capsule: its name and radius (m). Endpoints come per call."""

    name: str
    radius: float


@dataclass
class _Group:
    """Pairs evaluated together.

    ``product`` groups (capsules against box / cylinder / sphere shapes): capsules
    ``caps`` (Cg) against shapes that share one rotation ``rot`` (None = identity),
    evaluated shape by shape over all the group's capsules; ``rows[s]`` are the
    output rows of shape s for each capsule (-1: pair not requested) and ``views[s]``
    the same as a slice when they form one (results are then written in place). A
    product group of a ``moving`` shape has one shape whose pose comes per sample
    (``pose_key``). ``capsule`` groups are self pairs (``ia``, ``ib``), ``shape``
    groups shape-shape pairs (shape indices ``ia``, ``ib``); ``cols`` are the output
    rows of the pairs.
    """

    kind: str
    cols: np.ndarray
    product: bool = False
    caps: np.ndarray | None = None
    rows: list[np.ndarray] = field(default_factory=list)
    views: list[slice | None] = field(default_factory=list)
    rot: np.ndarray | None = None
    centre: tuple[list[float], ...] = ()
    size: tuple[list[float], ...] = ()
    r: np.ndarray | None = None
    ia: np.ndarray | None = None
    ib: np.ndarray | None = None
    pose_key: str | None = None


def reduce_min(distances: np.ndarray, groups: Sequence[Sequence[int]] | Mapping[Any, Sequence[int]]) -> np.ndarray:
    """Minimum (m) over column groups of ``distances (T, K)``: ``(T, G)``.

    One entity is often several shapes (a container's floor and four walls); its
    distance to a capsule is the least over its shapes. ``groups`` lists the
    column indices of each group (a mapping: its values, in order).
    """
    distances = np.asarray(distances)
    if isinstance(groups, Mapping):
        groups = list(groups.values())
    out = np.empty((distances.shape[0], len(groups)), dtype=distances.dtype)
    for g, cols in enumerate(groups):
        cols = list(cols)
        if not cols:
            raise ValueError(f"group {g} is empty")
        if len(cols) == 1:
            out[:, g] = distances[:, cols[0]]
        else:
            np.min(distances[:, cols], axis=1, out=out[:, g])
    return out


_DEPTH = {"box": _seg_box_depth, "cylinder": _seg_cyl_depth}

#: How many times longer the chunks of samples are when only the near blocks of a pair are evaluated
#: (:meth:`ProximityKernel._chunks`): 8 covers the bundled programs' trajectories (up to ~13,000 samples with the
#: UR3e's 10 capsules) in one chunk.
_FAR_CHUNKS = 8

def _rows_to_local(p: np.ndarray, Rc: np.ndarray, translate: bool = True) -> np.ndarray:
    """``R^T (p - c)`` (or ``R^T p``) per entry for points ``p (3, m)`` and poses given as the rows ``Rc (12, m)``
    of their ``[R c]`` entries (row-major: ``R[i][j]`` is row ``4 i + j``, ``c[i]`` row ``4 i + 3``): the same
    operations in the same order as :func:`~.kernels._to_local`, so the same values bit for bit."""
    px, py, pz = p
    if translate:
        px, py, pz = px - Rc[3], py - Rc[7], pz - Rc[11]
    return np.stack(
        [Rc[j] * px + Rc[4 + j] * py + Rc[8 + j] * pz for j in range(3)]
    )


def _rotate_back(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``R^T p`` for points ``p (3, ...)``, elementwise (``sum_i R[i, j] p_i``, in that order): the same numbers
    whatever the layout of ``p``, where a BLAS product may round differently for a different shape."""
    return np.stack([R[0, j] * p[0] + R[1, j] * p[1] + R[2, j] * p[2] for j in range(3)])


def _as_slice(rows: np.ndarray) -> slice | None:
    """``rows`` as an equivalent slice (for in-place output), or None."""
    if len(rows) == 0 or (rows < 0).any():
        return None
    step = int(rows[1] - rows[0]) if len(rows) > 1 else 1
    if step > 0 and np.array_equal(rows, rows[0] + step * np.arange(len(rows))):
        return slice(int(rows[0]), int(rows[-1]) + 1, step)
    return None


def _subgroup(g: _Group, keep: np.ndarray) -> _Group:
    """The product group ``g`` restricted to the capsules ``keep`` (a mask over ``g.caps``)."""
    rows = [rr[keep] for rr in g.rows]
    return replace(g, caps=g.caps[keep], rows=rows, views=[_as_slice(rr) for rr in rows], r=g.r[keep])


class _Batch:
    """Near entries of product groups gathered per shape kind and evaluated before they pass :data:`~.blocks.BATCH` (:meth:`ProximityKernel._flush`, then their deferred Newton and depth passes), so the gathered copies
    stay a few MB however many entries are near; each entry's value is the same whichever batch holds it."""

    def __init__(self, kernel: "ProximityKernel", buf: np.ndarray):
        self.kernel, self.buf = kernel, buf
        self.parts: dict[str, list] = {}
        self.count = 0

    def add(self, kind: str, part: tuple) -> None:
        """One shape's entries ``(a, d (3, m), centre, size, r (m,), where (m,))`` (see :meth:`ProximityKernel._flush`)."""
        m = part[0].shape[1]
        if self.count + m > BATCH:  # a batch holds at most BATCH entries (or one part, which near_entries bounds)
            self.flush()
        self.parts.setdefault(kind, []).append(part)
        self.count += m

    def flush(self) -> None:
        if self.parts:
            hits: dict = {}
            self.kernel._flush(self.parts, self.buf, hits)
            self.kernel._finish(self.buf, hits)
        self.parts, self.count = {}, 0


class ProximityKernel:
    """Signed distances (m) of many capsule and shape pairs over a whole trajectory, exact and vectorised.

    Built once from the capsules (``CapsuleSpec`` or ``(name, radius)``), the scene
    shapes and ``pairs`` of names ``(a, b)``:

    * ``(capsule, shape)``: a robot capsule against a scene shape;
    * ``(capsule, capsule)``: a self pair;
    * ``(shape, shape)``: two scene shapes (an object the gripper carries against
      the others): :func:`shape_shape`.

    ``moving`` names the shapes (by shape name or by owner, i.e. entity id) whose
    pose is given per sample at each :meth:`distances` call (objects the program
    moves); the others keep ``Shape.pose``. Names must be unique across capsules and
    shapes. Column k of the result is ``pairs[k]``; ``owners[k]`` is the entity of
    its b side (``Shape.owner``, or the capsule name) and :meth:`groups` gives the
    columns per ``(a, owner)`` for :func:`reduce_min` (a container's floor and
    walls are one entity).

    How it is fast: capsule/static-shape pairs are grouped by shape kind and
    rotation (a container's five boxes share one; upright objects and the table
    share the identity). Per group and chunk of samples, the capsules' segments are
    rotated into the shared frame and their per-segment terms (``1/d``, ``|d|^2``)
    computed once; then each shape is evaluated against all the group's capsules
    with its parameters as scalars on contiguous ``(Cg, n)`` arrays (``n`` about
    ``chunk / Cg`` samples, which keeps the temporaries in cache), writing straight
    into the output. A moving shape is one such group whose frame changes per
    sample. Penetrating samples (the segment meets the shape) and cylinder pairs
    whose closest point needs Newton steps are collected and solved in one batch
    each at the end.
    """

    def __init__(
        self,
        capsules: Sequence[CapsuleSpec | tuple[str, float]],
        shapes: Sequence[Shape],
        pairs: Sequence[tuple[str, str]],
        moving: Collection[str] = (),
        chunk: int = 16384,
    ):
        self.capsules = tuple(c if isinstance(c, CapsuleSpec) else CapsuleSpec(str(c[0]), float(c[1])) for c in capsules)
        self.shapes = tuple(shapes)
        self.chunk = int(chunk)
        cap_index = {c.name: i for i, c in enumerate(self.capsules)}
        shape_index = {s.name: i for i, s in enumerate(self.shapes)}
        if len(cap_index) != len(self.capsules):
            raise ValueError("capsule names must be unique")
        if len(shape_index) != len(self.shapes):
            raise ValueError("shape names must be unique")
        clash = set(cap_index) & set(shape_index)
        if clash:
            raise ValueError(f"names used by both a capsule and a shape: {sorted(clash)}")
        for s in self.shapes:
            if s.kind not in ("box", "cylinder", "sphere", "mesh"):
                raise ValueError(f"shape {s.name!r}: unknown kind {s.kind!r}; use box, cylinder, sphere or mesh")
        moving = set(moving)
        for s in self.shapes:
            if s.kind == "mesh" and (s.name in moving or s.owner in moving):
                raise ValueError(f"moving: {s.name!r} is a mesh, and a mesh is a fixture: it does not move")
        unknown = moving - set(shape_index) - {s.owner for s in self.shapes}
        if unknown:
            raise ValueError(f"moving: no shape or owner named {sorted(unknown)}")
        for name in moving - set(shape_index):
            parts = [s.name for s in self.shapes if s.owner == name]
            if len(parts) > 1:
                raise ValueError(f"moving: {name!r} is {len(parts)} shapes ({', '.join(parts)}); name the shapes, each with its own pose")
        # the key of the per-sample pose of each moving shape: its name if listed, else its owner
        self._pose_key = {
            s.name: (s.name if s.name in moving else s.owner) for s in self.shapes if s.name in moving or s.owner in moving
        }
        self.moving = frozenset(self._pose_key.values())
        self.radii = np.array([c.radius for c in self.capsules], dtype=_FLOAT)
        self.pairs = tuple((str(a), str(b)) for a, b in pairs)
        owners: list[str] = []
        static: dict[tuple[str, bytes], list[tuple[int, int, int]]] = {}
        movers: dict[int, list[tuple[int, int, int]]] = {}
        selfs: list[tuple[int, int, int]] = []
        shape_pairs: list[tuple[int, int, int]] = []
        rot_keys: dict[int, bytes] = {}  # shape index -> its rotation as a group key (b"": the identity)
        self._meshes: list[tuple[int, int, int]] = []  # (column, capsule or shape index, mesh shape index)
        for k, (a, b) in enumerate(self.pairs):
            if a in shape_index and self.shapes[shape_index[a]].kind == "mesh":
                a, b = b, a  # a mesh is measured from the other side (the distance is symmetric)
            if b in shape_index and self.shapes[shape_index[b]].kind == "mesh":
                self._meshes.append((k, cap_index[a] if a in cap_index else -1 - shape_index[a], shape_index[b]))
                owners.append(self.shapes[shape_index[b]].owner)
                continue
            if a in shape_index and b in shape_index:
                shape_pairs.append((k, shape_index[a], shape_index[b]))
                owners.append(self.shapes[shape_index[b]].owner)
                continue
            if a not in cap_index:
                raise ValueError(f"pair {k} {(a, b)}: {a!r} is not a capsule (have {', '.join(cap_index)})")
            ia = cap_index[a]
            if b in cap_index:
                selfs.append((k, ia, cap_index[b]))
                owners.append(b)
            elif b in shape_index:
                j = shape_index[b]
                s = self.shapes[j]
                owners.append(s.owner)
                if s.name in self._pose_key:
                    movers.setdefault(j, []).append((k, ia, j))
                    continue
                if j not in rot_keys:  # once per shape, not per (capsule, shape) pair
                    rot = np.asarray(s.pose, dtype=_FLOAT)[:3, :3]
                    rot_keys[j] = b"" if s.kind == "sphere" or np.array_equal(rot, _EYE3) else rot.tobytes()
                static.setdefault((s.kind, rot_keys[j]), []).append((k, ia, j))
            else:
                raise ValueError(f"pair {k} {(a, b)}: {b!r} is neither a capsule nor a scene shape")
        self.owners = tuple(owners)
        self._groups: list[_Group] = []
        for (kind, _), rows in static.items():
            caps = {r[1] for r in rows}
            shp = sorted({r[2] for r in rows})
            if len(rows) * 2 >= len(caps) * len(shp):
                self._groups.append(self._product_group(kind, rows))
            else:
                for j in shp:
                    self._groups.append(self._product_group(kind, [r for r in rows if r[2] == j]))
        for j, rows in movers.items():
            g = self._product_group(self.shapes[j].kind, rows)
            g.rot, g.centre, g.pose_key = None, ([0.0], [0.0], [0.0]), self._pose_key[self.shapes[j].name]
            self._groups.append(g)
        if selfs:
            ia = np.array([x[1] for x in selfs])
            ib = np.array([x[2] for x in selfs])
            self._groups.append(_Group("capsule", np.array([x[0] for x in selfs]), ia=ia, ib=ib, r=(self.radii[ia] + self.radii[ib])[:, None]))
        if shape_pairs:
            self._groups.append(
                _Group("shape", np.array([x[0] for x in shape_pairs]), ia=np.array([x[1] for x in shape_pairs]), ib=np.array([x[2] for x in shape_pairs]))
            )

    def _product_group(self, kind: str, rows: list[tuple[int, int, int]]) -> _Group:
        caps = sorted({r[1] for r in rows})
        shp = sorted({r[2] for r in rows})
        ci = {c: i for i, c in enumerate(caps)}
        out_rows = [np.full(len(caps), -1) for _ in shp]
        for k, c, j in rows:
            out_rows[shp.index(j)][ci[c]] = k
        views = [_as_slice(rr) for rr in out_rows]
        shapes = [self.shapes[j] for j in shp]
        rot = np.asarray(shapes[0].pose, dtype=_FLOAT)[:3, :3]
        rot = None if kind == "sphere" or np.array_equal(rot, _EYE3) else rot.copy()
        centres = np.array([np.asarray(s.pose, dtype=_FLOAT)[:3, 3] for s in shapes])  # (Sg, 3)
        if rot is not None:
            centres = centres @ rot  # R^T c, row by row
        if kind == "box":
            size = tuple([0.5 * float(s.size[i]) for s in shapes] for i in range(3))
        elif kind == "cylinder":
            size = ([float(s.size[0]) for s in shapes], [0.5 * float(s.size[1]) for s in shapes])
        else:
            size = ([float(s.size[0]) for s in shapes],)
        return _Group(
            kind,
            np.array([r[0] for r in rows]),
            product=True,
            caps=np.array(caps),
            rows=out_rows,
            views=views,
            rot=rot,
            centre=tuple(centres[:, i].tolist() for i in range(3)),
            size=size,
            r=self.radii[caps][:, None].copy(),
        )

    @property
    def names(self) -> list[str]:
        """Column labels ``"a|b"``."""
        return [f"{a}|{b}" for a, b in self.pairs]

    def groups(self) -> dict[tuple[str, str], list[int]]:
        """Columns per ``(a, owner of b)``: the shapes of one entity together, for :func:`reduce_min`."""
        out: dict[tuple[str, str], list[int]] = {}
        for k, ((a, _), owner) in enumerate(zip(self.pairs, self.owners)):
            out.setdefault((a, owner), []).append(k)
        return out

    def distances(
        self,
        p0: Any,
        p1: Any,
        poses: Mapping[str, Any] | None = None,
        far_m: float | None = None,
        exact_min_of: Sequence[int] | Sequence[Sequence[int]] | None = None,
    ) -> np.ndarray:
        """Signed distances ``(T, K)`` in m for capsule endpoints ``p0``, ``p1`` ``(T, C, 3)`` (base frame).

        ``poses`` gives the per-sample pose ``(T, 4, 4)`` of every ``moving`` name. The
        result is column-major (Fortran-ordered): each pair's column is contiguous.

        ``far_m=None`` (the default): every value is exact. With ``far_m >= 0`` set (m),
        the cutoff of column k at sample t is ``c_tk = far_m``, raised when ``exact_min_of``
        gives column sets (one list of columns is one set; a column belongs to at most one):
        ``u_tS`` is an upper bound of the least distance over set S at t, ``c_tk =
        max(far_m, u_tS)`` for k in S, and the first set's for a column in no set. Every value
        at or below its ``c_tk`` is exact; a value above it may instead be a *lower bound*
        that is itself above ``c_tk``. So any threshold test at or below ``far_m`` gives the
        exact answer, and the per-sample minimum over a set of columns X is exact at every
        sample when X holds the whole set of each of its columns (and the first set if it
        holds a column in no set): a bound in X is above a ``u_tS`` with S in X, so above the
        least distance over X. The bounds of a capsule/shape or
        capsule/capsule pair hold for a block of 32 samples (:func:`~.blocks.capsule_balls`:
        balls about the segments' midpoints, starts and ends over the block), so only the
        blocks that can be within the cutoff are evaluated exactly; for two boxes/cylinders
        (:func:`shape_shape`), a bounding ball's gap or a projection gap
        (:func:`_convex_bounds`). A shape pair with a sphere is always exact; a shape pair
        listed both ways round is bounded once (the distance is symmetric).
        """
        p0 = np.asarray(p0, dtype=_FLOAT)
        p1 = np.asarray(p1, dtype=_FLOAT)
        C = len(self.capsules)
        if p0.ndim != 3 or p0.shape[1:] != (C, 3) or p1.shape != p0.shape:
            raise ValueError(f"p0 and p1 must both be (T, {C}, 3) (one segment per capsule), got {p0.shape} and {p1.shape}")
        T = p0.shape[0]
        if far_m is not None and not far_m >= 0.0:
            raise ValueError(f"far_m must be >= 0 m (or None: every value exact), got {far_m}")
        set_of = None if far_m is None or exact_min_of is None else column_sets(exact_min_of, len(self.pairs))
        poses = dict(poses or {})
        for key in self.moving:
            if key not in poses:
                raise ValueError(f"poses[{key!r}] (T, 4, 4) is needed: {key!r} was declared moving")
            pose = poses[key] = np.asarray(poses[key], dtype=_FLOAT)
            if pose.shape != (T, 4, 4):
                raise ValueError(f"poses[{key!r}] must be (T, 4, 4) = ({T}, 4, 4), got {pose.shape}")
        buf = np.empty((len(self.pairs), T))
        # structure of arrays (3, C, T): one contiguous time series per capsule and coordinate
        P0 = np.ascontiguousarray(p0.transpose(2, 1, 0))
        D = np.ascontiguousarray((p1 - p0).transpose(2, 1, 0))
        groups = self._groups
        if T > 1:
            # capsules that do not move (a robot's base) against static shapes: one sample, broadcast
            still = (P0 == P0[:, :, :1]).all(axis=(0, 2)) & (D == D[:, :, :1]).all(axis=(0, 2))
            if still.any():
                groups, once = [], []
                for g in self._groups:
                    if not g.product or g.pose_key is not None:
                        groups.append(g)
                        continue
                    s = still[g.caps]
                    if s.any():
                        once.append(_subgroup(g, s))
                    if not s.all():
                        groups.append(_subgroup(g, ~s) if s.any() else g)
                if once:
                    buf1 = np.empty((len(self.pairs), 1))
                    self._run(once, P0[:, :, :1], D[:, :, :1], {}, None, buf1)  # one sample: exact
                    for g in once:
                        for rr in g.rows:
                            rr = rr[rr >= 0]
                            buf[rr] = buf1[rr]
        cuts = self._run(groups, P0, D, poses, far_m, buf, set_of)
        if self._meshes:
            cut = None if cuts is None else cuts[0][unique_values(cuts[1][[k for k, _, _ in self._meshes]])].max(axis=0)
            self._mesh_rows(p0, p1, poses, buf, cut)
        return buf.T

    def _mesh_rows(self, p0: np.ndarray, p1: np.ndarray, poses: dict, buf: np.ndarray, cut: np.ndarray | None) -> None:
        """The mesh columns (:mod:`robocritics.geometry.meshes`): coal where the bounding-ball bound is within ``cut``."""
        from .meshes import capsule_mesh, mesh_model, shape_mesh

        models = self.__dict__.setdefault("_mesh_models", {})
        for k, i, j in self._meshes:
            mesh = self.shapes[j]
            if j not in models:
                models[j] = mesh_model(mesh)
            if i >= 0:
                buf[k] = capsule_mesh(p0[:, i], p1[:, i], self.capsules[i].radius, mesh, models[j], cut)
                continue
            a = self.shapes[-1 - i]
            key = self._pose_key.get(a.name, "")
            Pa = poses[key] if key in poses else np.asarray(a.pose, dtype=_FLOAT)[None]
            buf[k] = np.broadcast_to(shape_mesh(a, mesh, Pa, np.asarray(mesh.pose, dtype=_FLOAT)[None]), (buf.shape[1],))

    def _run(
        self,
        groups: list[_Group],
        P0: np.ndarray,
        D: np.ndarray,
        poses: dict,
        far_m: float | None,
        buf: np.ndarray,
        set_of: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Evaluate ``groups`` for segments ``P0 + t D`` ``(3, C, T)`` into the rows of ``buf (K, T)``.

        With ``far_m``, a first pass writes every capsule/shape and capsule/capsule pair's block lower bound
        into ``buf`` and sets the cutoffs (:meth:`_cutoffs`); the second pass replaces the bounds that are
        ``<= c_t`` by exact values (:meth:`_product`, :meth:`_self_pairs`, then the batches and the deferred
        Newton and depth passes, :meth:`_finish`). The shape pairs come last (:meth:`_shape_pairs`): by then
        the capsule rows of each column set are exact wherever they can be its least distance, so their
        minimum (an upper bound of the set's least distance, and no larger than the block bound) lowers the
        shape pairs' cutoffs. Returns ``(cut, crow)`` (None without ``far_m``).
        """
        T = P0.shape[2]
        cut = crow = cut_b = None
        lbs: dict[tuple[int, int], Any] = {}
        if far_m is not None:
            cut, crow = self._cutoffs(groups, P0, D, poses, far_m, buf, set_of, lbs)
            cut_b = blocks(cut, -(-T // BLOCK)).max(axis=2)  # each cutoff row's largest per block
        hits: dict[str, list[tuple[np.ndarray, list[np.ndarray], np.ndarray]]] = {}
        batch = _Batch(self, buf)  # the near entries of the product groups, evaluated BATCH at a time
        for gi, g in enumerate(groups):
            if g.product:
                for t0, t1, pose in self._chunks(g, T, poses, far=cut is not None):
                    c = None if cut is None else cut[:, t0:t1]
                    self._product(g, P0, D, t0, t1, buf, hits, c, pose, lbs.get((gi, t0)), crow, batch)
            elif g.kind == "capsule":
                self._self_pairs(g, P0, D, buf, None if cut is None else cut_b[crow[g.cols]], lbs.get((gi, 0)))
        batch.flush()
        self._finish(buf, hits)
        shape_groups = [g for g in groups if g.kind == "shape"]
        if shape_groups:
            shape_cut = None
            if cut is not None:
                shape_cut = cut.copy()
                for s in range(len(cut) - 1):  # the exact minimum of each set's capsule rows so far
                    rows = [k for g in groups if g.kind != "shape" for k in g.cols.tolist() if set_of[k] == s]
                    if rows:  # row by row: no (rows, T) copy
                        least = buf[rows[0]].copy()
                        for k in rows[1:]:
                            np.minimum(least, buf[k], out=least)
                        np.minimum(shape_cut[s], np.maximum(least, far_m), out=shape_cut[s])
                if len(cut) > 1:
                    shape_cut[-1] = shape_cut[0]
            for g in shape_groups:
                self._shape_pairs(g, poses, buf, None if cut is None else shape_cut[unique_values(crow[g.cols])].max(axis=0))
        return None if cut is None else (cut, crow)

    def _cutoffs(self, groups, P0, D, poses, far_m, buf, set_of, lbs) -> tuple[np.ndarray, np.ndarray]:
        """The block bounds of every capsule/shape and capsule/capsule group (into ``buf`` and ``lbs``) and the
        cutoffs ``cut (S + 1, T)``: ``max(far_m, u_tS)`` per column set (``set_of (K,)``: each row's set, -1
        for none; ``u_tS`` the least block upper bound of the set's rows), then the row of the columns in no
        set (the first set's, or ``far_m``); and ``crow (K,)``, the cutoff row of each column."""
        T = P0.shape[2]
        n_sets = 0 if set_of is None else int(set_of.max(initial=-1)) + 1
        upper = np.full((n_sets, T), np.inf)  # u_tS: +inf (every value exact) until a bound of the set lowers it
        balls = None
        for gi, g in enumerate(groups):
            if g.product or g.kind == "capsule":
                if balls is None:
                    balls = capsule_balls(P0, D)
                if g.kind == "capsule":
                    tc = np.minimum(np.arange(-(-T // BLOCK)) * BLOCK + BLOCK // 2, T - 1)  # the balls' centres
                    a, d, b, e = P0[:, g.ia][:, :, tc], D[:, g.ia][:, :, tc], P0[:, g.ib][:, :, tc], D[:, g.ib][:, :, tc]
                    centre = np.sqrt(_seg_seg_sq(*a, *d, *b, *e)) - g.r  # exact at each block's centre sample
                    lbs[gi, 0] = self_bounds(balls, g.ia, g.ib, g.r, g.cols, buf, upper, set_of, centre)
                    continue
                for t0, t1, pose in self._chunks(g, T, poses, far=True):
                    lbs[gi, t0] = self._bounds(g, balls, t1 - t0, pose, buf, t0, upper, set_of)
        cut = np.empty((n_sets + 1, T))
        np.maximum(upper, far_m, out=cut[:n_sets])
        cut[n_sets] = far_m if n_sets == 0 else cut[0]  # the columns in no set: the first set's cutoffs
        crow = np.full(len(self.pairs), n_sets) if set_of is None else np.where(set_of >= 0, set_of, n_sets)
        return cut, crow

    def _self_pairs(self, g: _Group, P0: np.ndarray, D: np.ndarray, buf: np.ndarray, cut_b: np.ndarray | None, lb) -> None:
        """Capsule-capsule rows: where the cutoffs ``cut_b (P, blocks)`` (each row's largest per block) are given,
        only the blocks whose bound ``lb`` is within them, in flat batches (:func:`~.blocks.near_entries`); else
        every sample, in chunks."""
        T = P0.shape[2]
        if cut_b is not None:
            P2, D2 = P0.reshape(3, -1), D.reshape(3, -1)
            for pi, ti in near_entries(*np.nonzero(lb <= cut_b), T):
                flat_a, flat_b = g.ia[pi] * T + ti, g.ib[pi] * T + ti
                a, d = np.take(P2, flat_a, axis=1), np.take(D2, flat_a, axis=1)
                b, e = np.take(P2, flat_b, axis=1), np.take(D2, flat_b, axis=1)
                buf.reshape(-1)[g.cols[pi] * T + ti] = np.sqrt(_seg_seg_sq(*a, *d, *b, *e)) - g.r[pi, 0]
            return
        step = max(64, self.chunk // max(len(g.cols), 1))
        for t0 in range(0, T, step):
            t1 = min(T, t0 + step)
            a, d = P0[:, g.ia, t0:t1], D[:, g.ia, t0:t1]
            b, e = P0[:, g.ib, t0:t1], D[:, g.ib, t0:t1]
            buf[g.cols, t0:t1] = np.sqrt(_seg_seg_sq(*a, *d, *b, *e)) - g.r

    def _shape_pairs(self, g: _Group, poses: dict, buf: np.ndarray, cut: np.ndarray | None) -> None:
        """Shape-shape rows: a sphere in closed form once per run of equal poses, the others by
        :func:`_shape_runs` with the cutoffs ``cut (T,)`` (None: every value exact)."""
        T = buf.shape[1]
        changes: dict[tuple[str, ...], np.ndarray] = {}  # moving pose keys -> where any of them changes
        runs: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # id(changes[...]) -> run starts, run of each sample
        starts: dict[tuple[int, int], np.ndarray] = {}  # (id(poses), id(changes[...])) -> the poses at the run starts
        items, cols = [], []
        for col, i, j in zip(g.cols, g.ia, g.ib):
            a, b = self.shapes[i], self.shapes[j]
            ka, kb = self._pose_key.get(a.name, ""), self._pose_key.get(b.name, "")
            moved = tuple(sorted({ka, kb} & poses.keys()))
            for key in moved:
                if (key,) not in changes:
                    changes[key,] = _pose_changes(poses[key], T)
            if moved not in changes:  # one array per set of moving poses: _shape_runs shares its runs
                changes[moved] = np.logical_or.reduce([changes[key,] for key in moved]) if moved else _pose_changes(a.pose[None], T)
            changed = changes[moved]
            Pa = poses[ka] if ka in poses else np.asarray(a.pose, dtype=_FLOAT)[None]
            Pb = poses[kb] if kb in poses else np.asarray(b.pose, dtype=_FLOAT)[None]
            if a.kind == "sphere" or b.kind == "sphere":  # closed form, exact: once per run of equal poses
                if id(changed) not in runs:  # the runs and the poses at their starts: once per pose key
                    runs[id(changed)] = np.flatnonzero(changed), np.cumsum(changed) - 1
                first, run = runs[id(changed)]
                at = []
                for P in (Pa, Pb):
                    if len(P) > 1 and (id(P), id(changed)) not in starts:
                        starts[id(P), id(changed)] = P[first]
                    at.append(P if len(P) == 1 else starts[id(P), id(changed)])
                v = shape_shape(a, b, *at)
                if len(v) == 1:
                    buf[col] = v[0]
                else:
                    np.take(v, run, out=buf[col])
                continue
            items.append((a, b, Pa, Pb, changed))
            cols.append(col)
        if items:
            for col, v in zip(cols, _shape_runs(items, cut)):
                buf[col] = v

    @staticmethod
    def _finish(buf: np.ndarray, hits: dict) -> None:
        """The deferred work, one batch each: cylinder pairs whose closest point is interior (Newton), then the
        depths of the segments that meet a shape."""
        flat = buf.reshape(-1)
        pending = hits.pop("cylinder-inner", None)
        if pending:
            where = np.concatenate([e[0] for e in pending])
            args = [np.concatenate([e[1][i] for e in pending]) for i in range(11)]
            r = np.concatenate([e[2] for e in pending])
            sq = _cyl_sq_inner(*args, tol=1e-12, max_iter=100)
            flat[where] = np.sqrt(sq) - r
            z = sq == 0.0
            if z.any():
                hits.setdefault("cylinder", []).append((where[z], [args[i][z] for i in (0, 1, 2, 3, 4, 5, 9, 10)], r[z]))
        for kind, entries in hits.items():
            where = np.concatenate([e[0] for e in entries])
            args = [np.concatenate([e[1][i] for e in entries]) for i in range(len(entries[0][1]))]
            r = np.concatenate([e[2] for e in entries])
            flat[where] = -_DEPTH[kind](*args) - r

    def _chunks(self, g: _Group, T: int, poses: dict, far: bool = False):
        """``(t0, t1, pose)`` chunks of a product group: about ``chunk`` pair-samples each, keeping temporaries in cache.

        ``far``: the chunks of the block-bound pass, where only the near blocks are gathered into flat batches
        (a few per cent of the pair-samples): :data:`_FAR_CHUNKS` times longer, so the per-shape work of the
        bounds and the gathers runs over fewer, longer arrays.
        """
        step = max(64, (_FAR_CHUNKS if far else 1) * self.chunk // max(len(g.caps), 1)) // BLOCK * BLOCK
        for t0 in range(0, T, step):
            t1 = min(T, t0 + step)
            yield t0, t1, (poses[g.pose_key][t0:t1] if g.pose_key is not None else None)

    @staticmethod
    def _local(g: _Group, a: np.ndarray, d: np.ndarray, pose: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Segment starts and directions ``(3, Cg, n)`` in the frame of the group's shapes."""
        if pose is not None and g.kind == "sphere":  # a ball has no orientation: p - c per sample is enough
            return a - np.ascontiguousarray(pose[:, :3, 3].T)[:, None, :], d
        if pose is not None:  # R^T (p - c) per sample, broadcast over the capsules
            R, c = pose[:, :3, :3], pose[:, :3, 3]
            return np.stack(_to_local(a[0], a[1], a[2], R, c)), np.stack(_to_local(d[0], d[1], d[2], R, c, translate=False))
        if g.rot is not None:
            return _rotate_back(g.rot, a), _rotate_back(g.rot, d)  # R^T p: into the shapes' frame
        return a, d

    def _bounds(self, g, balls_all, n_chunk, pose, buf, t0, upper, set_of) -> list:
        """Block bounds of a box or cylinder product group for the samples ``t0 ..`` (base frame ``a``, ``d``).

        Per capsule and block of :data:`BLOCK` samples, the balls ``(c, rho)`` that hold the segment
        midpoints (``rho``: their farthest one plus its half length) and the start and end points. Every
        point of the capsule is then within ``rho + r`` of ``c``, and the capsule holds the ball of radius
        ``r`` about each of those points; ``e`` (the distance outside the shape, 0 inside) is 1-Lipschitz, so
        at every sample of the block::

            e(c_mid) - rho_mid - r  <=  signed distance  <=  min over mid, start, end of e(c) + rho' - r

        (``rho'`` without the half length; the left side is used only where it is positive). A shape that
        moves is bounded by the ball of its centre's path over the block plus its bounding radius. The lower
        bound goes to ``buf`` (and is returned per shape, ``(Cg, blocks)``); the upper bound of the rows in a
        column set (``set_of``) lowers that set's ``upper (S, T)`` (:func:`~.blocks.lower_upper`).
        """
        n = n_chunk
        b0, nb = t0 // BLOCK, -(-n // BLOCK)  # chunks start on a block
        balls = [(c[:, g.caps, b0 : b0 + nb], rho[g.caps, b0 : b0 + nb]) for c, rho in balls_all]
        if pose is not None:  # the shape's centre over each block: a ball about the middle of its extent
            sc = blocks(np.ascontiguousarray(pose[:, :3, 3].T)[:, None, :], nb)[:, 0]  # (3, nb, B)
            s_c = 0.5 * (sc.min(axis=2) + sc.max(axis=2))
            s_rho = np.sqrt(np.einsum("inb,inb->nb", sc - s_c[..., None], sc - s_c[..., None])).max(axis=1)
            s_rho += _bounding_radius(g.kind, self._size_of(g))
        elif g.rot is not None:
            balls = [(np.tensordot(g.rot.T, c, axes=1), rho) for c, rho in balls]
        r = g.r
        if pose is None:
            return self._static_bounds(g, balls, n, buf, t0, upper, set_of)
        out = []
        for s in range(len(g.centre[0])):
            rows = g.rows[s]
            keep = rows >= 0
            if pose is not None:
                e = [np.maximum(np.sqrt(np.einsum("icn,icn->cn", c - s_c[:, None], c - s_c[:, None])) - s_rho, 0.0) for c, _ in balls]
                e_ub = [np.sqrt(np.einsum("icn,icn->cn", c - s_c[:, None], c - s_c[:, None])) + s_rho for c, _ in balls]
            else:
                e = [self._outside(g.kind, c, g, s) for c, _ in balls]
                e_ub = e
            lb = e[0] - balls[0][1] - r
            fill_rows(buf, rows[keep], lb[keep], t0, n)
            out.append(lb)
            if set_of is not None:
                sel = keep.copy()
                sel[keep] = set_of[rows[keep]] >= 0
                if sel.any():
                    ub = np.minimum.reduce([(x + rho)[sel] for x, (_, rho) in zip(e_ub, balls)]) - r[sel]
                    lower_upper(upper, set_of[rows[sel]], ub, t0, n)
        return out

    @staticmethod
    def _static_bounds(g, balls, n, buf, t0, upper, set_of) -> list:
        """:meth:`_bounds` for a group of static shapes: every shape at once, ``(S, Cg, blocks)`` arrays."""
        S = len(g.centre[0])
        centre = [np.asarray(v, dtype=_FLOAT)[:, None, None] for v in g.centre]
        size = [np.asarray(v, dtype=_FLOAT)[:, None, None] for v in g.size]
        e = [ProximityKernel._outside_all(g.kind, c, centre, size) for c, _ in balls]
        lb = e[0] - balls[0][1] - g.r  # (S, Cg, nb)
        rows = np.stack(g.rows)  # (S, Cg)
        keep = rows >= 0
        fill_rows(buf, rows[keep], lb[keep], t0, n)
        if set_of is not None:
            sel = keep & (set_of[np.where(keep, rows, 0)] >= 0)
            if sel.any():
                ub = np.minimum.reduce([(x + rho)[sel] for x, (_, rho) in zip(e, balls)])
                ub -= np.broadcast_to(g.r, (S,) + g.r.shape)[sel]
                lower_upper(upper, set_of[rows[sel]], ub, t0, n)
        return list(lb)

    @staticmethod
    def _outside_all(kind: str, p, centre, size) -> np.ndarray:
        """Distance (m) of the points ``p`` (x, y, z in the shapes' frame) outside each shape, 0 inside: ``centre``
        and ``size`` (half sizes) per coordinate, scalars for one shape or ``(S, 1, 1)`` arrays for several."""
        ex = [np.abs(v - ci) for v, ci in zip(p, centre)]
        if kind == "sphere":
            out = np.maximum(np.sqrt(ex[0] ** 2 + ex[1] ** 2 + ex[2] ** 2) - size[0], 0.0)
            return out
        if kind == "box":
            out = sum(np.maximum(e - h, 0.0) ** 2 for e, h in zip(ex, size))
        else:
            rad = np.maximum(np.sqrt(ex[0] ** 2 + ex[1] ** 2) - size[0], 0.0)
            out = rad * rad + np.maximum(ex[2] - size[1], 0.0) ** 2
        return np.sqrt(out, out=out)

    @staticmethod
    def _size_of(g: _Group) -> list[float]:
        """The size of a moving group's one shape, as :class:`Shape` gives it (full extents, radius, ...)."""
        if g.kind == "box":
            return [2.0 * v[0] for v in g.size]
        if g.kind == "cylinder":
            return [g.size[0][0], 2.0 * g.size[1][0]]
        return [g.size[0][0]]

    @staticmethod
    def _outside(kind: str, p, g: _Group, s: int) -> np.ndarray:
        """Distance (m) of the points ``p`` (x, y, z in the group's frame) outside shape ``s`` of ``g``, 0 inside."""
        return ProximityKernel._outside_all(kind, p, [c[s] for c in g.centre], [v[s] for v in g.size])

    @staticmethod
    def _collect(hits, kind, sq, loc, a, d, c, size, r):
        """Record the samples where a segment meets a shape (``sq == 0``) for the batched depth pass.

        ``loc(ci, ti)``: the flat output indices of the entries ``(ci, ti)`` of ``sq`` (-1: not requested).
        """
        ci, ti = np.nonzero(sq == 0.0)
        where = loc(ci, ti)
        keep = where >= 0
        if not keep.all():
            ci, ti, where = ci[keep], ti[keep], where[keep]
        if not ci.size:
            return
        args = [np.broadcast_to(a[i], sq.shape)[ci, ti] - np.broadcast_to(c[i], sq.shape)[ci, ti] for i in range(3)]
        args += [np.broadcast_to(d[i], sq.shape)[ci, ti] for i in range(3)]
        args += [np.broadcast_to(np.asarray(v, dtype=_FLOAT), sq.shape)[ci, ti] for v in size]
        hits.setdefault(kind, []).append((where, args, np.broadcast_to(r, sq.shape)[ci, ti]))

    @staticmethod
    def _defer_inner(hits, pending, loc, r, shape):
        """Record the cylinder pairs whose minimiser is interior for the batched Newton pass."""
        (ci, ti), sub = pending
        where = loc(ci, ti)
        keep = where >= 0
        if not keep.all():
            ci, ti, where, sub = ci[keep], ti[keep], where[keep], [v[keep] for v in sub]
        hits.setdefault("cylinder-inner", []).append((where, sub, np.broadcast_to(r, shape)[ci, ti]))

    def _product(
        self,
        g: _Group,
        P0: np.ndarray,
        D: np.ndarray,
        t0: int,
        t1: int,
        buf: np.ndarray,
        hits: dict,
        cut: np.ndarray | None,
        pose: np.ndarray | None,
        lbs: list | None = None,
        crow: np.ndarray | None = None,
        batch: _Batch | None = None,
    ) -> None:
        """Evaluate one product group for the samples ``t0 .. t1``; ``P0``, ``D``: ``(3, C, T)`` segment starts and
        directions of every capsule.

        ``pose (n, 4, 4)``: the per-sample pose of a moving group's shape. ``cut (R, n)``: :meth:`_bounds` has
        written block lower bounds ``lbs`` into ``buf``; only the blocks whose bound is ``<= cut[crow[k]]``
        (row k's cutoff) somewhere in the block are evaluated exactly, the others keep their bound: the near
        entries of every shape go into ``batch`` (:class:`_Batch`: evaluated per kind, :data:`~.blocks.BATCH` at a
        time).
        """
        T = buf.shape[1]
        n = t1 - t0
        r = g.r
        if cut is not None:
            cut_b = blocks(cut, lbs[0].shape[1]).max(axis=2)  # (R, nb): each cutoff row's largest per block
            # flat takes of the entries straight from (3, C * T): no (3, Cg, n) copy of the group's capsules
            Tp = P0.shape[2]
            a2, d2 = np.ascontiguousarray(P0).reshape(3, -1), np.ascontiguousarray(D).reshape(3, -1)
            base = g.caps * Tp + t0
            if pose is not None:  # the pose's [R c] entries as contiguous rows (12, n): one take per batch
                rc = np.ascontiguousarray(pose[:, :3, :].reshape(n, 12).T)
            for s, lb in enumerate(lbs):
                rows = g.rows[s]
                near = lb <= cut_b[crow[np.maximum(rows, 0)]]
                near &= (rows >= 0)[:, None]
                c = tuple(v[s] for v in g.centre)
                size = tuple(v[s] for v in g.size)
                for ci, ti in near_entries(*np.nonzero(near), n):
                    flat_i = base[ci] + ti  # (3, m): one flat batch of (capsule, sample) entries
                    ga, gd = np.take(a2, flat_i, axis=1), np.take(d2, flat_i, axis=1)
                    if pose is not None and g.kind == "sphere":  # as :meth:`_local`: a ball needs only p - c
                        ga = ga - np.take(rc[3::4], ti, axis=1)
                    elif pose is not None:
                        Rc = np.take(rc, ti, axis=1)
                        ga, gd = _rows_to_local(ga, Rc), _rows_to_local(gd, Rc, translate=False)
                    elif g.rot is not None:
                        ga, gd = _rotate_back(g.rot, ga), _rotate_back(g.rot, gd)
                    batch.add(g.kind, (ga, gd, c, size, r[ci, 0], rows[ci] * T + t0 + ti))
            return
        a, d = self._local(g, P0[:, g.caps, t0:t1], D[:, g.caps, t0:t1], pose)
        if n == 1 and pose is None:  # one sample (capsules that stand still): a few entries per shape, batched
            for s in range(len(g.centre[0])):
                rows = g.rows[s]
                ci = np.flatnonzero(rows >= 0)
                c = tuple(v[s] for v in g.centre)
                size = tuple(v[s] for v in g.size)
                batch.add(g.kind, (a[:, ci, 0], d[:, ci, 0], c, size, r[ci, 0], rows[ci] * T + t0))
            return
        aux = self._prep(g.kind, d)
        for s in range(len(g.centre[0])):
            c = tuple(ci[s] for ci in g.centre)
            size = tuple(v[s] for v in g.size)
            rows = g.rows[s]
            view = g.views[s]
            o = buf[view, t0 : t0 + n] if view is not None else np.empty((len(rows), n))

            def loc(ci, ti, rows=rows):
                rr = rows[ci]
                return np.where(rr >= 0, rr * T + t0 + ti, -1)

            self._shape_eval(g.kind, a, d, aux, c, size, r, loc, hits, o)
            if view is None:
                keep = rows >= 0
                buf[rows[keep], t0 : t0 + n] = o[keep]

    def _flush(self, batch: dict, buf: np.ndarray, hits: dict) -> None:
        """Evaluate the near entries that :meth:`_product` gathered, one kernel call per shape kind: ``batch[kind]``
        lists ``(a, d (3, m) in the shape's frame, centre, size (scalars), r (m,), where (m,) flat output index)``.
        Elementwise, so every value is the one a call per shape gives, bit for bit."""
        flat = buf.reshape(-1)
        for kind, parts in batch.items():
            a = np.concatenate([p[0] for p in parts], axis=1)[:, None, :]
            d = np.concatenate([p[1] for p in parts], axis=1)[:, None, :]
            count = [p[0].shape[1] for p in parts]
            c = tuple(np.repeat([p[2][i] for p in parts], count)[None] for i in range(3))
            size = tuple(np.repeat([p[3][i] for p in parts], count)[None] for i in range(len(parts[0][3])))
            r = np.concatenate([p[4] for p in parts])[None]
            where = np.concatenate([p[5] for p in parts])
            o = np.empty((1, len(where)))
            self._shape_eval(kind, a, d, self._prep(kind, d), c, size, r, lambda ci, ti: where[ti], hits, o)
            flat[where] = o[0]

    @staticmethod
    def _prep(kind: str, d: np.ndarray):
        """The per-segment terms of a kind's kernel for directions ``d (3, ...)``."""
        dx, dy, dz = d
        if kind == "box":
            return _box_prep(dx, dy, dz)
        aux = dx * dx
        aux += dy * dy
        if kind == "cylinder":
            return aux
        aux += dz * dz
        aux += 1e-300
        return np.divide(1.0, aux, out=aux)

    def _shape_eval(self, kind, a, d, aux, c, size, r, loc, hits, o) -> None:
        """Signed distances ``o (k, n)`` of segments ``a + t d`` ``(3, k, n)`` (shape frame) to one shape."""
        ax, ay, az = a
        dx, dy, dz = d
        if kind == "box":
            sq = _box_sq(ax, ay, az, dx, dy, dz, aux, *c, *size)
        elif kind == "cylinder":
            sq, pending = _cyl_sq(ax, ay, az, dx, dy, dz, aux, *c, *size, defer=True)
            if pending is not None:
                self._defer_inner(hits, pending, loc, r, sq.shape)
        else:
            sq = _point_seg_sq(*c, ax, ay, az, dx, dy, dz, aux)
        np.sqrt(sq, out=o)
        if kind == "sphere":
            o -= size[0]
        elif sq.min() == 0.0:
            self._collect(hits, kind, sq, loc, a, d, c, size, r)
        o -= r