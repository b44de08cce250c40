"""Arrays derived from a run that several critics read, computed once per run object.

A critic's judgement reads a few per-sample quantities of the trajectory; some are the same for several critics
(every frame's origin as coordinate planes, for the space-usage and joint-speed critics). :func:`shared` keeps
each on the :class:`~robocritics.execution.Execution` it was derived from (its ``derived`` dict), so the first
critic that asks computes it and the others read it. A chunk of a long run is its own Execution, so its arrays
are the chunk's; :func:`robocritics.critique` judges a copy of the run, so nothing derived outlives one call.
The values are the same bits whoever asks first: a derived array is a pure function of the trajectory.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from ..execution import Execution

__all__ = ["shared", "position_planes"]


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
