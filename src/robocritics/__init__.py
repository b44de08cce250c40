"""robocritics: LLM robot programming you can check before it moves a robot.

A language model writes a program against a small skill API; :func:`simulate`
turns it into a physically timed motion trace (:class:`Trajectory`); expert-informed
critics (:func:`critique`) flag joint speed, space usage, collision, spearing
and pinch-point problems with explanations and fix hints (:class:`Report`);
:class:`Loop` sends that feedback back to the model; only a verified trace is
deployed to a UR3e (:mod:`robocritics.deploy`).
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
    "State": "robocritics.trajectory",
    "critique": "robocritics.critic",
    "Flag": "robocritics.critic",
    "Verdict": "robocritics.critic",
    "Report": "robocritics.critic",
    "Critic": "robocritics.critic",
    "CriticParams": "robocritics.critic",
    "Evidence": "robocritics.critic",
    "get_critics": "robocritics.critic",
    "critic_sources": "robocritics.critic",
    "hookimpl": "robocritics.hookspecs",
    "URArm": "robocritics.deploy.stream",
    "Loop": "robocritics.llm.loop",
    "Attempt": "robocritics.llm.loop",
    "OpenAICompatible": "robocritics.llm.client",
}
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

# Eager, and cheap (its heavy imports are inside the function): the submodule
# `robocritics.simulate` would otherwise shadow the function of the same name.
from .simulate import Execution, simulate  # noqa: E402
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

__all__ = [*_EXPORTS, "simulate", "Execution", *_ERRORS]


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())


if TYPE_CHECKING:  # pragma: no cover
    from .critic import Critic, CriticParams, Evidence, Flag, Report, Verdict, critic_sources, critique, get_critics
    from .hookspecs import hookimpl
    from ..deploy.stream import URArm
    from .llm.client import OpenAICompatible
    from .llm.loop import Attempt, Loop
    from .robot.model import Robot
    from .scene import Scene
    from .trajectory import State, Trajectory
