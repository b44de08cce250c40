"""Numeric helpers the built-in critics share (not a critic; no entry point).

numpy reduces slowly over a short innermost axis (a length-3 xyz axis, or the
~12 frames of a ``(T, L)`` array), so these helpers combine columns with
vectorised elementwise operations instead. Loops here run over columns (a
handful), never over samples.
"""

from __future__ import annotations

import numpy as np

__all__ = ["positions", "sq_norm3", "row_max", "row_min", "take_columns", "time_derivative"]


def positions(frames: np.ndarray, select=None) -> np.ndarray:
    """Contiguous ``(T, L, 3)`` frame origins, m, from ``(T, L, 4, 4)`` poses (one gather)."""
    if select is not None:
        return np.ascontiguousarray(frames[:, select][:, :, :3, 3])
    return np.ascontiguousarray(frames[:, :, :3, 3])


def sq_norm3(d: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``|d|^2`` over the last (xyz) axis of ``d (..., 3)``; overwrites ``d``."""
    d *= d
    if out is None:
        out = d[..., 0] + d[..., 1]
    else:
        np.add(d[..., 0], d[..., 1], out=out)
    out += d[..., 2]
    return out


def row_max(a: np.ndarray) -> np.ndarray:
    """``a.max(axis=1)`` of a tall, narrow ``(T, L)`` array."""
    out = a[:, 0].copy()
    for j in range(1, a.shape[1]):
        np.maximum(out, a[:, j], out=out)
    return out


def row_min(a: np.ndarray) -> np.ndarray:
    """``a.min(axis=1)`` of a tall, narrow ``(T, K)`` array."""
    out = a[:, 0].copy()
    for j in range(1, a.shape[1]):
        np.minimum(out, a[:, j], out=out)
    return out


def take_columns(a: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """``a[:, cols]`` as a C-contiguous copy (plain fancy indexing yields Fortran order, slow to scan by rows)."""
    cols = np.asarray(cols, dtype=np.int64)
    if cols.size and cols[-1] - cols[0] + 1 == cols.size and np.all(np.diff(cols) == 1):
        return np.ascontiguousarray(a[:, cols[0] : cols[-1] + 1])
    return np.take(a, cols, axis=1)


def time_derivative(y: np.ndarray, time: np.ndarray) -> np.ndarray:
    """d y / d time along the last axis of ``y (..., T)``, for uneven ``time (T,)``.

    Second-order central differences inside, first-order one-sided differences
    at both ends: the same numbers as ``numpy.gradient(y, time, axis=-1)``
    (``edge_order=1``), computed on contiguous rows. Zero for a single sample.
    """
    T = y.shape[-1]
    out = np.empty_like(y, dtype=float)
    if T < 2:
        out[...] = 0.0
        return out
    dt = np.diff(time)
    out[..., 0] = (y[..., 1] - y[..., 0]) / dt[0]
    out[..., -1] = (y[..., -1] - y[..., -2]) / dt[-1]
    if T > 2:
        h1, h2 = dt[:-1], dt[1:]  # t_i - t_{i-1}, t_{i+1} - t_i
        a = -h2 / (h1 * (h1 + h2))
        b = (h2 - h1) / (h1 * h2)
        c = h1 / (h2 * (h1 + h2))
        mid = out[..., 1:-1]
        np.multiply(y[..., :-2], a, out=mid)
        mid += y[..., 1:-1] * b
        mid += y[..., 2:] * c
    return out
