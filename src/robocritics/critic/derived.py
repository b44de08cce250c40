"""Arrays derived from a run that several critics read, computed once per run object.

A critic's judgement reads a few per-sample quantities of the trajectory; some are the same for several critics
(every frame's origin as coordinate planes, for the space-usage and joint-speed critics). :func:`shared` keeps
each on the :class:`~robocritics.execution.Execution` it was derived from (its ``derived`` dict), so the first
critic that asks computes it and the others read it. A chunk of a long run is its own Execution, so its arrays
are the chunk's; :func:`robocritics.critique` judges a copy of the run, so nothing derived outlives one call.
The values are the same bits whoever asks first: a derived array is a pure function of the trajectory.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, NamedTuple

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from ..execution import Execution

__all__ = ["shared", "position_planes", "columns_as_rows", "Frames", "frame_kinds", "moving_frames"]

GATHER_BLOCK = 512
"""Samples per block of :func:`columns_as_rows` on a row-major array: 512 rows of 60 pairs (240 kB) stay in a core's
L2 cache."""


def shared(execution: "Execution", key: str, compute: Callable[[], Any]) -> Any:
    """``compute()`` for ``execution``, computed once: later calls with the same ``key`` return the same object
    (read-only arrays: one critic must not change what the next one reads)."""
    cache = execution.derived
    if key not in cache:
        value = compute()
        if isinstance(value, np.ndarray):
            value.setflags(write=False)
        cache[key] = value
    return cache[key]


def position_planes(execution: "Execution") -> np.ndarray:
    """``(3, L, T)`` m: every frame's origin in the base frame, as planes of x, y and z, each frame's samples
    contiguous: ``planes[c, l, t] = trajectory.positions[t, l, c]``. Differences along time, norms over the
    coordinates and maxima over the frames are then operations on whole contiguous rows (3-6x cheaper than on the
    interleaved ``(T, L, 3)`` array). A stored trajectory keeps them (:attr:`Trajectory.position_planes`, made
    once, as its ``positions``): judging it again does not transpose them again."""
    return shared(execution, "position_planes", lambda: execution.trajectory.position_planes)


def columns_as_rows(P: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """``P.T[columns]``: the columns ``columns`` (indices) of ``P (T, K)`` as the rows of a new ``(len(columns), T)``
    array, each column's series contiguous. From a column-major ``P`` (a simulated trajectory's proximity) that is
    a copy of whole rows of ``P.T``; from a row-major one, block by block of :data:`GATHER_BLOCK` samples, each
    block gathered and transposed within the cache (40 % cheaper than one strided gather of the whole array, whose
    reads miss the cache row after row)."""
    PT = P.T
    if PT.flags.c_contiguous or not len(columns):
        return PT[columns]
    lo, hi = int(columns[0]), int(columns[-1]) + 1
    consecutive = hi - lo == len(columns) and bool(np.all(np.diff(columns) == 1))
    out = np.empty((len(columns), P.shape[0]), dtype=P.dtype)
    for start in range(0, P.shape[0], GATHER_BLOCK):
        block = P[start : start + GATHER_BLOCK]
        out[:, start : start + GATHER_BLOCK] = (block[:, lo:hi] if consecutive else block[:, columns]).T
    return out


class Frames(NamedTuple):
    """Which frames of a window of positions need their own per-point work: ``runs`` of consecutive frames
    ``[(lo, hi), ...]`` that move and are no copy of an earlier frame; ``still``, the frames at one place over the
    whole window (a robot's base and shoulder); ``copies`` and ``twins``, the frames equal to an earlier moving
    frame at every sample (a flange and the gripper body mounted on it), and that frame. Their second differences
    are 0 and their twin's, bit for bit, and their centre distances a constant and their twin's."""

    runs: list
    still: np.ndarray
    copies: np.ndarray
    twins: np.ndarray


def frame_kinds(Y: np.ndarray) -> Frames:
    """:class:`Frames` of the coordinate planes ``Y (3, L, n)``: a frame is still, or a copy, only if every sample
    says so (a few spread samples rule most frames out first, a full comparison confirms)."""
    L, n = Y.shape[1], Y.shape[2]
    probe = Y[:, :, :: max(1, n // 64)]  # (3, L, <= 128)
    maybe_still = (probe == probe[:, :, :1]).all(axis=(0, 2))  # (L,)
    maybe_equal = (probe[:, :, None, :] == probe[:, None, :, :]).all(axis=(0, 3))  # (L, L)
    still, copies, twins, own = [], [], [], []
    for l in range(L):
        if maybe_still[l] and (Y[:, l] == Y[:, l, :1]).all():
            still.append(l)
            continue
        twin = next((m for m in own if maybe_equal[l, m] and np.array_equal(Y[:, l], Y[:, m])), None)
        if twin is None:
            own.append(l)
        else:
            copies.append(l)
            twins.append(twin)
    runs = [(a, a + 1) for a in own[:1]]
    for l in own[1:]:
        runs[-1:] = [(runs[-1][0], l + 1)] if l == runs[-1][1] else [runs[-1], (l, l + 1)]
    as_array = lambda x: np.array(x, dtype=np.int64)  # noqa: E731
    return Frames(runs, as_array(still), as_array(copies), as_array(twins))


def moving_frames(execution: "Execution") -> Frames:
    """:func:`frame_kinds` of the run's :func:`position_planes`, found once and shared (space usage, joint speed)."""
    return shared(execution, "moving_frames", lambda: frame_kinds(position_planes(execution)))
