"""Language-model side of robocritics: the HTTP client, prompts, interaction memory and the loop.

Submodules are imported on first use, so ``import robocritics.llm`` stays cheap.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

_EXPORTS = {
    "ChatModel": "robocritics.llm.protocol",
    "EmbeddingModel": "robocritics.llm.protocol",
    "OpenAICompatible": "robocritics.llm.providers.openai_compatible",
    "LLMArgumentError": "robocritics.llm.protocol",
    "InteractionMemory": "robocritics.llm.memory",
    "Interaction": "robocritics.llm.memory",
    "InteractionMemoryError": "robocritics.llm.memory",
    "PromptError": "robocritics.llm.prompts",
    "extract_code": "robocritics.llm.prompts",
    "system_prompt": "robocritics.llm.prompts",
    "fix_prompt": "robocritics.llm.prompts",
    "runtime_feedback": "robocritics.llm.prompts",
    "Loop": "robocritics.llm.loop",
    "Attempt": "robocritics.llm.loop",
    "NothingToFixError": "robocritics.llm.loop",
}

__all__ = list(_EXPORTS)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())


if TYPE_CHECKING:  # pragma: no cover
    from .protocol import ChatModel, EmbeddingModel, LLMArgumentError
    from .providers.openai_compatible import OpenAICompatible
    from .loop import Attempt, Loop, NothingToFixError
    from .memory import Interaction, InteractionMemory, InteractionMemoryError
    from .prompts import PromptError, extract_code, fix_prompt, runtime_feedback, system_prompt
