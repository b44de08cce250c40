"""Task goals: where an object should end up, checked on the final scene of an execution.

A goal is written ``"<object> in <container>"`` or ``"<object> on <support>"`` (support: another object or
``table``), e.g. ``"green_apple in white_box"``, ``"cupcake on plate"``, ``"fork in trash_bin"``. Goals come
from ``--goal`` on the command line, from ``critique(..., goals=[...])`` and from a program's own
``expect(obj, inside=container)`` / ``expect(obj, on=support)`` calls; the ``task_outcome`` critic checks them.
"""

from __future__ import annotations

import math
import re
from typing import TYPE_CHECKING, Any, Iterable, Literal, Mapping, Protocol

from pydantic import BaseModel, ConfigDict, Field

from ._suggest import did_you_mean
from .errors import GoalError

if TYPE_CHECKING:
    from .scene import Scene

__all__ = ["Goal", "GoalError", "GoalOutcome", "Run", "parse_goals", "program_goals", "check_outcomes"]


class Run(Protocol):
    """What goals are checked on: the scene at the start and the end of a run, where the program set objects
    down, the run's own goals and its plan (None for motion not from a program). An
    :class:`~robocritics.execution.Execution` is one; this module does not import it (goals sit below it)."""

    scene: Scene
    final_scene: Scene
    resting_on: Mapping[str, str]
    goals: tuple[Goal, ...]
    plan: Any

    def object_on(self, obj_id: str, support_id: str) -> bool: ...

    def object_inside(self, obj_id: str, container_id: str) -> bool: ...

TABLE = "table"
"""The support id of the table top."""

ON_TOLERANCE_M = 0.01
"""An unmoved object counts as on a support when its bottom is within this of the support's top, m."""

_RELATIONS = {"in": "in", "inside": "in", "into": "in", "on": "on", "onto": "on"}
_GOAL = re.compile(r"^\s*([A-Za-z_]\w*)\s+([A-Za-z_]\w*)\s+([A-Za-z_]\w*)\s*$")
_QUOTED = 60


def _quoted(text: str) -> str:
    return repr(text) if len(text) <= _QUOTED else repr(text[:_QUOTED]) + f"... ({len(text):,} characters)"


class Goal(BaseModel):
    """Object ``object`` should end ``relation`` (``"in"`` a container, ``"on"`` an object or the table) ``target``."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    object: str
    relation: Literal["in", "on"]
    target: str

    def __str__(self) -> str:
        return f"{self.object} {self.relation} {self.target}"

    @classmethod
    def parse(cls, text: "str | Goal") -> "Goal":
        """The goal written ``text`` (``"cupcake on plate"``); :class:`GoalError` saying what is wrong otherwise."""
        if isinstance(text, Goal):
            return text
        if not isinstance(text, str):
            raise GoalError(f"a goal is text such as 'green_apple in white_box', not {type(text).__name__}")
        match = _GOAL.match(text)
        if not match:
            raise GoalError(
                f"goal {_quoted(text)} is not '<object> in <container>' or '<object> on <support>' "
                "(e.g. 'green_apple in white_box', 'cupcake on plate')"
            )
        obj, word, target = match.groups()
        relation = _RELATIONS.get(word.lower())
        if relation is None:
            raise GoalError(
                f"goal {_quoted(text)}: unknown relation {word!r}; use 'in' or 'on'{did_you_mean(word, ['in', 'on', 'inside'])}"
            )
        return cls(object=obj, relation=relation, target=target)  # type: ignore[arg-type]

    def check(self, scene: "Scene") -> "Goal":
        """This goal, if its ids fit ``scene``; :class:`GoalError` naming the bad id (with a suggestion) otherwise."""
        objects = [o.id for o in scene.objects]
        containers = [c.id for c in scene.containers]
        if self.object not in objects:
            hint = " (a container cannot be moved)" if self.object in containers else did_you_mean(self.object, objects)
            raise GoalError(f"goal '{self}': no object {self.object!r} in scene {scene.name!r}{hint}")
        if self.relation == "in":
            if self.target not in containers:
                hint = (
                    f"; {self.target!r} is an object: use 'on'"
                    if self.target in objects or self.target == TABLE
                    else did_you_mean(self.target, containers)
                )
                raise GoalError(f"goal '{self}': no container {self.target!r} in scene {scene.name!r}{hint}")
        else:
            supports = [*objects, TABLE]
            if self.target not in supports:
                hint = (
                    f"; {self.target!r} is a container: use 'in'"
                    if self.target in containers
                    else did_you_mean(self.target, supports)
                )
                raise GoalError(f"goal '{self}': no object {self.target!r} (or 'table') in scene {scene.name!r}{hint}")
            if self.target == self.object:
                raise GoalError(f"goal '{self}': an object cannot rest on itself")
        return self

    def met(self, execution: Run) -> bool:
        """Whether the object ended where this goal says, in ``execution``'s final scene."""
        final = execution.final_scene
        if self.relation == "in":
            return execution.object_inside(self.object, self.target)
        if self.object in execution.resting_on:
            return execution.object_on(self.object, self.target)
        # never set down by the program: on the target when its bottom touches the target's top above it
        obj = final.entity(self.object)
        if final.container_holding(self.object) is not None:
            return False
        if self.target == TABLE:
            return abs(obj.bottom - final.table.top_z) <= ON_TOLERANCE_M
        support = final.entity(self.target)
        horizontal = math.hypot(obj.position[0] - support.position[0], obj.position[1] - support.position[1])
        return abs(obj.bottom - support.top) <= ON_TOLERANCE_M and horizontal <= max(support.width, obj.width) / 2

    def outcome(self, execution: Run) -> tuple[bool, str]:
        """``(met, where)``: whether the goal holds, and where the object ended, in plain words with metres."""
        self.check(execution.scene)
        final = execution.final_scene
        obj = final.entity(self.object)
        x, y, z = obj.position
        holder = final.container_holding(self.object)
        if holder is not None:
            place = f"in {holder.id}"
        elif self.object in execution.resting_on:
            support = execution.resting_on[self.object]
            place = "on the table" if support == TABLE else f"on {support}"
        else:
            place = "where it started"
        where = f"{self.object} ended {place} at ({x:.2f}, {y:.2f}) m"
        met = self.met(execution)
        if not met and self.target != TABLE:
            target = final.entity(self.target)
            d = math.hypot(x - target.position[0], y - target.position[1])
            over_rim = self.relation == "in" and target.contains_point((x, y, target.floor_top + ON_TOLERANCE_M))
            if over_rim and z > target.top:  # e.g. stacked on another object in the box, sticking out of it
                where += f", its centre {z - target.top:.2f} m above the rim of {self.target}"
            else:
                where += f", {d:.2f} m from {self.target}"
        elif not met:
            where += f", {obj.bottom - final.table.top_z:.2f} m above the table"
        return met, where


class GoalOutcome(BaseModel):
    """One goal checked on a final scene: the goal's text, whether it holds, where the object ended."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    goal: str
    met: bool
    where: str
    object: str = ""
    lines: tuple[int, ...] = Field((), description="program lines of the expect() calls that stated it")


def parse_goals(goals: "Iterable[str | Goal] | str | Goal | None", scene: "Scene | None" = None) -> list[Goal]:
    """Goals from text or :class:`Goal` values (duplicates dropped, order kept), checked against ``scene`` if given."""
    if goals is None:
        return []
    if isinstance(goals, (str, Goal)):
        goals = [goals]
    out: list[Goal] = []
    for g in goals:
        goal = Goal.parse(g)
        if scene is not None:
            goal.check(scene)
        if goal not in out:
            out.append(goal)
    return out


def program_goals(plan) -> list[tuple[Goal, int]]:
    """The goals a program stated with ``expect(...)``: ``(goal, line)`` per call of :class:`~robocritics.program.Plan` ``plan``."""
    return [
        (Goal(object=c.args["object"], relation=c.args["relation"], target=c.args["target"]), c.line)
        for c in getattr(plan, "calls", ())  # an Execution built by hand may have no plan
        if c.skill == "expect"
    ]


def check_outcomes(execution: Run, goals: "Iterable[str | Goal] | str | Goal | None" = None) -> list[GoalOutcome]:
    """:class:`GoalOutcome` of every goal in ``goals``, in ``execution.goals`` and of the program's ``expect(...)``
    calls, checked on ``execution``'s final scene (each goal once, with all its lines)."""
    lines: dict[Goal, list[int]] = {g: [] for g in parse_goals(goals, execution.scene)}
    for goal in execution.goals:
        lines.setdefault(goal, [])
    for goal, line in program_goals(execution.plan):
        lines.setdefault(goal, []).append(line)
    out = []
    for goal, at in lines.items():
        met, where = goal.outcome(execution)
        out.append(GoalOutcome(goal=str(goal), met=met, where=where, object=goal.object, lines=tuple(at)))
    return out
