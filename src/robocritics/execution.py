"""``Execution``: one run as the critics see it.

Everything a critic may read about a run, whatever produced it:

* ``trajectory``: the timed motion (the paper's s_1..s_T) that the critics judge and the deploy gate streams;
* ``scene`` and ``final_scene``: the cell at the start and where every object ended;
* ``robot``: the arm the motion runs on (kinematics, limits, tool), or None when a bare trajectory was judged
  without one;
* ``plan``: the program's skill calls with their source lines, or None for motion that did not come from a
  program in the skill API (URScript, a recording, a trajectory file);
* ``goals``: the task goals the run is judged against (besides the program's own ``expect(...)`` calls);
* ``source``: where the motion came from, in words (``"program"``, ``"URScript pick.script"``, ...).

A critic's ``check(execution, params)`` receives this object (see :mod:`robocritics.critic`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Iterator, Optional

if TYPE_CHECKING:  # pragma: no cover
    import numpy as np

    from .goals import Goal
    from .program.plan import Plan
    from .critic.report import Report
    from .robot.model import Robot
    from .planning.planner import Event
    from .scene import Scene
    from .trajectory import Chunk, Trajectory

__all__ = ["Execution", "MovedPoses"]


class MovedPoses(Mapping):
    """``{object id: (T, 4, 4)}`` poses of the objects a compact (long) trajectory moves, each computed when read
    (:meth:`robocritics.trajectory.Trajectory.object_poses`): the ``object_poses`` of a long run, which would
    take 128 bytes a sample per object as arrays. Chunks of the run (:meth:`Execution.chunks`) carry theirs."""

    def __init__(self, trajectory: "Trajectory"):
        self.trajectory = trajectory

    def __getitem__(self, obj_id: str) -> "np.ndarray":
        if obj_id not in self.trajectory.geometry.schedules:
            raise KeyError(obj_id)
        return self.trajectory.object_poses()[obj_id]

    def at(self, obj_id: str, samples) -> "np.ndarray":
        """``(n, 4, 4)`` poses of ``obj_id`` at sample indices ``samples`` only (a replay's decimated samples)."""
        import numpy as np

        return self.trajectory.geometry.poses_at(obj_id, np.asarray(samples, dtype=np.int64))

    def __contains__(self, obj_id) -> bool:  # without computing the poses (Mapping's would read them)
        return obj_id in self.trajectory.geometry.schedules

    def __iter__(self):
        return iter(self.trajectory.geometry.schedules)

    def __len__(self) -> int:
        return len(self.trajectory.geometry.schedules)


@dataclass
class Execution:
    """One run: the result of :func:`robocritics.simulate`, or motion imported from another tool.

    ``trajectory`` is what the critics read and what is deployed; ``final_scene``
    says where every object ended up.
    """

    trajectory: Trajectory
    plan: Optional[Plan]
    events: list[Event]
    final_scene: Scene
    scene: Scene
    robot: Optional[Robot] = field(repr=False)
    resting_on: dict[str, str] = field(default_factory=dict)
    #: Per-sample pose ``(T, 4, 4)`` (m, base frame) of every object the program moved; the others stay put.
    object_poses: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    #: Task goals to judge the run against, besides the program's own ``expect(...)`` calls.
    goals: tuple[Goal, ...] = ()
    #: Where the motion came from, in words: ``"program"`` for the skill API, else the tool or file.
    source: str = "program"
    #: Arrays derived from this run's trajectory that several critics read (:mod:`robocritics.critic.derived`),
    #: each computed on first use. Not an argument: every new Execution (a ``replace`` of one, a chunk's) starts
    #: empty, so nothing derived outlives the run object it was derived from.
    derived: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def duration_s(self) -> float:
        return self.trajectory.duration_s

    def __getstate__(self) -> dict:
        # derived arrays are a cache of the trajectory's: not shipped between processes (a batch pickles runs)
        return {**self.__dict__, "derived": {}}

    def chunks(self, size: int | None = None) -> Iterator[tuple["Chunk", "Execution"]]:
        """The run chunk by chunk (:meth:`robocritics.trajectory.Trajectory.chunks`, ``size`` samples each): each
        chunk with the run restricted to its samples (its trajectory and the moving objects' poses there). A run of
        one chunk is itself. By default a compact trajectory comes in chunks of
        :data:`~robocritics.trajectory.CHUNK_SAMPLES` and a stored one in one chunk (its arrays are all in memory
        already: slicing them would only cost copies)."""
        from .trajectory import CHUNK_SAMPLES, Chunk

        if size is None and not self.trajectory.compact:
            yield Chunk(0, len(self.trajectory), 0, self.trajectory, {}), self
            return
        for chunk in self.trajectory.chunks(size or CHUNK_SAMPLES):
            if chunk.trajectory is self.trajectory:
                yield chunk, self
                continue
            lo, hi = chunk.lo, chunk.lo + len(chunk.trajectory)
            poses = chunk.object_poses or {oid: p[lo:hi] for oid, p in self.object_poses.items()}
            yield chunk, replace(self, trajectory=chunk.trajectory, object_poses=poses)

    def show(self, report: Report | None = None, *, title: str | None = None):
        """The 3-D replay of this run (with ``report``'s verdicts on its timeline), displayed inline in Jupyter.

        Returns a :class:`robocritics.viz.Replay`; its ``save(path)`` writes the same
        self-contained HTML page that ``robocritics check --html`` writes.
        """
        from .viz import Replay

        return Replay(self, report, title=title)

    def object_on(self, obj_id: str, support_id: str) -> bool:
        """Whether object ``obj_id`` was last set down on ``support_id`` (an object, container or 'table')."""
        return self.resting_on.get(obj_id) == support_id

    def object_inside(self, obj_id: str, container_id: str) -> bool:
        """Whether object ``obj_id`` ended inside container ``container_id``."""
        holder = self.final_scene.container_holding(obj_id)
        return holder is not None and holder.id == container_id
