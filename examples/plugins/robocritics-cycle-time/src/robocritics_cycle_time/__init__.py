"""Cycle-time critic: a third-party robocritics plugin (CoFrame's business frame).

The duration of the trajectory on its physical time axis, ``T = time[-1] - time[0]``
(s), against a target and a maximum cycle time. Where the time goes is found
per program step: the duration of each sample interval ``time[t+1] - time[t]``
is credited to the step of sample ``t+1`` and summed per step with
``numpy.bincount``.

The plugin also offers a repair (the ``robocritics_repairs`` hook): the slowest
steps run faster (:data:`SPEEDUP` times the speed in effect, at most full
speed), restored after each step; ``robocritics.repair`` keeps the edit only
if no safety critic gets worse.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field, model_validator

from robocritics import hookimpl
from robocritics.critic import CriticParams, Flag, Verdict, format_lines, make_evidence, make_signal, threshold_verdict

__all__ = ["CycleTimeCritic", "register_critics", "robocritics_repairs"]
__version__ = "0.1.0"


class Params(CriticParams):
    target_cycle_time_s: float = Field(
        45.0,
        gt=0,
        description="warning when the trajectory lasts longer than this, s "
        "(task-specific business target; CoFrame's business frame leaves it to the operator)",
    )
    max_cycle_time_s: float = Field(
        90.0, gt=0, description="error when the trajectory lasts longer than this, s (task-specific upper bound)"
    )
    slowest_steps: int = Field(3, ge=1, le=20, description="how many of the longest program steps the hint names")

    @model_validator(mode="after")
    def _order(self) -> "Params":
        if self.target_cycle_time_s > self.max_cycle_time_s:
            raise ValueError(
                f"target_cycle_time_s ({self.target_cycle_time_s}) must not exceed max_cycle_time_s ({self.max_cycle_time_s})"
            )
        return self


class CycleTimeCritic:
    name = "cycle_time"
    description = "Trajectory duration against a target and a maximum cycle time (CoFrame business frame)."
    Params = Params

    def check(self, trajectory, scene, params: Params) -> Verdict:
        time = trajectory.time
        duration = float(time[-1] - time[0])
        elapsed = time - time[0]
        signal = make_signal(
            time,
            elapsed,
            label="elapsed time",
            unit="s",
            warning=params.target_cycle_time_s,
            error=params.max_cycle_time_s,
        )
        # time spent per program step (no loop over samples)
        per_step = np.zeros(max(len(trajectory.steps), 1))
        if len(time) > 1 and trajectory.steps:
            per_step = np.bincount(trajectory.step[1:], weights=np.diff(time), minlength=len(trajectory.steps))
        order = np.argsort(per_step)[::-1][: params.slowest_steps]
        slow = [
            (trajectory.steps[i], float(per_step[i])) for i in order if trajectory.steps and per_step[i] > 0
        ]
        details = {
            "duration_s": duration,
            "slowest_steps": [
                {"skill": s.skill, "line": s.line, "seconds": round(sec, 3)} for s, sec in slow
            ],
        }
        if duration > params.target_cycle_time_s:
            flag = Flag.ERROR if duration > params.max_cycle_time_s else Flag.WARNING
            threshold = params.max_cycle_time_s if flag is Flag.ERROR else params.target_cycle_time_s
            over = elapsed > threshold
            ev = make_evidence(trajectory, over, worst=len(time) - 1)
            ev = ev.model_copy(
                update={"lines": sorted({s.line for s, _ in slow if s.line > 0}), "skills": [s.skill for s, _ in slow]}
            )
            parts = [
                f"[{s.skill}] on {format_lines([s.line])} ({sec:.1f} s)" if s.line > 0 else f"[{s.skill}] ({sec:.1f} s)"
                for s, sec in slow
            ]
            longest = f" The longest steps are {', '.join(parts)}." if parts else ""
            word = "maximum" if flag is Flag.ERROR else "target"
            return threshold_verdict(
                self.name,
                trajectory,
                flag,
                evidence=ev,
                message=f"The program takes {duration:.1f} s, longer than the {word} cycle time of {threshold:g} s.",
                hint="To shorten the cycle time, you can consider removing redundant moves, moving through fewer "
                f"waypoints or raising the speed where it is safe.{longest}",
                value=duration,
                threshold=threshold,
                unit="s",
                signal=signal,
                details=details,
            )
        return threshold_verdict(
            self.name,
            trajectory,
            Flag.OK,
            worst=len(time) - 1,
            message=f"The program takes {duration:.1f} s, within the target cycle time of {params.target_cycle_time_s:g} s.",
            value=duration,
            threshold=params.target_cycle_time_s,
            unit="s",
            signal=signal,
            details=details,
        )


@hookimpl
def register_critics(register):
    register(CycleTimeCritic())


#: How much faster the repair runs the slowest steps (factor on the speed fraction in effect).
SPEEDUP = 2.0



@hookimpl
def robocritics_repairs(verdict, execution, program):
    """Run the lines that take the most time :data:`SPEEDUP` times faster, until the saving covers the excess.

    Doubling the speed of a step roughly halves its time, so lines are taken,
    slowest first, until half their time adds up to ``value - threshold`` (s).
    """
    if verdict.critic != "cycle_time" or verdict.value is None or verdict.threshold is None:
        return []
    from robocritics.repair import Edit, Insert

    trajectory = execution.trajectory
    per_step = np.bincount(trajectory.step[1:], weights=np.diff(trajectory.time), minlength=len(trajectory.steps))
    per_line: dict[int, float] = {}
    for step, seconds in zip(trajectory.steps, per_step):
        if step.line > 0 and (step.skill.startswith("move") or step.skill == "home"):
            per_line[step.line] = per_line.get(step.line, 0.0) + float(seconds)
    excess = verdict.value - verdict.threshold
    ops, parts, saved = [], [], 0.0
    for line, seconds in sorted(per_line.items(), key=lambda kv: -kv[1]):
        prev = execution.plan.speed_at(line)
        fast = min(1.0, round(prev * SPEEDUP, 2))
        if fast <= prev:
            continue
        ops.append(Insert(line, before=(f"set_speed({fast:g})",), after=(f"set_speed({prev:g})",)))
        parts.append(f"line {line}: speed {prev:g} -> {fast:g}")
        saved += seconds * (1 - prev / fast)
        if saved > excess:
            break
    if not ops:
        return []
    return [Edit("cycle_time", ops[0].line, "; ".join(parts), f"the program takes {verdict.value:.1f} s", ops)]
