"""robocritics: LLM robot programming you can check before it moves a robot.

A language model writes a program against a small skill API; :func:`simulate`
turns it into a physically timed motion trace (:class:`Trajectory`); expert-informed
critics (:func:`critique`) flag joint speed, space usage, collision, spearing
and pinch-point problems with explanations and fix hints (:class:`Report`);
:func:`repair` applies the critics' own fixes, verified by simulation;
:class:`Loop` sends what is left back to the model; only a verified trace is
deployed to a UR3e (:mod:`robocritics.deploy`).

The root holds the names most programs need; everything else lives in its
module: ``robocritics.trajectory.State``,
``robocritics.critic`` (``Evidence``, ``get_critics``, ``critic_sources``,
``register``, the verdict helpers), ``robocritics.llm`` (``OpenAICompatible``,
``Attempt``), ``robocritics.deploy`` (``URArm``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ._lazy import lazy_exports

__version__ = "0.1.0"

# Public names and the modules that define them. Imported lazily so that
# `import robocritics` stays cheap and a missing optional part never breaks it.
_EXPORTS = {
    "Robot": "robocritics.robot.model",
    "Scene": "robocritics.scene",
    "Trajectory": "robocritics.trajectory",
    "Execution": "robocritics.execution",
    "simulate": "robocritics.pipeline",
    "check": "robocritics.pipeline",
    "critique": "robocritics.critic",
    "Critic": "robocritics.critic",
    "CriticParams": "robocritics.critic",
    "Flag": "robocritics.critic.verdict",
    "Verdict": "robocritics.critic.verdict",
    "Report": "robocritics.critic.report",
    "hookimpl": "robocritics.critic.hookspecs",
    "Loop": "robocritics.llm.loop",
}
# Names that used to be exported here, and the module to import them from.
_MOVED = {
    "State": "robocritics.trajectory",
    "Evidence": "robocritics.critic",
    "get_critics": "robocritics.critic",
    "critic_sources": "robocritics.critic",
    "URArm": "robocritics.deploy",
    "Attempt": "robocritics.llm",
    "OpenAICompatible": "robocritics.llm",
}

# Eager, and cheap (its heavy imports are inside the function): the subpackage
# `robocritics.repair` would otherwise shadow the function of the same name.
from .repair import repair  # noqa: E402
from .errors import (  # noqa: E402
    CriticError,
    DeployError,
    LLMError,
    PlanningError,
    ProgramError,
    RobotModelError,
    RoboCriticsError,
    RTDEError,
    SceneError,
    TrajectoryError,
)

_ERRORS = (
    "RoboCriticsError",
    "SceneError",
    "ProgramError",
    "PlanningError",
    "TrajectoryError",
    "RobotModelError",
    "CriticError",
    "LLMError",
    "DeployError",
    "RTDEError",
)

__all__ = [*_EXPORTS, "repair", *_ERRORS]


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals(), moved=_MOVED)


if TYPE_CHECKING:  # pragma: no cover
    from .critic import Critic, CriticParams, critique
    from .execution import Execution
    from .pipeline import check, simulate
    from .critic.hookspecs import hookimpl
    from .llm.loop import Loop
    from .critic.report import Report
    from .robot.model import Robot
    from .scene import Scene
    from .trajectory import Trajectory
    from .critic.verdict import Flag, Verdict
