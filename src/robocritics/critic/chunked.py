"""Critics as reductions over the chunks of a run, so judging a long motion needs memory for one chunk.

A critic that offers ``reduction(execution, params)`` returns a :class:`Reduction`: :meth:`Reduction.add` is
called with every chunk of the run in order (:meth:`robocritics.execution.Execution.chunks`: each chunk's own
samples ``chunk.start..chunk.stop-1``, with one sample of halo either side for differences over time, and the run
restricted to them), then :meth:`Reduction.verdict` gives the verdict. Its ``check(execution, params)`` is
:func:`judge_in_chunks` of itself, so it stays a plain critic; :func:`robocritics.critique` runs every such
critic of a selection in one pass over the chunks, so a compact (long) trajectory's frames and proximity are
computed once per chunk, not once per critic.

The contract: the verdict is the same, bit for bit, whatever the chunk size (a run of one chunk is the
whole-array computation). Reductions keep per-sample values (a few numbers a sample) and per-chunk extremes,
never a chunk's ``(n, L, 4, 4)`` or ``(n, K)`` arrays. The helpers here are the reductions the built-in critics
share.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from ..execution import Execution
    from ..trajectory import Chunk
    from .verdict import Verdict

__all__ = ["Reduction", "judge_in_chunks", "Extreme", "Series", "AnyOver"]


@runtime_checkable
class Reduction(Protocol):
    """One critic's judgement of one run, fed chunk by chunk."""

    def add(self, chunk: "Chunk", execution: "Execution") -> None: ...

    def verdict(self) -> "Verdict": ...


def judge_in_chunks(critic: Any, execution: "Execution", params: Any, size: int | None = None) -> "Verdict":
    """``critic.reduction(execution, params)`` fed every chunk of ``execution`` (``size`` samples each, default
    :data:`~robocritics.trajectory.CHUNK_SAMPLES`), and its verdict."""
    reduction = critic.reduction(execution, params)
    for chunk, window in execution.chunks(size):
        reduction.add(chunk, window)
    return reduction.verdict()


class Series:
    """A per-sample value ``(T,)`` assembled from the chunks' own samples."""

    def __init__(self, T: int, dtype=float, fill=0.0):
        self.values = np.full(T, fill, dtype=dtype)

    def put(self, start: int, values: np.ndarray) -> None:
        self.values[start : start + len(values)] = values


class Extreme:
    """The first sample where a per-sample value is largest (``worst="max"``) or least (``"min"``) over every
    chunk, as ``np.argmax`` / ``np.argmin`` of the whole series picks it, with what ``detail`` says about it
    (computed in the chunk that holds it)."""

    def __init__(self, worst: str = "max"):
        self.worst = worst
        self.value: float | None = None
        self.index = 0
        self.detail: Any = None

    def offer(self, start: int, values: np.ndarray, detail: Callable[[int], Any] | None = None) -> None:
        """``values`` of samples ``start..``; ``detail(i)`` of the chunk's row ``i`` is kept for a new extreme."""
        if not len(values):
            return
        i = int(np.argmax(values) if self.worst == "max" else np.argmin(values))
        v = values[i]
        # NaN wins as np.argmax/argmin let it (the first NaN); otherwise strictly better, so the first sample wins ties
        better = self.value is None or (
            not np.isnan(self.value) and (np.isnan(v) or (v > self.value if self.worst == "max" else v < self.value))
        )
        if better:
            self.value, self.index = v, start + i
            self.detail = detail(i) if detail is not None else None


class AnyOver:
    """Which columns (links, pairs) pass a test at some own sample of some chunk: an ``or`` over the chunks."""

    def __init__(self, columns: int):
        self.hit = np.zeros(columns, dtype=bool)

    def add(self, hits: np.ndarray) -> None:
        if hits.shape[0]:
            self.hit |= hits.any(axis=0)
