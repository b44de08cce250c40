"""The options of an LLM loop (:class:`robocritics.llm.loop.Loop`), grouped: how much it automates, how it
remembers, how it asks the model, how it checks programs. Each is documented on ``Loop``; bad values raise here,
before any model call.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any, Callable, Literal, Mapping

from .fitting import MIN_CONTEXT_TOKENS

__all__ = ["LoopOptions", "AUTOMATION_LEVELS", "Automation", "Approve"]

AUTOMATION_LEVELS = ("manual", "guided", "auto")
Automation = Literal["manual", "guided", "auto"]
Approve = Callable[[str, str], bool]

#: User/assistant messages sent per call: the last few revisions, small enough for a small model's context.
DEFAULT_MAX_HISTORY_MESSAGES = 12
#: Model replies per run: the paper's limit of five attempts per task.
DEFAULT_MAX_ATTEMPTS = 5


@dataclass(frozen=True)
class LoopOptions:
    """Everything about a :class:`~robocritics.llm.loop.Loop` besides its model, scene, robot, critics, memory and
    goals (see ``Loop`` for each). ``LoopOptions(max_attempts=3)``; ``options.updated(automation="auto")``."""

    automation: Automation = "guided"
    approve: Approve | None = None
    session: str | None = None
    max_history_messages: int = DEFAULT_MAX_HISTORY_MESSAGES
    max_attempts: int = DEFAULT_MAX_ATTEMPTS
    memory_k: int = 3
    embedded_rules: bool = False
    on_attempt: Callable[[Any], None] | None = None
    model_options: Mapping[str, Any] | None = None
    sample_rate_hz: float | None = None
    context_tokens: int | None = None
    simulate: Callable[[str], Any] | None = None
    repairs: bool | Callable[[str], Any] = True

    def __post_init__(self) -> None:
        if self.automation not in AUTOMATION_LEVELS:
            raise ValueError(f"automation must be one of {', '.join(AUTOMATION_LEVELS)}, got {self.automation!r}")
        if int(self.max_history_messages) < 2:
            raise ValueError(f"max_history_messages must be at least 2, got {self.max_history_messages}")
        if int(self.max_attempts) < 1:
            raise ValueError(f"max_attempts must be at least 1, got {self.max_attempts}")
        if int(self.memory_k) < 0:
            raise ValueError(f"memory_k must be >= 0, got {self.memory_k}")
        if self.context_tokens is not None and int(self.context_tokens) < MIN_CONTEXT_TOKENS:
            raise ValueError(f"context_tokens must be at least {MIN_CONTEXT_TOKENS}, got {self.context_tokens}")
        if self.approve is not None and not callable(self.approve):
            raise TypeError("approve must be a callable approve(program, diff) -> bool")
        if self.simulate is not None and not callable(self.simulate):
            raise TypeError("simulate must be a callable simulate(program) -> (Execution, Report)")

    def updated(self, **changes: Any) -> LoopOptions:
        """These options with ``changes``; a name that is no option is a TypeError naming it and the options."""
        names = [f.name for f in fields(self)]
        unknown = sorted(set(changes) - set(names))
        if unknown:
            raise TypeError(f"Loop() got unexpected keyword argument(s) {', '.join(unknown)} (options: {', '.join(names)})")
        return replace(self, **changes) if changes else self
