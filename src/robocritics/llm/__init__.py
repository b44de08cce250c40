"""Language-model side of robocritics: the HTTP client, prompts, interaction memory and the loop.

Submodules are imported on first use, so ``import robocritics.llm`` stays cheap.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

_EXPORTS = {
    "ChatModel": "robocritics.llm.client",
    "EmbeddingModel": "robocritics.llm.client",
    "OpenAICompatible": "robocritics.llm.client",
    "InteractionMemory": "robocritics.llm.memory",
    "Interaction": "robocritics.llm.memory",
    "extract_code": "robocritics.llm.prompts",
    "system_prompt": "robocritics.llm.prompts",
    "fix_prompt": "robocritics.llm.prompts",
    "runtime_feedback": "robocritics.llm.prompts",
    "Loop": "robocritics.llm.loop",
    "Attempt": "robocritics.llm.loop",
    "NothingToFixError": "robocritics.llm.loop",
}

__all__ = list(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'robocritics.llm' has no attribute {name!r}")
    value = getattr(import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)


if TYPE_CHECKING:  # pragma: no cover
    from .client import ChatModel, EmbeddingModel, OpenAICompatible
    from .loop import Attempt, Loop, NothingToFixError
    from .memory import Interaction, InteractionMemory
    from .prompts import extract_code, fix_prompt, runtime_feedback, system_prompt
