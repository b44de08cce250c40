"""Language-model endpoints: the protocols the rest of robocritics talks to, and
one HTTP implementation for any OpenAI-compatible server.

``ChatModel`` and ``EmbeddingModel`` are the only things ``llm.loop`` and
``llm.memory`` depend on, so a test or a user can plug in anything that has the
right two members. ``OpenAICompatible`` implements both on top of httpx and
works with OpenAI, Ollama (``http://localhost:11434/v1``), vLLM, llama.cpp's
server, LM Studio and similar: it POSTs to ``{base_url}/chat/completions`` and
``{base_url}/embeddings``.

Failure policy of ``OpenAICompatible``:

* HTTP 408, 409, 429 and every 5xx, timeouts and connection errors (refused,
  reset, dropped before the response) are retried up to ``max_retries`` times
  with exponential backoff ``backoff_base_s * 2**attempt`` (capped at
  ``backoff_max_s``). A ``Retry-After`` header (seconds or HTTP date; or
  ``retry-after-ms``) is honoured: the wait is at least
  ``min(retry_after * retry_after_scale, retry_after_cap_s)``.
* 401/403 raise ``LLMError`` pointing at the API key, 404 and redirects at
  ``base_url`` (and the model name), other 4xx carry the server's own message.
* A body that is not JSON, or JSON without ``choices[0].message.content``,
  raises ``LLMError`` quoting (a truncated, redacted excerpt of) what arrived.
* The API key never appears in ``repr``/``str``, log records or error messages;
  any part of it a server echoes back (8 characters or more) is replaced by
  ``***`` before it reaches an exception.
"""

from __future__ import annotations

import base64
import email.utils
import json
import logging
import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import httpx
import numpy as np

from robocritics.errors import LLMError

__all__ = [
    "ChatModel",
    "ChatReply",
    "EmbeddingModel",
    "OpenAICompatible",
    "embedding_space_name",
]

log = logging.getLogger("robocritics.llm")

ENV_BASE_URL = "ROBOCRITICS_BASE_URL"
ENV_MODEL = "ROBOCRITICS_MODEL"
ENV_EMBEDDING_MODEL = "ROBOCRITICS_EMBEDDING_MODEL"
ENV_API_KEYS = ("ROBOCRITICS_API_KEY", "OPENAI_API_KEY")

#: Statuses that mean "try again later" rather than "your request is wrong".
RETRYABLE_STATUSES = frozenset({408, 409, 429})

#: Seconds per network phase: a local model can take most of a minute before the first byte of a long prompt.
DEFAULT_TIMEOUT_S = 60.0
#: Extra attempts: with the default backoff, about 7.5 s of waiting in all, enough to ride out a server restart.
DEFAULT_MAX_RETRIES = 4
#: Longest pause between two attempts, s: past it, waiting longer only delays the error.
DEFAULT_BACKOFF_MAX_S = 30.0
#: Longest Retry-After honoured, s: a server that asks for more is treated as down rather than throttling.
DEFAULT_RETRY_AFTER_CAP_S = 60.0

# Characters of a server's body quoted in an error: enough to recognise an HTML error page or a JSON error.
_EXCERPT_CHARS = 300
# Shorter runs of the key's characters are common in ordinary text; 8 cannot be guessed from an excerpt.
_MIN_REDACTED_RUN = 8


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


class _Secret:
    """Holds the API key so that no repr, str or format of the holder shows it."""

    __slots__ = ("_value",)

    def __init__(self, value: str):
        self._value = value

    def reveal(self) -> str:
        return self._value

    def __repr__(self) -> str:
        return "'***'"

    __str__ = __repr__

    def __reduce__(self):  # never pickle the key along with a client
        raise TypeError("the API key holder cannot be pickled")


class _BearerAuth(httpx.Auth):
    """Adds ``Authorization: Bearer <key>`` to each request without storing it in client headers."""

    def __init__(self, secret: _Secret):
        self._secret = secret

    def auth_flow(self, request: httpx.Request):
        request.headers["Authorization"] = f"Bearer {self._secret.reveal()}"
        yield request


class OpenAICompatible:
    """Chat and embeddings over the OpenAI HTTP API, from any compatible server.

    Arguments fall back to the environment:

    * ``base_url`` ← ``ROBOCRITICS_BASE_URL`` (e.g. ``https://api.openai.com/v1``
      or ``http://localhost:11434/v1``); a trailing ``/chat/completions`` or
      ``/embeddings`` is stripped.
    * ``model`` ← ``ROBOCRITICS_MODEL`` (the chat model).
    * ``embedding_model`` ← ``ROBOCRITICS_EMBEDDING_MODEL`` (needed only by ``embed``).
    * ``api_key`` ← ``ROBOCRITICS_API_KEY``, then ``OPENAI_API_KEY``; servers
      that need none (Ollama, llama.cpp) work without it.

    ``timeout_s`` (seconds) bounds each network phase (connect, each read,
    write). ``max_retries`` is the number of *extra* attempts after the first,
    so at most ``max_retries + 1`` requests are sent per call. Backoff before
    retry n (0-based) is ``min(backoff_base_s * 2**n, backoff_max_s)`` seconds,
    raised to the server's ``Retry-After`` × ``retry_after_scale`` capped at
    ``retry_after_cap_s``; ``sleep(seconds)`` does the waiting (tests pass one
    that records the pauses instead). ``transport`` is passed to ``httpx.Client``.

    ``name`` is the chat model; ``embedding_name`` the embedding model.
    """

    def __init__(
        self,
        base_url: str | None = None,
        model: str | None = None,
        api_key: str | None = None,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        max_retries: int = DEFAULT_MAX_RETRIES,
        embedding_model: str | None = None,
        temperature: float = 0.0,
        transport: httpx.BaseTransport | None = None,
        *,
        backoff_base_s: float = 0.5,
        backoff_max_s: float = DEFAULT_BACKOFF_MAX_S,
        retry_after_cap_s: float = DEFAULT_RETRY_AFTER_CAP_S,
        retry_after_scale: float = 1.0,
        embedding_batch_size: int = 64,
        sleep: Callable[[float], None] = time.sleep,
    ):
        base_url = base_url or os.environ.get(ENV_BASE_URL) or None
        model = model or os.environ.get(ENV_MODEL) or None
        if not base_url:
            raise LLMError(
                f"no LLM endpoint configured: pass base_url= or set {ENV_BASE_URL} "
                "(e.g. https://api.openai.com/v1 or http://localhost:11434/v1 for Ollama)"
            )
        if not model:
            raise LLMError(
                f"no chat model configured: pass model= or set {ENV_MODEL} (e.g. gpt-4o-mini, or llama3.1 for Ollama)"
            )
        self.base_url = _normalise_base_url(base_url)
        self.model = str(model)
        self.embedding_model = embedding_model or os.environ.get(ENV_EMBEDDING_MODEL) or None
        if api_key is None:
            api_key = next((os.environ[v] for v in ENV_API_KEYS if os.environ.get(v)), None)
        self._api_key = _Secret(api_key) if api_key else None

        if timeout_s <= 0 or not math.isfinite(timeout_s):
            raise ValueError(f"timeout_s must be a positive number of seconds, got {timeout_s!r}")
        if max_retries < 0:
            raise ValueError(f"max_retries must be >= 0, got {max_retries!r}")
        if embedding_batch_size < 1:
            raise ValueError(f"embedding_batch_size must be >= 1, got {embedding_batch_size!r}")
        self.timeout_s = float(timeout_s)
        self.max_retries = int(max_retries)
        self.temperature = float(temperature)
        self.backoff_base_s = float(backoff_base_s)
        self.backoff_max_s = float(backoff_max_s)
        self.retry_after_cap_s = float(retry_after_cap_s)
        self.retry_after_scale = float(retry_after_scale)
        self.embedding_batch_size = int(embedding_batch_size)
        self._sleep = sleep

        self._http = httpx.Client(
            timeout=httpx.Timeout(self.timeout_s),
            transport=transport,
            auth=_BearerAuth(self._api_key) if self._api_key else None,
            headers={"Accept": "application/json"},
        )

    # -- identity ---------------------------------------------------------

    @property
    def name(self) -> str:
        """The chat model's name."""
        return self.model

    @property
    def embedding_name(self) -> str | None:
        """The embedding model's name, or None when none is configured."""
        return self.embedding_model

    def __repr__(self) -> str:
        key = "'***'" if self._api_key else "None"
        return (
            f"OpenAICompatible(base_url={self.base_url!r}, model={self.model!r}, "
            f"embedding_model={self.embedding_model!r}, api_key={key}, "
            f"timeout_s={self.timeout_s}, max_retries={self.max_retries})"
        )

    __str__ = __repr__

    def __reduce__(self):
        raise TypeError("OpenAICompatible holds an API key and cannot be pickled; build one per process")

    # -- lifecycle --------------------------------------------------------

    def close(self) -> None:
        """Close the pooled HTTP connections. The client is unusable afterwards."""
        self._http.close()

    def __enter__(self) -> OpenAICompatible:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- chat -------------------------------------------------------------

    def complete(self, messages: list[dict], **kw: Any) -> str:
        """Return the assistant's reply text to ``messages`` (see ``chat``)."""
        return self.chat(messages, **kw).content

    def chat(self, messages: list[dict], **kw: Any) -> ChatReply:
        """POST ``messages`` to ``{base_url}/chat/completions`` and return the first choice.

        Keyword arguments go into the request body as they are (``max_tokens``,
        ``seed``, ``stop``, ``response_format`` ...); ``temperature`` defaults to
        the client's. Raises ``ValueError`` for malformed ``messages`` and
        ``LLMError`` for everything the server does wrong.
        """
        _check_messages(messages)
        payload: dict[str, Any] = {"model": self.model, "messages": list(messages), "temperature": self.temperature}
        payload.update(kw)
        body, attempts = self._post("/chat/completions", payload, what=f"chat completion with model {self.model!r}")
        content, finish_reason = self._parse_choice(body)
        if finish_reason == "length":
            log.warning("model %s stopped at its token limit; the reply is truncated", self.model)
        raw_usage = body.get("usage")
        usage: dict[str, Any] = raw_usage if isinstance(raw_usage, dict) else {}
        return ChatReply(
            content=content,
            model=str(body.get("model") or self.model),
            finish_reason=finish_reason,
            usage=usage,
            attempts=attempts,
        )

    def _parse_choice(self, body: dict) -> tuple[str, str | None]:
        if "choices" not in body:
            raise LLMError(
                f"chat reply from {self._url('/chat/completions')} has no 'choices'; {self._what_arrived(body)}"
            )
        choices = body["choices"]
        if not isinstance(choices, list) or not choices:
            raise LLMError(
                f"chat reply from {self._url('/chat/completions')} has an empty or invalid 'choices' "
                f"list; received {self._excerpt(body)}"
            )
        choice = choices[0]
        message = choice.get("message") if isinstance(choice, dict) else None
        if not isinstance(message, dict):
            raise LLMError(f"chat reply's first choice has no 'message' object; received {self._excerpt(body)}")
        content = message.get("content")
        if isinstance(content, list):  # content parts: [{"type": "text", "text": ...}, ...]
            texts = [str(p["text"]) for p in content if isinstance(p, dict) and isinstance(p.get("text"), str)]
            content = "".join(texts) if texts else None
        if not isinstance(content, str):
            hint = " (the model answered with tool calls, not text)" if message.get("tool_calls") else ""
            raise LLMError(f"chat reply's message has no text 'content'{hint}; received {self._excerpt(body)}")
        finish_reason = choice.get("finish_reason")
        return content, finish_reason if isinstance(finish_reason, str) else None

    # -- embeddings -------------------------------------------------------

    def embed(self, texts: list[str]) -> np.ndarray:
        """Embed ``texts`` with ``embedding_model``; return float64 of shape ``(len(texts), d)``.

        Texts are sent in batches of ``embedding_batch_size``. An empty list
        gives an array of shape ``(0, 0)``. Raises ``LLMError`` when no
        embedding model is configured or the server's vectors are missing,
        miscounted, of unequal length or not finite.
        """
        if not self.embedding_model:
            raise LLMError(
                f"no embedding model configured: pass embedding_model= or set {ENV_EMBEDDING_MODEL} "
                "(e.g. text-embedding-3-small, or nomic-embed-text for Ollama)"
            )
        if isinstance(texts, str) or not all(isinstance(t, str) for t in texts):
            raise ValueError("embed() takes a list of strings")
        texts = list(texts)
        if not texts:
            return np.zeros((0, 0))
        rows: list[np.ndarray] = []
        for start in range(0, len(texts), self.embedding_batch_size):
            batch = texts[start : start + self.embedding_batch_size]
            payload = {"model": self.embedding_model, "input": batch}
            body, _ = self._post("/embeddings", payload, what=f"embeddings with model {self.embedding_model!r}")
            rows.extend(self._parse_embeddings(body, len(batch)))
        dims = {r.shape[0] for r in rows}
        if len(dims) != 1:
            raise LLMError(f"embedding server returned vectors of different lengths {sorted(dims)}")
        return np.vstack(rows)

    def _parse_embeddings(self, body: dict, expected: int) -> list[np.ndarray]:
        data = body.get("data")
        if not isinstance(data, list):
            raise LLMError(
                f"embeddings reply from {self._url('/embeddings')} has no 'data' list; {self._what_arrived(body)}"
            )
        if len(data) != expected:
            raise LLMError(
                f"embeddings reply has {len(data)} vectors for {expected} texts; received {self._excerpt(body)}"
            )
        items = sorted(data, key=lambda d: d.get("index", 0) if isinstance(d, dict) else 0)
        vectors = []
        for item in items:
            raw = item.get("embedding") if isinstance(item, dict) else None
            try:
                if isinstance(raw, str):  # encoding_format="base64": little-endian float32
                    vector = np.frombuffer(base64.b64decode(raw), dtype="<f4").astype(np.float64)
                else:
                    vector = np.asarray(raw, dtype=np.float64)
            except (ValueError, TypeError) as exc:
                raise LLMError(
                    f"embeddings reply holds a vector that is not numbers; received {self._excerpt(body)}"
                ) from exc
            if vector.ndim != 1 or vector.size == 0 or not np.all(np.isfinite(vector)):
                raise LLMError(
                    f"embeddings reply holds an empty, nested or non-finite vector; received {self._excerpt(body)}"
                )
            vectors.append(vector)
        return vectors

    # -- HTTP with retries ------------------------------------------------

    def _url(self, path: str) -> str:
        return self.base_url + path

    def _post(self, path: str, payload: dict, what: str) -> tuple[dict, int]:
        """POST JSON with retries; return (decoded JSON object, attempts used)."""
        url = self._url(path)
        attempts = self.max_retries + 1
        last_problem = ""
        for attempt in range(attempts):
            retry_after_s: float | None = None
            try:
                response = self._http.post(url, json=payload)
            except httpx.TimeoutException:
                last_problem = f"timed out (timeout_s={self.timeout_s})"
            except httpx.TransportError as exc:
                last_problem = f"connection failed ({type(exc).__name__}: {self._redact(str(exc))})"
            else:
                status = response.status_code
                if 300 <= status < 400:
                    location = self._redact(response.headers.get("location", "?"))
                    raise LLMError(
                        f"{what} at {url} was redirected (HTTP {status}) to {location}: check base_url "
                        "(http vs https, a missing or extra path part)"
                    )
                if status < 400:
                    return self._decode_json(response, what), attempt + 1
                if status in RETRYABLE_STATUSES or status >= 500:
                    retry_after_s = _retry_after_seconds(response.headers)
                    last_problem = f"HTTP {status}{self._server_says(response)}"
                else:
                    raise self._status_error(response, what)
            if attempt + 1 < attempts:
                delay_s = self._delay_s(attempt, retry_after_s)
                log.warning(
                    "%s: attempt %d of %d %s; retrying in %.2f s", what, attempt + 1, attempts, last_problem, delay_s
                )
                self._sleep(delay_s)
        raise LLMError(f"{what} at {url} failed after {attempts} attempts; last error: {last_problem}")

    def _delay_s(self, attempt: int, retry_after_s: float | None) -> float:
        delay = min(self.backoff_base_s * (2.0**attempt), self.backoff_max_s)
        if retry_after_s is not None:
            delay = max(delay, min(retry_after_s * self.retry_after_scale, self.retry_after_cap_s))
        return max(delay, 0.0)

    def _status_error(self, response: httpx.Response, what: str) -> LLMError:
        status = response.status_code
        url = str(response.request.url)
        says = self._server_says(response)
        if status in (401, 403):
            return LLMError(
                f"{what} at {url} was refused with HTTP {status}{says}: check your API key "
                f"(api_key= or the OPENAI_API_KEY / ROBOCRITICS_API_KEY variable)"
            )
        if status == 404:
            return LLMError(
                f"{what} at {url} got HTTP 404{says}: check base_url (OpenAI-compatible servers "
                f"usually end in /v1) and model name (model={self.model!r}, "
                f"embedding_model={self.embedding_model!r})"
            )
        return LLMError(f"{what} at {url} was rejected with HTTP {status}{says}")

    def _server_says(self, response: httpx.Response) -> str:
        """' (server says: ...)' from an error body, redacted and truncated, or ''."""
        try:
            body = response.json()
        except (ValueError, UnicodeDecodeError):
            body = None
        message = _error_message(body) if body is not None else None
        if message is None:
            message = response.text.strip()
        if not message:
            return ""
        return f" (server says: {self._safe_excerpt(message)})"

    def _decode_json(self, response: httpx.Response, what: str) -> dict:
        try:
            body = response.json()
        except (ValueError, UnicodeDecodeError):
            content_type = response.headers.get("content-type", "no content-type")
            text = response.content.decode("utf-8", errors="replace")
            raise LLMError(
                f"{what} at {response.request.url}: the server answered HTTP {response.status_code} "
                f"({content_type}) with a body that is not JSON: {self._safe_excerpt(text)!r}"
            ) from None
        if not isinstance(body, dict):
            raise LLMError(f"{what} at {response.request.url}: expected a JSON object, received {self._excerpt(body)}")
        return body

    def _what_arrived(self, body: dict) -> str:
        """The server's error message in ``body`` if it has one, else an excerpt of ``body``."""
        server_message = _error_message(body)
        return f"the server's error: {server_message}" if server_message else f"received {self._excerpt(body)}"

    def _excerpt(self, value: Any) -> str:
        try:
            text = json.dumps(value, ensure_ascii=False)
        except (TypeError, ValueError):
            text = repr(value)
        return self._safe_excerpt(text)

    def _safe_excerpt(self, text: str) -> str:
        """At most ``_EXCERPT_CHARS`` of ``text``, redacted, saying how long the original was."""
        head = self._redact(text[: 2 * _EXCERPT_CHARS])
        if len(text) <= _EXCERPT_CHARS and len(head) <= _EXCERPT_CHARS:
            return head
        return head[:_EXCERPT_CHARS] + f"... [{len(text)} chars, truncated]"

    def _redact(self, text: str) -> str:
        """Replace the API key, and any run of 8+ of its characters, with '***'."""
        if not self._api_key or not text:
            return text
        return _redact_secret(text, self._api_key.reveal())


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
        raise ValueError("messages must be a non-empty list of {'role': ..., 'content': ...} dicts")
    for i, message in enumerate(messages):
        if not isinstance(message, Mapping) or "role" not in message:
            raise ValueError(f"messages[{i}] must be a dict with a 'role' key, got {message!r:.80}")


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
