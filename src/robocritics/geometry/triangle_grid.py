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

from dataclasses import dataclass

import numpy as np

__all__ = ["TriangleGrid", "triangle_grid", "ENTRIES_PER_TRIANGLE"]

#: the grid's budget of cell entries per triangle (mean): bounds its memory at build time
ENTRIES_PER_TRIANGLE = 8


@dataclass(frozen=True)
class TriangleGrid:
    """``origin (3,)`` (m) the grid's low corner, ``cell`` (m) its cell edge, ``shape (3,)`` cells per axis;
    ``keys (E,)`` sorted cell numbers and ``members (E,)`` the triangle of each entry."""

    origin: np.ndarray
    cell: float
    shape: np.ndarray
    keys: np.ndarray
    members: np.ndarray

    def near(self, p: np.ndarray) -> np.ndarray:
        """The indices of the triangles entered in the cell of ``p (3,)`` (m): every triangle within the grid's
        margin of ``p`` is among them. Empty outside the grid."""
        index = np.floor((np.asarray(p, dtype=float) - self.origin) / self.cell)
        if (index < 0).any() or (index >= self.shape).any():
            return self.members[:0]
        ix, iy, iz = (int(i) for i in index)
        key = ix + int(self.shape[0]) * (iy + int(self.shape[1]) * iz)
        lo, hi = np.searchsorted(self.keys, [key, key + 1])
        return self.members[lo:hi]


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
    keys, members = [], []
    for t in range(len(corners)):  # once per piece at load: a triangle's cells, its box's range on each axis
        x, y, z = (np.arange(first[t, k], last[t, k] + 1) for k in range(3))
        grid = x[:, None, None] + shape[0] * (y[None, :, None] + shape[1] * z[None, None, :])
        keys.append(grid.ravel())
        members.append(np.full(grid.size, t, dtype=np.int64))
    keys = np.concatenate(keys) if keys else np.zeros(0, np.int64)
    members = np.concatenate(members) if members else np.zeros(0, np.int64)
    order = np.argsort(keys, kind="stable")
    return TriangleGrid(origin, cell, shape, keys[order], members[order])
