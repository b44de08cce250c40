"""Fitting a prompt to a model's context: what to leave out, in which order, when the next call does not fit.

The loop (:mod:`robocritics.llm.loop`) builds its messages with a ``build(n_examples, api, keep, text)`` callable
(the system prompt with ``n_examples`` memory examples and the skill API in full, ``"compact"`` or ``"minimal"``
form, the last ``keep`` history messages, and the new message ``text``); :func:`fit_messages` tries them from the
richest to the smallest until the prompt and the reply fit the context, then cuts the new message, then the reply.
Tokens are estimates (:func:`robocritics.llm.prompts.estimate_tokens`).
"""

from __future__ import annotations

import logging
from typing import Callable

from .limits import MIN_REPLY_TOKENS, cut_text
from .prompts import PromptError, estimate_tokens

__all__ = ["fit_messages", "CONTEXT_MARGIN_TOKENS", "MIN_CONTEXT_TOKENS"]

log = logging.getLogger("robocritics.llm")

#: Tokens of the context left unused by a fitted prompt: the estimate's error on short texts, chat-template tokens.
CONTEXT_MARGIN_TOKENS = 64
#: Smallest context a loop accepts, tokens: the minimal prompt of a built-in scene is ~1,000 tokens plus a reply.
MIN_CONTEXT_TOKENS = 512
# History lengths tried, in messages, when the prompt does not fit (0: only the new message, the task restated).
_FITTING_HISTORY = (8, 4, 2, 0)
# Characters of the new message's feedback always kept when it is cut to fit.
_MIN_FEEDBACK_CHARS = 600


Messages = list[dict[str, str]]


def fit_messages(
    build: Callable[[int, "bool | str", int, str], Messages],
    content: str,
    *,
    context_tokens: int,
    reply_tokens: int,
    examples: int,
    keep_all: int,
) -> tuple[Messages, int | None, int]:
    """The richest prompt that fits ``context_tokens`` with a reply of ``reply_tokens``: ``(messages, max_tokens,
    prompt tokens)``, ``max_tokens`` None when the reply keeps its length, else the tokens left for it.

    Tries every count of the ``examples`` memory examples down to none, then the compact and the minimal skill
    API, then shorter histories (of ``keep_all`` messages at most); then cuts the new message ``content`` (its
    first :data:`_MIN_FEEDBACK_CHARS` characters always kept), then the reply (down to ``MIN_REPLY_TOKENS``).
    Raises :class:`~robocritics.llm.prompts.PromptError` when even that does not fit.
    """
    budget = context_tokens - CONTEXT_MARGIN_TOKENS
    candidates = [(n, False, keep_all) for n in range(examples, -1, -1)]
    candidates += [(0, "compact", keep_all), (0, "minimal", keep_all)]
    candidates += [(0, "minimal", k) for k in _FITTING_HISTORY if k < keep_all]
    messages: list[dict[str, str]] = []
    for n, api, keep in candidates:
        messages = build(n, api, keep, content)
        if estimate_tokens(messages) + reply_tokens <= budget:
            return messages, None, estimate_tokens(messages)
    # The smallest prompt still does not fit with a full reply: cut the new message, then the reply.
    _, api, keep = candidates[-1]
    fixed = estimate_tokens(messages) - estimate_tokens(content)
    room_chars = int((budget - reply_tokens - fixed) * 3.0)
    if room_chars >= _MIN_FEEDBACK_CHARS and room_chars < len(content):
        messages = build(0, api, keep, cut_text(content, room_chars))
    elif room_chars < len(content):
        messages = build(0, api, keep, cut_text(content, max(_MIN_FEEDBACK_CHARS, 80)))
    prompt = estimate_tokens(messages)
    room = budget - prompt
    if room >= reply_tokens:
        return messages, None, prompt
    if room >= MIN_REPLY_TOKENS:
        log.warning(
            "the prompt (~%d tokens) leaves %d of the %d context tokens for the reply; max_tokens lowered "
            "from %d", prompt, room, context_tokens, reply_tokens,
        )  # fmt: skip
        return messages, room, prompt
    raise PromptError(
        f"the smallest prompt for this task and scene (task, short skill API, scene) is about {prompt:,} "
        f"tokens; with {MIN_REPLY_TOKENS} tokens for the reply it needs a context of at least "
        f"{prompt + MIN_REPLY_TOKENS + CONTEXT_MARGIN_TOKENS:,} tokens, and the model has "
        f"{context_tokens:,} (context_tokens): use a model or server setting with a larger context"
    )
