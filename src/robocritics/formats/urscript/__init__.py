"""URScript programs, parsed and interpreted by robocritics (never executed as Python) and timed with UR's
motion model; see docs/formats.md for the subset and what is refused.

:func:`run_urscript` turns a script into the :class:`~robocritics.simulate.Execution` the critics read.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .commands import Arm, ArmOptions
from .interpreter import MAX_STEPS, Interpreter
from .syntax import UnsupportedURScript, URScriptError, parse

if TYPE_CHECKING:  # pragma: no cover
    from ...robot.model import Robot
    from ...scene import Scene
    from ...execution import Execution

__all__ = ["run_urscript", "ArmOptions", "URScriptError", "UnsupportedURScript", "parse"]


def run_urscript(
    source: str,
    robot: "Robot",
    scene: "Scene",
    options: ArmOptions | None = None,
    *,
    passes: int = 1,
    name: str = "script",
    max_steps: int = MAX_STEPS,
) -> "Execution":
    """The run of URScript ``source`` on ``robot`` in ``scene``: its trajectory, ``plan=None``, ``source`` set.

    ``options``: the installation's TCP, payload, start joints and gripper output (:class:`ArmOptions`).
    ``passes``: iterations judged of a loop that runs forever or waits on an input. Raises
    :class:`UnsupportedURScript` (construct and line) for what is outside the subset,
    :class:`URScriptError` for a script that is not valid or hits a limit, and
    :class:`~robocritics.errors.PlanningError` (with the line) for a target the arm cannot reach.
    """
    from ..grasps import imported_execution

    if not isinstance(passes, int) or passes < 1:
        raise URScriptError(f"passes must be a whole number >= 1, got {passes!r}")
    options = options or ArmOptions()
    tree = parse(source)
    arm = Arm(robot, options, source.splitlines())
    interpreter = Interpreter(tree, arm, passes=passes, max_steps=max_steps)
    interpreter.run()
    arm.flush_servo()
    if not arm.timeline.segments:
        raise URScriptError("the script commands no motion, so there is nothing to check", line=1)
    time, values, step = arm.timeline.samples(options.rate_hz)
    notes = "; ".join(interpreter.notes)
    described = f"URScript {name}" + (f" ({notes})" if notes else "")
    return imported_execution(robot, scene, values[:, :-1], time, values[:, -1], described, step=step, steps=arm.steps)
