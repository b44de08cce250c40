"""The seam between robocritics and a language model: :class:`ChatModel` and :class:`EmbeddingModel` (the only
things ``llm.loop`` and ``llm.memory`` depend on: a test or a user plugs in anything with the right two members),
what a chat call returns (:class:`ChatReply`, :class:`ChatProgress`), and the errors any provider raises.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from robocritics.errors import LLMError

__all__ = [
    "ChatModel",
    "ChatProgress",
    "ChatReply",
    "ContextLengthError",
    "EmbeddingModel",
    "EmbeddingsUnavailableError",
    "GenerationTimeoutError",
    "LLMArgumentError",
    "embedding_space_name",
]


class LLMArgumentError(LLMError, ValueError):
    """A bad argument to the client: malformed messages, an out-of-range limit or option, a request too large."""


class ContextLengthError(LLMError):
    """The server refused the request as longer than the model's context window (final: not retried).

    ``context_tokens`` is the context the server reported (e.g. llama-cpp-python's "Requested tokens (2764)
    exceed context window of 2048", llama.cpp's ``n_ctx``, vLLM's "maximum context length is 2048 tokens"),
    ``requested_tokens`` what it counted for the request; either is None when the server did not say.
    """

    def __init__(self, message: str, *, context_tokens: int | None = None, requested_tokens: int | None = None):
        super().__init__(message)
        self.context_tokens = context_tokens
        self.requested_tokens = requested_tokens


class EmbeddingsUnavailableError(LLMError):
    """The server cannot embed at all (HTTP 501, or 500 "must be created with embedding=True"): final, not retried."""


class GenerationTimeoutError(LLMError):
    """The server stopped sending (or never answered) while it was generating: final, never retried.

    Retrying would leave the abandoned generation running on the server and start another one.
    """


@dataclass(frozen=True)
class ChatProgress:
    """What a chat request is doing, for a progress line (``OpenAICompatible(on_progress=...)``).

    ``phase`` is ``"waiting"`` (the request was sent; no token yet), ``"receiving"`` (a streamed token arrived)
    or ``"done"``. ``tokens`` counts the reply's tokens so far (streamed chunks, or the server's
    ``completion_tokens``), ``chars`` its characters, ``elapsed_s`` the seconds since the call began.
    :attr:`text` is the reply received so far (``chars`` characters, at most ``max_reply_chars``), so a UI
    can show it as it arrives.
    """

    phase: str
    tokens: int
    chars: int
    elapsed_s: float
    # The reply's pieces (a list that only grows) and how many of them had arrived: the text is joined
    # only when read, so reporting every chunk of a long reply does not copy it once per chunk.
    _parts: Sequence[str] = field(default=(), repr=False, compare=False)
    _count: int = field(default=0, repr=False, compare=False)

    @property
    def text(self) -> str:
        """The reply text received so far ("" while waiting; the whole reply when done)."""
        return "".join(self._parts[: self._count])


@runtime_checkable
class ChatModel(Protocol):
    """Anything that turns a chat transcript into the assistant's next message."""

    @property
    def name(self) -> str:
        """The model's name, for logs and for tagging what it produced."""
        ...

    def complete(self, messages: list[dict], **kw: Any) -> str:
        """Return the assistant's reply to ``messages``.

        ``messages`` are OpenAI-style dicts: ``{"role": "system" | "user" |
        "assistant", "content": str}``. Keyword arguments are model options
        (``temperature``, ``max_tokens``, ``seed``, ``stop`` ...). Raises
        ``LLMError`` when no usable reply can be obtained.
        """
        ...


@runtime_checkable
class EmbeddingModel(Protocol):
    """Anything that maps texts to fixed-length vectors.

    ``name`` identifies the vector space: two embedders with the same name must
    produce comparable vectors. An object that is also a ``ChatModel`` (whose
    ``name`` is the chat model) may expose ``embedding_name`` instead; see
    ``embedding_space_name``.
    """

    @property
    def name(self) -> str:
        """The embedding model's name (the identity of its vector space)."""
        ...

    def embed(self, texts: list[str]) -> np.ndarray:
        """Return a float array of shape ``(len(texts), d)``, row i embedding ``texts[i]``."""
        ...


def embedding_space_name(embedder: EmbeddingModel) -> str:
    """The name that identifies ``embedder``'s vectors.

    ``embedder.embedding_name`` when the object has a non-empty one (as
    ``OpenAICompatible`` does, since its ``name`` is the chat model), otherwise
    ``embedder.name``.
    """
    specific = getattr(embedder, "embedding_name", None)
    return str(specific) if specific else str(embedder.name)


@dataclass(frozen=True)
class ChatReply:
    """One chat completion: the text plus what the server said about it.

    ``finish_reason`` is ``"stop"`` for a complete answer and ``"length"`` when
    the server cut it at the token limit. ``usage`` is the server's token
    accounting (``prompt_tokens``, ``completion_tokens``, ``total_tokens``) or
    an empty dict if it sent none. ``attempts`` counts HTTP requests made.
    """

    content: str
    model: str
    finish_reason: str | None = None
    usage: Mapping[str, Any] = field(default_factory=dict)
    attempts: int = 1
    max_tokens: int | None = None
    streamed: bool = False

    @property
    def truncated(self) -> bool:
        """Whether the server cut the reply at its token limit (``finish_reason == "length"``)."""
        return self.finish_reason == "length"

    @property
    def completion_tokens(self) -> int | None:
        """The reply's length in tokens, as the server counted it (or streamed chunks), or None."""
        value = self.usage.get("completion_tokens") if isinstance(self.usage, Mapping) else None
        return int(value) if isinstance(value, (int, float)) and not isinstance(value, bool) and value >= 0 else None
