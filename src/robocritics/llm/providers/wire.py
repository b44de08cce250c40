"""What the OpenAI-compatible provider reads and writes on the wire: its argument checks, the server's error
messages (context overflows, missing embeddings), ``Retry-After``, and the redaction of an echoed API key.
"""

from __future__ import annotations

import email.utils
import math
import re
import time
from collections.abc import Mapping, Sequence
from typing import Any

import httpx
import numpy as np

from robocritics.errors import LLMError

from ..limits import clean_text
from ..transport import loads_json
from ..protocol import LLMArgumentError

#: Environment variables the provider reads when an argument is not given.
ENV_BASE_URL = "ROBOCRITICS_BASE_URL"
ENV_MODEL = "ROBOCRITICS_MODEL"
ENV_EMBEDDING_MODEL = "ROBOCRITICS_EMBEDDING_MODEL"
ENV_API_KEYS = ("ROBOCRITICS_API_KEY", "OPENAI_API_KEY")

# Characters of a server's body quoted in an error: enough to recognise an HTML error page or a JSON error.
_EXCERPT_CHARS = 300
# Bytes of an error response read to quote it: an error page is short; the rest is not read.
_ERROR_BODY_BYTES = 64 * 1024
# Characters of the model name and finish reason taken from a reply: names are short.
_NAME_CHARS = 200
# Shorter runs of the key's characters are common in ordinary text; 8 cannot be guessed from an excerpt.
_MIN_REDACTED_RUN = 8


class _StreamRefused(LLMError):
    """The server refused ``stream: true`` (the client asks again without)."""


# Marks a reply body that was assembled from a stream.
_STREAMED = "__robocritics_streamed__"
# Bytes of a /props or /models answer read: llama.cpp's /props carries the chat template (a few KB).
_PROPS_BYTES = 1 << 20

# The server cannot embed: llama-cpp-python "Llama model must be created with embedding=True to call this method";
# llama.cpp "This server does not support embeddings. Start it with `--embeddings`"; vLLM / Ollama wordings.
_NO_EMBEDDINGS = re.compile(
    r"embedding\s*=\s*true|does not support embeddings?|embeddings? (?:are |is )?not (?:supported|enabled)"
    r"|--embeddings?\b",
    re.IGNORECASE,
)
# Context-window errors: (pattern, group of the context size, group of the requested tokens).
_CONTEXT_ERRORS = (
    # llama-cpp-python: "Requested tokens (2764) exceed context window of 2048"
    (re.compile(r"requested tokens \((\d+)\) exceed context window of (\d+)", re.IGNORECASE), 2, 1),
    # vLLM / OpenAI: "This model's maximum context length is 2048 tokens. However, you requested 2764 tokens"
    (
        re.compile(
            r"maximum context length is (\d+) tokens(?:.*?(?:requested|resulted in) (\d+) tokens)?",
            re.IGNORECASE | re.DOTALL,
        ),
        1,
        2,
    ),
    # llama.cpp: "the request exceeds the available context size, try increasing it" (+ n_ctx in the body)
    (re.compile(r"exceeds? the available context size", re.IGNORECASE), 0, 0),
    # Ollama / others: "input length exceeds the context length", "context length exceeded"
    (
        re.compile(
            r"exceeds? (?:the |its )?(?:maximum )?context (?:length|window)|context length exceeded", re.IGNORECASE
        ),
        0,
        0,
    ),
)


def _context_error(message: str, raw: bytes) -> tuple[int | None, int | None] | None:
    """(context tokens, requested tokens) if an error says the prompt is over the context, else None."""
    for pattern, ctx_group, req_group in _CONTEXT_ERRORS:
        found = pattern.search(message or "")
        if found is None:
            continue
        n_ctx = _positive_int(found.group(ctx_group)) if ctx_group else None
        requested = _positive_int(found.group(req_group)) if req_group and found.group(req_group) else None
        if n_ctx is None or requested is None:  # llama.cpp puts the numbers beside the message
            try:
                body = loads_json(raw, where="the error") if raw.strip() else None
            except LLMError:
                body = None
            error = body.get("error") if isinstance(body, dict) else None
            if isinstance(error, dict):
                n_ctx = n_ctx or _positive_int(error.get("n_ctx"))
                requested = requested or _positive_int(error.get("n_prompt_tokens"))
        return n_ctx, requested
    return None


def _positive_int(value: Any) -> int | None:
    if isinstance(value, bool):
        return None
    try:
        number = int(value)
    except (TypeError, ValueError, OverflowError):
        return None
    return number if 0 < number < 1 << 40 else None


def _props_context(body: Any) -> int | None:
    """llama.cpp's ``/props``: ``default_generation_settings.n_ctx`` (or a top-level ``n_ctx``)."""
    if not isinstance(body, dict):
        return None
    settings = body.get("default_generation_settings")
    if isinstance(settings, dict) and _positive_int(settings.get("n_ctx")):
        return _positive_int(settings.get("n_ctx"))
    return _positive_int(body.get("n_ctx"))


def _redact_secret(text: str, secret: str) -> str:
    """``text`` with every run of ``_MIN_REDACTED_RUN``+ characters of ``secret`` replaced by '***'.

    Linear in ``len(text)``: every window of the run length that occurs in the
    secret marks its characters; each maximal marked span becomes '***'.
    """
    if secret in text:
        text = text.replace(secret, "***")
    width = _MIN_REDACTED_RUN
    if len(secret) < width or len(text) < width:
        return text
    grams = {secret[i : i + width] for i in range(len(secret) - width + 1)}
    covered = bytearray(len(text))
    for i in range(len(text) - width + 1):
        if text[i : i + width] in grams:
            covered[i : i + width] = b"\x01" * width
    if not any(covered):
        return text
    out: list[str] = []
    i = 0
    while i < len(text):
        if covered[i]:
            while i < len(text) and covered[i]:
                i += 1
            out.append("***")
        else:
            out.append(text[i])
            i += 1
    return "".join(out)


def _normalise_base_url(base_url: str) -> str:
    url = str(base_url).strip().rstrip("/")
    for suffix in ("/chat/completions", "/embeddings"):
        if url.endswith(suffix):
            url = url[: -len(suffix)]
    if not url.startswith(("http://", "https://")):
        raise LLMError(
            f"base_url must start with http:// or https://, got {url!r} (argument base_url= or {ENV_BASE_URL})"
        )
    return url


def _check_messages(messages: Sequence[Any]) -> None:
    if isinstance(messages, (str, bytes)) or not isinstance(messages, Sequence) or not messages:
        raise LLMArgumentError("messages must be a non-empty list of {'role': ..., 'content': ...} dicts")
    for i, message in enumerate(messages):
        if not isinstance(message, Mapping) or "role" not in message:
            shown = clean_text(repr(message)[:80]) if isinstance(message, (str, bytes, int, float)) else type(message).__name__
            raise LLMArgumentError(f"messages[{i}] must be a dict with a 'role' key, got {shown}")


def _clean_message(message: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of ``message`` whose text (string content, or text parts) is cleaned of lone surrogates."""
    out = dict(message)
    content = out.get("content")
    if isinstance(content, str):
        out["content"] = clean_text(content)
    elif isinstance(content, list):
        out["content"] = [
            {**p, "text": clean_text(p["text"])} if isinstance(p, Mapping) and isinstance(p.get("text"), str) else p
            for p in content
        ]
    for key in ("role", "name"):
        if isinstance(out.get(key), str):
            out[key] = clean_text(out[key])
    return out


def _seconds(name: str, value: Any, *, zero: bool = False) -> float:
    """``value`` as a finite number of seconds, > 0 (or >= 0 with ``zero``); ``LLMArgumentError`` otherwise."""
    try:
        seconds = float(value)
    except (TypeError, ValueError):
        raise LLMArgumentError(f"{name} must be a number of seconds, got {value!r:.60}") from None
    if not math.isfinite(seconds) or seconds < 0 or (seconds == 0 and not zero):
        bound = ">= 0" if zero else "> 0"
        raise LLMArgumentError(f"{name} must be a finite number {bound}, got {value!r:.60}")
    return seconds


def _count(name: str, value: Any, *, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise LLMArgumentError(f"{name} must be a whole number >= {minimum}, got {value!r:.60}")
    return int(value)


def _temperature(value: Any) -> float:
    """A sampling temperature: a finite number from 0 to 2 (the range OpenAI accepts)."""
    try:
        t = float(value)
    except (TypeError, ValueError):
        raise LLMArgumentError(f"temperature must be a number from 0 to 2, got {value!r:.60}") from None
    if not (math.isfinite(t) and 0.0 <= t <= 2.0):
        raise LLMArgumentError(f"temperature must be a number from 0 to 2, got {value!r:.60}")
    return t


def _error_message(body: Any) -> str | None:
    """The human message in an OpenAI-style error body ({"error": {"message": ...}} or {"error": "..."})."""
    if not isinstance(body, dict):
        return None
    error = body.get("error")
    if isinstance(error, dict) and isinstance(error.get("message"), str):
        return error["message"]
    if isinstance(error, str):
        return error
    if isinstance(body.get("detail"), str):  # FastAPI-style servers (vLLM)
        return body["detail"]
    return None


def _retry_after_seconds(headers: httpx.Headers, now_s: float | None = None) -> float | None:
    """Seconds a server asked us to wait: ``retry-after-ms``, or ``Retry-After`` in seconds or as an HTTP date.

    An HTTP date is measured from ``now_s`` (Unix time, s; default: the current time).
    """
    ms = headers.get("retry-after-ms")
    if ms is not None:
        try:
            value = float(ms) / 1000.0
            if math.isfinite(value) and value >= 0:
                return value
        except ValueError:
            pass
    raw = headers.get("retry-after")
    if raw is None:
        return None
    raw = raw.strip()
    try:
        value = float(raw)
        return value if math.isfinite(value) and value >= 0 else None
    except ValueError:
        pass
    try:
        when = email.utils.parsedate_to_datetime(raw)
    except (TypeError, ValueError):
        return None
    if when is None:
        return None
    return max(0.0, when.timestamp() - (time.time() if now_s is None else now_s))
