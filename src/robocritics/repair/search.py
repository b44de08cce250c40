"""The repair search: simulate, ask the critics that flag an Error for edits, keep those simulation verifies.

See :mod:`robocritics.repair` for the whole story; this module is its implementation.
"""

from __future__ import annotations

import difflib
import logging
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..critic import RUNTIME
from ..errors import RoboCriticsError
from ..critic.verdict import Flag
from . import builtin
from .edit import Edit, apply_edits

log = logging.getLogger(__name__)

if TYPE_CHECKING:  # pragma: no cover
    from ..critic.report import Report
    from ..scene import Scene
    from ..execution import Execution

__all__ = ["search", "Repair", "Change", "NotRun", "MAX_ROUNDS", "MAX_SIMULATIONS"]

#: Most accepted edits per repair() call.
MAX_ROUNDS = 16
#: Most candidate programs re-simulated per repair() call: the search's CPU bound (a bundled-scene program
#: simulates and is critiqued in about 0.05-0.3 s of CPU, so a repair costs at most about 35 s).
MAX_SIMULATIONS = 120
#: Edits that may be combined beyond the first when no single one helps, and how many first edits are tried.
DEPTH = 1
LOOKAHEAD = 3


@dataclass(frozen=True)
class Change:
    """One accepted edit: which critic asked for it, the program line, what changed, why, and its cost.

    ``cost_s`` is the change in cycle time it caused, s (positive = slower; 0 for the
    edit that makes a program that did not run run).
    """

    critic: str
    line: int
    what: str
    why: str
    cost_s: float

    def __str__(self) -> str:
        return f"{self.critic} (line {self.line}): {self.what} -- {self.why} [{self.cost_s:+.2f} s]"


@dataclass
class Repair:
    """The result of :func:`repair`: the repaired ``program`` with its ``report`` and ``execution``.

    ``execution`` is None when the program still does not run (``report`` then holds the
    ``runtime`` critic's Error naming the line); that happens only with no ``changes``,
    since the runtime repair is kept only when the program then runs.
    """

    original: str
    program: str
    report: Report
    execution: Execution | None
    changes: list[Change] = field(default_factory=list)
    #: The original program's score (0-10) and cycle time (s; None when it did not run).
    original_score: float = 0.0
    original_cycle_s: float | None = None

    @property
    def diff(self) -> str:
        """A unified diff from the original program to the repaired one."""
        return "".join(
            difflib.unified_diff(
                self.original.splitlines(keepends=True), self.program.splitlines(keepends=True), "original", "repaired"
            )
        )

    @property
    def errors(self) -> list:
        """The verdicts still flagged Error."""
        return [v for v in self.report.verdicts if v.flag == Flag.ERROR]

    @property
    def warnings(self) -> list:
        """The verdicts still flagged Warning."""
        return [v for v in self.report.verdicts if v.flag == Flag.WARNING]

    def summary(self) -> str:
        """One line: how many changes, the score and cycle time before and after, and what is left."""
        after = f"{self.report.score:g}/10"
        cycle = f", cycle {self.execution.duration_s:.2f} s" if self.execution is not None else ""
        if self.original_cycle_s is not None and self.execution is not None:
            cycle = f", cycle {self.original_cycle_s:.2f} s -> {self.execution.duration_s:.2f} s"
        left = f"{len(self.errors)} Error(s) and {len(self.warnings)} Warning(s) left"
        clean = "nothing left" if not self.errors and not self.warnings else left
        return f"repair: {len(self.changes)} change(s), score {self.original_score:g}/10 -> {after}{cycle}; {clean}"


@dataclass(frozen=True)
class NotRun:
    """What a repair hook gets as ``execution`` for the ``runtime`` verdict of a program that does not run.

    It has the ``scene`` (with the robot's workspace) and the ``robot`` the program was
    simulated with, but no trajectory or plan: a repair re-runs what it needs (e.g. the
    built-in one re-simulates to read the unreachable target from the PlanningError).
    """

    scene: Scene
    robot: Any


def _manager():
    from ..critic.plugins import load_plugins, pm

    load_plugins()
    if not pm.is_registered(builtin):
        pm.register(builtin, name="robocritics.repair.builtin")
    return pm


def _flags(report: Report) -> dict[str, int]:
    return {v.critic: v.score for v in report.verdicts}


#: The critic of the task goals: a repair never trades a goal for anything else.
TASK_OUTCOME = "task_outcome"

#: Fraction by which a flag's distance from its threshold must shrink to count as progress.
PROGRESS = 0.25


def _progress(before: Report, after: Report, critic: str) -> bool:
    old = next((v for v in before.verdicts if v.critic == critic), None)
    new = next((v for v in after.verdicts if v.critic == critic), None)
    if old is None or new is None or None in (old.value, old.threshold, new.value) or old.threshold != new.threshold:
        return False
    gap_old, gap_new = old.value - old.threshold, new.value - new.threshold
    if gap_old * gap_new > 0 and abs(gap_new) <= (1 - PROGRESS) * abs(gap_old):
        return True
    # as bad at its worst, but over clearly fewer samples: one of several faults of that critic is gone
    fewer = new.evidence.samples_flagged <= (1 - PROGRESS) * old.evidence.samples_flagged
    return new.flag == old.flag and abs(gap_new) <= abs(gap_old) and fewer


def _runtime_moved_on(before: Report, after: Report) -> bool:
    """The program still does not run, but fails on another call or target: e.g. the first unreachable hover is
    fixed and the next one is reached (in a loop that can be an earlier line, for the next object). The search
    never revisits a program and its rounds are bounded, so a different failure is taken as a step forward."""
    old, new = (next(v for v in r.verdicts if v.critic == RUNTIME) for r in (before, after))
    return new.message != old.message


def _acceptable(before: Report, after: Report, critic: str) -> bool:
    """``after`` scores no verdict lower than ``before`` and makes progress on ``critic``'s flag.

    Progress is one of: ``critic``'s flag is lifted (an Error to a Warning or OK, a
    Warning to OK); its flag is clearly smaller (:data:`PROGRESS`: the measured value
    moved toward the threshold by that fraction, e.g. a 6 cm penetration that became
    2.9 cm, so a repair that uncovers the next, lesser fault of the same critic still
    counts and the next round can fix that one), or no worse and flagged on that
    fraction fewer samples (one of several collisions gone); or another critic's Error is gone
    (e.g. picking the cupcake first puts it on the plate, while the collision it
    caused moves elsewhere). For the ``runtime`` Error of a program that did not run,
    progress is that it runs.
    """
    old, new = _flags(before), _flags(after)
    if critic == RUNTIME:  # the program did not run: running at all, or failing later, is the progress
        return RUNTIME not in new or _runtime_moved_on(before, after)
    if not all(new.get(name, 2) >= score for name, score in old.items()):
        return False
    if not all(name in old or score > 0 for name, score in new.items()):
        return False
    if new.get(critic, 2) > old.get(critic, 2) or _progress(before, after, critic):
        return True
    return sum(s == 0 for s in new.values()) < sum(s == 0 for s in old.values())


def _offered_edits(hook, verdict, execution, source: str) -> list:
    """Every plugin's edits for ``verdict``; a plugin whose hook raises is logged by name and skipped."""
    edits: list = []
    for impl in hook.robocritics_repairs.get_hookimpls():
        try:
            offered = impl.function(verdict=verdict, execution=execution, program=source)
        except Exception as exc:  # noqa: BLE001 - third-party code: report it, keep repairing with the others
            log.warning("repair plugin %s failed on %s and was skipped: %s: %s",
                        impl.plugin_name, verdict.critic, type(exc).__name__, str(exc)[:200])  # fmt: skip
            continue
        edits += [e for e in offered or [] if isinstance(e, Edit)]
    return edits


def _merit(report: Report, execution) -> tuple:
    """How good a candidate is, best highest: it runs, fewest Errors, then the score, then the shortest cycle."""
    errors = sum(v.flag == Flag.ERROR for v in report.verdicts)
    if any(v.critic == RUNTIME for v in report.verdicts):
        errors = 1_000  # a program that does not run is worse than any that runs
    return (-errors, report.score, -(execution.duration_s if execution is not None else float("inf")))


def _better(before: Report, after: Report) -> bool:
    """``after`` has fewer Errors, or as many and a higher score (an Error traded for a Warning is better);
    never at the cost of a task goal (the ``task_outcome`` verdict) or of running at all."""
    old, new = _flags(before), _flags(after)
    if any(new.get(name, 2) < old.get(name, 2) for name in (TASK_OUTCOME, RUNTIME)):
        return False
    return _merit(after, None)[:2] > _merit(before, None)[:2]


def _flagged(report: Report) -> list:
    """The verdicts to repair, Errors first (the ``runtime`` one before all), then Warnings, each in report order."""
    bad = [v for v in report.verdicts if v.flag != Flag.OK]
    return sorted(bad, key=lambda v: (v.critic != RUNTIME, v.flag != Flag.ERROR))


@dataclass
class _State:
    """One program the search reached: its source, execution (None: it does not run) and report."""

    source: str
    execution: Any
    report: Any


@dataclass
class _Step:
    edit: Edit
    state: _State


class _Search:
    """The bounded search of :func:`search`: re-simulates at most ``budget`` candidate programs, never one twice."""

    def __init__(self, evaluate, hook, not_run, budget: int):
        self.evaluate, self.hook, self.not_run, self.budget = evaluate, hook, not_run, budget
        self.tried: set[str] = set()

    def candidates(self, state: _State, verdict) -> list[_Step]:
        """Every edit offered for ``verdict``, applied and re-simulated (within the budget)."""
        out = []
        for edit in _offered_edits(self.hook, verdict, state.execution or self.not_run, state.source):
            try:
                source = apply_edits(state.source, edit.ops)
            except (RoboCriticsError, SyntaxError, ValueError):
                continue
            if source in self.tried or self.budget <= 0:
                continue  # the same program again (or out of budget): nothing to learn
            self.tried.add(source)
            self.budget -= 1
            try:
                execution, report = self.evaluate(source)
            except (RoboCriticsError, SyntaxError):
                continue  # e.g. an edit that is no longer valid Python: not a repair
            out.append(_Step(edit, _State(source, execution, report)))
        return out

    def step(self, state: _State, depth: int) -> list[_Step] | None:
        """The edits (one, or with ``depth`` > 0 up to ``depth + 1`` combined) that take ``state`` forward.

        One edit: the best (:func:`_merit`) acceptable candidate (:func:`_acceptable`) for the first
        flagged verdict that has one. Else, with ``depth`` left, the :data:`LOOKAHEAD` most promising
        candidates that run are each followed by their own best step, and the first combination that is
        :func:`_better` than ``state`` is taken (e.g. a release moved to its own spot leaves the workspace;
        the heights lowered after it bring it back).
        """
        pool: list[_Step] = []
        for verdict in _flagged(state.report):
            steps = self.candidates(state, verdict)
            good = [s for s in steps if _acceptable(state.report, s.state.report, verdict.critic)
                    or _better(state.report, s.state.report)]  # fmt: skip
            if good:
                return [max(good, key=lambda s: _merit(s.state.report, s.state.execution))]
            pool += [s for s in steps if s.state.execution is not None]
        if depth <= 0 or state.execution is None:
            return None
        pool.sort(key=lambda s: _merit(s.state.report, s.state.execution), reverse=True)
        for first in pool[:LOOKAHEAD]:
            follow = self.step(first.state, depth - 1)
            if follow and _better(state.report, follow[-1].state.report):
                return [first, *follow]
        return None


def search(program: str, scene: Scene | str, goal: Any, critics: Any, robot: Any, params: Any) -> Repair:
    """The body of :func:`robocritics.repair.repair` (its arguments and result are documented there).

    A bounded search: each round asks the flagged critics (Errors first, then Warnings)
    for edits and keeps the best acceptable one, or a combination of up to
    :data:`DEPTH` + 1 edits that is better together (:meth:`_Search.step`); the next
    round starts from there. It stops when nothing is flagged, nothing helps, or after
    :data:`MAX_ROUNDS` rounds or :data:`MAX_SIMULATIONS` re-simulations. Only
    improvements are kept, so the last program is the best one found.
    """
    from ..pipeline import check
    from ..robot.model import default_robot
    from ..scene import Scene

    scene = scene if isinstance(scene, Scene) else Scene.resolve(scene)
    from ..goals import parse_goals

    goals = parse_goals(goal, scene) or None
    robot = robot or default_robot()
    not_run = NotRun(robot.scene_for(scene), robot)

    def evaluate(source: str):
        return check(source, scene, goals=goals, critics=critics, params=params, robot=robot)

    state = _State(program, *evaluate(program))
    original = state
    finder = _Search(evaluate, _manager().hook, not_run, MAX_SIMULATIONS)
    finder.tried.add(program)
    changes: list[Change] = []
    for _ in range(MAX_ROUNDS):
        steps = finder.step(state, DEPTH)
        if not steps:
            break
        for step in steps:
            # a program that did not run had no cycle to compare with: its first running version costs 0
            before, after = state.execution, step.state.execution
            cost = after.duration_s - before.duration_s if before is not None and after is not None else 0.0
            edit = step.edit
            changes.append(Change(edit.critic, edit.line, edit.what, edit.why, cost))
            state = step.state
    return Repair(program, state.source, state.report, state.execution, changes, original.report.score,
                  original.execution.duration_s if original.execution is not None else None)  # fmt: skip
