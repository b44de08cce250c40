"""A uniform grid over a set of triangles: the few that can lie within a tolerance of a point. Metres.

Each triangle's axis-aligned box, grown by ``margin`` on every side, is entered in every grid cell it overlaps.
A triangle within ``margin`` of a point ``p`` has ``p`` inside that grown box, so it is entered in ``p``'s cell:
:meth:`TriangleGrid.near` returns a superset of the triangles within ``margin`` of ``p`` (those it leaves out
are farther), at the cost of one cell look-up instead of a scan of every triangle.

The cell edge is the smallest (of a few tried) for which the triangles' cell entries stay under
:data:`ENTRIES_PER_TRIANGLE` a triangle on average: a long thin triangle across the piece enters many cells, so
a mesh of a few large faces gets a coarse grid (few cells, where a scan is cheap anyway).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["TriangleGrid", "triangle_grid", "ENTRIES_PER_TRIANGLE"]

#: the grid's budget of cell entries per triangle (mean): bounds its memory at build time
ENTRIES_PER_TRIANGLE = 8


@dataclass(frozen=True)
class TriangleGrid:
    """``origin (3,)`` (m) the grid's low corner, ``cell`` (m) its cell edge, ``shape`` cells per axis;
    ``cells``: each cell's number ``ix + sx (iy + sy iz)`` to the triangles entered in it."""

    origin: tuple[float, float, float]
    cell: float
    shape: tuple[int, int, int]
    cells: dict[int, np.ndarray]

    def near(self, p) -> np.ndarray:
        """The indices of the triangles entered in the cell of ``p (3,)`` (m): every triangle within the grid's
        margin of ``p`` is among them. Empty outside the grid."""
        x, y, z = (float(v) for v in p)  # in scalars: a call costs a dictionary look-up, not numpy's overheads
        ix, iy, iz = (math.floor((x - self.origin[0]) / self.cell), math.floor((y - self.origin[1]) / self.cell),
                      math.floor((z - self.origin[2]) / self.cell))
        sx, sy, sz = self.shape
        if not (0 <= ix < sx and 0 <= iy < sy and 0 <= iz < sz):
            return _NONE
        return self.cells.get(ix + sx * (iy + sy * iz), _NONE)


_NONE = np.zeros(0, dtype=np.int64)


def triangle_grid(corners: np.ndarray, margin: float) -> TriangleGrid:
    """The :class:`TriangleGrid` of triangles ``corners (F, 3, 3)`` (m) for points within ``margin`` (m)."""
    corners = np.asarray(corners, dtype=float).reshape(-1, 3, 3)
    lo, hi = corners.min(axis=1) - margin, corners.max(axis=1) + margin
    origin = lo.min(axis=0) if len(lo) else np.zeros(3)
    extent = float((hi.max(axis=0) - origin).max()) if len(lo) else 1.0
    for cells in (64, 32, 16, 8, 4, 2, 1):  # finest first, until the entries fit the budget
        cell = max(extent, 1e-300) / cells
        first = np.floor((lo - origin) / cell).astype(np.int64)
        last = np.floor((hi - origin) / cell).astype(np.int64)
        span = last - first + 1
        if span.prod(axis=1).sum() <= ENTRIES_PER_TRIANGLE * max(len(corners), 1) or cells == 1:
            break
    shape = np.maximum(last.max(axis=0) + 1, 1) if len(lo) else np.ones(3, np.int64)
    # every (triangle, cell) entry at once: entry k of triangle t is its box's cell (k mod sx, k // sx mod sy, ...)
    count = span.prod(axis=1)
    members = np.repeat(np.arange(len(corners), dtype=np.int64), count)
    k = np.arange(int(count.sum()), dtype=np.int64) - np.repeat(np.cumsum(count) - count, count)
    sx, sy = span[members, 0], span[members, 1]
    x, y, z = first[members, 0] + k % sx, first[members, 1] + (k // sx) % sy, first[members, 2] + k // (sx * sy)
    keys = x + shape[0] * (y + shape[1] * z)
    order = np.argsort(keys, kind="stable")
    keys, members = keys[order], members[order]
    starts = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]]) if len(keys) else np.zeros(0, np.int64)
    ends = np.r_[starts[1:], len(keys)]
    cells = {int(keys[lo]): members[lo:hi] for lo, hi in zip(starts.tolist(), ends.tolist())}
    return TriangleGrid(tuple(origin.tolist()), float(cell), tuple(int(v) for v in shape), cells)
