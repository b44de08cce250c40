"""Task outcome: did every object end where the task's goals say? (planning level)

Goals (:class:`robocritics.goals.Goal`: ``"green_apple in white_box"``, ``"cupcake on plate"``) come from
``critique(execution, goals=[...])``, ``--goal`` on the command line (both end up in ``execution.goals``) and
the program's own ``expect(obj, inside=container)`` / ``expect(obj, on=support)`` calls. The critic checks them
on the execution's final scene:

* ERROR when any goal is unmet, naming each object and where it ended (e.g. "green_apple ended on the table
  at (0.31, -0.12) m, 0.18 m from white_box");
* OK when all are met;
* OK with the message "no task goals were given: nothing to check" when there are none and it was named.

It is an on-demand critic: ``requested(execution)`` is true when the run has goals, so the default selection
runs it only then, and any selection runs it then.

It is not part of the 0-10 score (:attr:`robocritics.critic.report.Report.scored_verdicts`: the five motion
critics), but its Error makes ``Report.has_errors`` true and ``Report.passed`` false.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict

from ...goals import GoalOutcome, check_outcomes, program_goals
from ..hookspecs import hookimpl
from ..verdict import Evidence, Flag, Verdict

__all__ = ["TaskOutcomeCritic", "GoalOutcome", "register_critics"]

NAME = "task_outcome"


# a CriticParams (frozen, unknown fields rejected) without importing robocritics.critic, which imports this module
class Params(BaseModel):
    """No thresholds: a goal is met or not (the tolerance of "on" is :data:`robocritics.goals.ON_TOLERANCE_M`)."""

    model_config = ConfigDict(frozen=True, extra="forbid")


class TaskOutcomeCritic:
    name = NAME
    description = "Task goals (object in container / on support) checked on the final scene."
    Params = Params

    def requested(self, execution) -> bool:
        """The run asks for this critic when it has goals: given ones or the program's ``expect(...)`` calls."""
        return bool(execution.goals) or bool(program_goals(execution.plan))

    def check(self, execution, params: Params) -> Verdict:
        outcomes = check_outcomes(execution)
        if not outcomes:
            return Verdict(
                critic=NAME,
                flag=Flag.OK,
                message="no task goals were given: nothing to check",
                hint="state goals with --goal 'obj in container', critique(..., goals=[...]) or expect(obj, inside=box)",
            )
        unmet = [o for o in outcomes if not o.met]
        met = len(outcomes) - len(unmet)
        details = {"goals": [o.model_dump(mode="json") for o in outcomes]}
        if not unmet:
            return Verdict(
                critic=NAME,
                flag=Flag.OK,
                message=f"all {len(outcomes)} task goal{'s' if len(outcomes) > 1 else ''} met: "
                + "; ".join(o.goal for o in outcomes),
                value=float(met),
                threshold=float(len(outcomes)),
                unit="goals met",
                details=details,
            )
        lines = sorted({line for o in unmet for line in o.lines})
        return Verdict(
            critic=NAME,
            flag=Flag.ERROR,
            message=f"{len(unmet)} of {len(outcomes)} task goals unmet: "
            + "; ".join(f"'{o.goal}' — {o.where}" for o in unmet),
            hint="change where the program releases "
            + ", ".join(dict.fromkeys(o.object for o in unmet if o.object))
            + " (its last open_gripper), or check that it is grasped at all (a missed grasp leaves it in place)",
            value=float(met),
            threshold=float(len(outcomes)),
            unit="goals met",
            evidence=Evidence(objects=list(dict.fromkeys(o.object for o in unmet if o.object)), lines=lines),
            details=details,
        )


@hookimpl
def register_critics(register):
    register(TaskOutcomeCritic())
