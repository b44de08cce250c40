"""The timed motion a URScript program commands, as segments on one clock, and its samples.

Every motion command becomes a :class:`Segment`: local sample times from 0 to its duration and the
values ``(m, n + 1)`` at them (the joints, rad, and the gripper opening, m, last). Segments run one after
another; a move with a blend radius ``r`` overlaps the next move, and the overlap is the sum of the two
(superposition: the second move's change is added while the first finishes), so position and speed stay
continuous. The overlap is the shorter of the time the first move spends within ``r`` (TCP distance) of its
target and the time the next spends within ``r`` of its start, and at most half of either move. The real
controller blends along a different curve through the same zone; the duration saving and the corner cut are
of the same size (documented in docs/formats.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .syntax import URScriptError

__all__ = ["Segment", "Timeline", "MAX_MOTION_S", "MAX_SEGMENTS"]

#: The longest motion a script may command, s (as the planner's budget for programs).
MAX_MOTION_S = 300.0
MAX_SEGMENTS = 20_000


@dataclass
class Segment:
    """One command's motion: ``times (m,)`` s from its start (0 first), ``values (m, n + 1)``, ``steps (m,)``."""

    times: np.ndarray
    values: np.ndarray
    steps: np.ndarray
    blend_m: float = 0.0
    moves: bool = True
    #: Runs beside what follows instead of before it (a gripper command that does not wait); names no samples.
    parallel: bool = False
    tcp: np.ndarray | None = field(default=None, repr=False)  # (m, 3) TCP positions, for blends

    @property
    def duration(self) -> float:
        return float(self.times[-1])


class Timeline:
    """Segments on one clock; :meth:`samples` makes the trajectory's samples at a rate."""

    def __init__(self, start: np.ndarray, tcp_position):
        self.start = np.asarray(start, dtype=float)
        self.state = self.start.copy()  # where every segment so far leaves the arm and gripper
        self.segments: list[Segment] = []
        self.starts: list[float] = []
        self.end_time = 0.0
        self.last_end = 0.0  # the latest end of any segment, parallel ones included
        self.tcp_position = tcp_position  # q (m, n) -> (m, 3) m

    @property
    def end(self) -> np.ndarray:
        return self.state

    def add(self, segment: Segment, line: int, delay_s: float = 0.0) -> None:
        """Append ``segment`` (a ``parallel`` one starting ``delay_s`` after the end of the others)."""
        if len(self.segments) >= MAX_SEGMENTS:
            raise URScriptError(f"the script commands more than {MAX_SEGMENTS:,} motions", line=line)
        start = self.end_time + (delay_s if segment.parallel else 0.0)
        previous = next((s for s in reversed(self.segments) if not s.parallel), None)
        if previous is not None and segment.moves and previous.moves and previous.blend_m > 0 and not segment.parallel:
            start -= self._overlap(previous, segment)
        self.segments.append(segment)
        self.starts.append(start)
        self.state = self.state + (segment.values[-1] - segment.values[0])
        if not segment.parallel:
            self.end_time = start + segment.duration
        self.last_end = max(self.last_end, start + segment.duration)
        if self.last_end > MAX_MOTION_S:
            raise URScriptError(
                f"the motion lasts more than {MAX_MOTION_S:.0f} s (the limit for one check); "
                "shorten it or judge fewer passes (--passes)",
                line=line,
            )

    def _tcp(self, seg: Segment) -> np.ndarray:
        if seg.tcp is None:
            seg.tcp = self.tcp_position(seg.values[:, :-1])
        return seg.tcp

    def _overlap(self, first: Segment, second: Segment) -> float:
        r = first.blend_m
        a, b = self._tcp(first), self._tcp(second)
        inside_a = np.linalg.norm(a - a[-1], axis=1) <= r
        inside_b = np.linalg.norm(b - b[0], axis=1) <= r
        # time the first move spends in the zone at its end, the second at its start
        ta = first.duration - float(first.times[int(np.argmax(inside_a))]) if inside_a.any() else 0.0
        outside_b = np.flatnonzero(~inside_b)
        tb = float(second.times[outside_b[0]]) if len(outside_b) else second.duration
        return max(0.0, min(ta, tb, first.duration / 2.0, second.duration / 2.0))

    def samples(self, rate_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(time (T,) s, values (T, n + 1), step (T,))``: a uniform grid at ``rate_hz`` plus every segment's end."""
        total = self.last_end
        uniform = np.arange(int(math.floor(total * rate_hz + 1e-9)) + 1) / rate_hz
        ends = np.unique([s + seg.duration for s, seg in zip(self.starts, self.segments)] + [total])
        # uniform samples within a quarter period of a segment's end give way to it (nearest end by bisection)
        i = np.clip(np.searchsorted(ends, uniform), 1, len(ends) - 1) if len(ends) > 1 else np.zeros(len(uniform), int)
        nearest = np.minimum(np.abs(uniform - ends[i]), np.abs(uniform - ends[i - 1 if len(ends) > 1 else 0]))
        grid = np.unique(np.concatenate([uniform[nearest > 0.25 / rate_hz], ends, [0.0]]))
        values = np.repeat(self.start[None, :], len(grid), axis=0)
        steps = np.zeros(len(grid), dtype=np.int64)
        increments = np.zeros_like(values)
        los = [int(np.searchsorted(grid, start - 1e-12, side="left")) for start in self.starts]
        # the samples a segment names run to where the next segment that names samples starts
        claims = [k for k, seg in enumerate(self.segments) if not seg.parallel]
        until = dict(zip(claims, [los[k] for k in claims[1:]] + [len(grid)]))
        for k, (start, seg) in enumerate(zip(self.starts, self.segments)):
            lo = los[k]
            hi = int(np.searchsorted(grid, start + seg.duration + 1e-12, side="right"))
            local = grid[lo:hi] - start
            base = seg.values[0]
            for j in range(values.shape[1]):
                values[lo:hi, j] += np.interp(local, seg.times, seg.values[:, j]) - base[j]
            if hi < len(grid):
                increments[hi] += seg.values[-1] - base
            if seg.parallel:
                continue
            # a sample belongs to the latest segment started by its time
            mine = grid[lo : max(lo, until[k])] - start
            idx = np.clip(np.searchsorted(seg.times, mine, side="right") - 1, 0, len(seg.steps) - 1)
            steps[lo : lo + len(mine)] = seg.steps[idx]
        values += np.cumsum(increments, axis=0)
        return grid, values, steps
