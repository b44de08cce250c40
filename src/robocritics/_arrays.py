"""Array helpers for the check path: sort-based set operations and row reductions.

``np.unique(x)`` called without ``return_index``/``return_inverse``/``return_counts`` asks ``np.ma.is_masked``
(numpy 2.4), which imports ``numpy.ma``: about 9 ms of a cold ``robocritics check``. The set helpers give the
same answers from one sort and never touch ``numpy.ma``; they are tested against ``np.unique``.

numpy reduces a short last axis row by row, with an overhead per row: ``A.max(axis=1)`` of a ``(7000, 12)``
array costs 3x ``np.ascontiguousarray(A.T).max(axis=0)``, which takes elementwise maxima of whole rows (and
pays one copy). The row reductions below do that; maxima, minima and ``any`` are exact, so the answers are
the same.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "unique_values",
    "run_starts",
    "equal_row_groups",
    "first_of_equal_rows",
    "row_max",
    "row_any",
    "min_over_columns",
    "squared_norms",
]


def unique_values(values: np.ndarray) -> np.ndarray:
    """Sorted distinct values of ``values`` (flattened): ``np.unique(values)``, NaNs collapsed into one (numbers;
    datetimes' NaT are not merged)."""
    a = np.sort(np.asarray(values).ravel())
    if a.size == 0:
        return a
    keep = np.empty(a.size, dtype=bool)
    keep[0] = True
    np.not_equal(a[1:], a[:-1], out=keep[1:])
    if a.dtype.kind in "fc" and np.isnan(a[-1]):  # NaNs sort last and never compare equal: keep the first
        first_nan = int(np.argmax(np.isnan(a)))
        keep[first_nan] = True
        keep[first_nan + 1 :] = False
    return a[keep]


def run_starts(values: np.ndarray) -> np.ndarray:
    """Indices of the first element of each run of equal consecutive values of the 1-D ``values`` (0 first)."""
    change = np.empty(len(values), dtype=bool)
    change[:1] = True
    np.not_equal(values[1:], values[:-1], out=change[1:])
    return np.flatnonzero(change)


def _lexsorted_runs(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(order, start)``: a stable lexicographic order of the rows of ``A (N, K)`` (column 0 first) and, along
    it, whether each row starts a run of rows equal to it (``==`` per element, so ``-0.0`` equals ``0.0``)."""
    order = np.lexsort(A.T[::-1])  # lexsort's last key is the primary one
    S = A[order]
    start = np.empty(len(A), dtype=bool)
    start[:1] = True
    np.any(S[1:] != S[:-1], axis=1, out=start[1:])
    return order, start


def equal_row_groups(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(group (N,), counts (G,))`` for the rows of ``A (N, K)``: rows ``i`` and ``j`` are equal (element-wise
    ``==``) iff ``group[i] == group[j]``; group ``g`` has ``counts[g]`` rows. The labels are those of
    ``np.unique(A, axis=0, return_inverse=True, return_counts=True)`` for finite ``A`` (lexicographic order of the
    distinct rows); a row holding a NaN equals no row, not even itself, so it is a group of its own."""
    A = np.asarray(A)
    if len(A) == 0:
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
    order, start = _lexsorted_runs(A.reshape(len(A), -1))
    group = np.empty(len(A), dtype=np.intp)
    group[order] = np.cumsum(start) - 1
    counts = np.diff(np.append(np.flatnonzero(start), len(A)))
    return group, counts


def first_of_equal_rows(A: np.ndarray, W: np.ndarray) -> np.ndarray:
    """Ascending indices ``i`` of ``A (N, K)`` such that row ``A[i]`` equals a row of ``W (M, K)`` and no earlier
    row of ``A`` equals it (element-wise ``==``): the first of each set of equal rows that ``W`` asks for. Rows of
    ``W`` that ``A`` lacks are ignored."""
    A, W = np.asarray(A), np.asarray(W)
    if A.dtype != W.dtype:  # compare values, not W cast to A's dtype (0.5 is no int 0; 258 is no uint8 2)
        common = np.result_type(A, W)
        A, W = A.astype(common), W.astype(common)
    if len(A) == 0 or len(W) == 0:
        return np.zeros(0, dtype=np.int64)
    # candidates: rows of A whose first element is one of W's (a binary search each; W is usually much
    # smaller than A, and a lexicographic sort of all of A costs several times more)
    wx = np.sort(W[:, 0])
    at = np.minimum(np.searchsorted(wx, A[:, 0]), len(wx) - 1)
    candidates = np.flatnonzero(wx[at] == A[:, 0])
    n = len(candidates)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    # one stable sort of the candidates and W together: in each run of equal rows, A's rows come first, in index
    # order (candidates ascend)
    order, start = _lexsorted_runs(np.concatenate([A[candidates], W.astype(A.dtype, copy=False)]))
    run = np.cumsum(start) - 1
    first = order[start]  # the first row (smallest index) of each run
    wanted = np.zeros(len(first), dtype=bool)
    wanted[run[order >= n]] = True  # runs holding a row of W
    found = first[wanted]
    return candidates[np.sort(found[found < n])].astype(np.int64)  # a run led by a row of W has no row of A


def row_max(A: np.ndarray) -> np.ndarray:
    """``A.max(axis=1)`` of a 2-D array (NaN propagates; no columns: ValueError), along the rows of ``A.T``."""
    return np.ascontiguousarray(A.T).max(axis=0)


def row_any(A: np.ndarray) -> np.ndarray:
    """``A.any(axis=1)`` of a 2-D array, along the rows of ``A.T``."""
    return np.ascontiguousarray(A.T).any(axis=0)


def min_over_columns(A: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """``(T,)`` minimum of ``A[:, columns]`` (``A (T, K)``, ``columns`` indices) per row, +inf for no columns.

    The columns are gathered as rows of ``A.T`` (a ``(len(columns), T)`` array) and reduced along axis 0, by
    elementwise minima of whole rows: the minimum along each short row of ``A[:, columns]`` costs 4x more
    (40 columns).
    """
    return A.T[columns].min(axis=0) if len(columns) else np.full(len(A), np.inf)


def squared_norms(v: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``|v|^2`` over the last axis (length 3) of ``v (..., 3)``, as ``x^2 + z^2 + y^2``: the order
    ``np.einsum("...i,...i->...", v, v)`` adds in (bit for bit with numpy 2.4), at a third of its cost."""
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    out = np.multiply(x, x, out=out)
    out += z * z
    out += y * y
    return out
