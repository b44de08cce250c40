"""One exception tree for everything robocritics raises on bad input.

Every error says *what* is wrong and *where* (a field path, a program line, a
target position, a sample index), so a person or an LLM can act on it.
"""

from __future__ import annotations


class RoboCriticsError(Exception):
    """Base class of every error robocritics raises on purpose."""


class SceneError(RoboCriticsError, ValueError):
    """A scene description is malformed. ``path`` names the offending field."""

    def __init__(self, message: str, path: str = ""):
        self.path = path
        super().__init__(f"{path}: {message}" if path else message)


class RobotModelError(RoboCriticsError, ValueError):
    """A robot description (URDF, frame name, joint vector) is unusable."""


class TrajectoryError(RoboCriticsError, ValueError):
    """A trajectory's arrays disagree in shape, are not finite, or time does not increase."""


class ProgramError(RoboCriticsError):
    """An LLM-written program was rejected by the sandbox or failed while running.

    ``line`` and ``col`` are 1-based positions in the program source (0 if unknown).
    """

    def __init__(self, message: str, line: int = 0, col: int = 0):
        self.line = line
        self.col = col
        self.reason = message
        where = f"line {line}, column {col}: " if line else ""
        super().__init__(f"{where}{message}")


class PlanningError(RoboCriticsError):
    """A motion could not be planned: unreachable target, joint limits, no route.

    ``line`` is the program line of the skill call that asked for it (0 if unknown).
    """

    def __init__(self, message: str, line: int = 0):
        self.line = line
        self.reason = message
        super().__init__(f"line {line}: {message}" if line else message)


class CriticError(RoboCriticsError):
    """A critic is unknown, misconfigured, or given invalid parameters."""


class LLMError(RoboCriticsError):
    """The language-model endpoint failed or answered something unusable."""


class DeployError(RoboCriticsError):
    """Deployment to the robot was refused by the gate or stopped by a fault.

    ``sample`` is the index of the last trajectory sample sent (-1 if none was).
    """

    def __init__(self, message: str, sample: int = -1, cause: str = ""):
        self.sample = sample
        self.cause = cause or message
        super().__init__(message if sample < 0 else f"{message} (at sample {sample})")


class RTDEError(DeployError):
    """The RTDE or Dashboard conversation with the controller failed."""


class GoalError(RoboCriticsError, ValueError):
    """A task goal (``"green_apple in white_box"``) is malformed or names ids the scene does not have."""
