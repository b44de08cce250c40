"""The provider for any OpenAI-compatible HTTP server: ``OpenAICompatible``.

It implements both protocols of :mod:`robocritics.llm.protocol` (``ChatModel``, ``EmbeddingModel``) on top of
httpx and
works with OpenAI, Ollama (``http://localhost:11434/v1``), vLLM, llama.cpp's
server, LM Studio and similar: it POSTs to ``{base_url}/chat/completions`` and
``{base_url}/embeddings``.

Failure policy of ``OpenAICompatible``:

* Every call has one total deadline, ``deadline_s`` (default 300 s): connecting,
  sending, waiting for and reading the reply, every retry and every pause
  between retries must fit in it. Each socket operation waits at most until
  the deadline (``llm.transport.DeadlineTransport``), so a server that sends
  one byte a second ends the call at the deadline with an ``LLMError``.
* Generation is bounded: ``max_tokens`` (default ``llm.limits.DEFAULT_MAX_TOKENS``)
  is sent with every chat request, replies are streamed (server-sent events)
  with an inactivity timeout ``idle_timeout_s`` inside the deadline, and
  servers that do not stream are read (or asked again) without it.
* Final, never retried: a chat request that times out reading (the server
  was generating: ``GenerationTimeoutError``; the connection is closed so
  that it stops), a prompt over the context (``ContextLengthError``), a
  server that cannot embed (``EmbeddingsUnavailableError``: HTTP 501, or 500
  "must be created with embedding=True") and HTTP 501 in general.
* HTTP 408, 409, 429 and every other 5xx, other timeouts (connect, write, an
  embedding request's read) and connection errors (refused,
  reset, dropped before the response) are retried up to ``max_retries`` times
  with exponential backoff ``backoff_base_s * 2**attempt`` (capped at
  ``backoff_max_s``). A ``Retry-After`` header (seconds or HTTP date; or
  ``retry-after-ms``) is honoured: the wait is at least
  ``retry_after * retry_after_scale``. A server that asks for more than
  ``retry_after_cap_s``, or a pause that would end past the deadline, ends
  the call at once with an ``LLMError`` instead of waiting.
* Bodies are read incrementally and capped at ``max_response_bytes`` both on
  the wire and after gzip/deflate decompression; JSON that nests too deep or
  holds too many arrays/objects is refused before it is decoded; a chat reply
  longer than ``max_reply_chars`` is refused. Requests larger than
  ``max_request_bytes`` are refused before they are sent.
* Text is cleaned of lone surrogates (``llm.limits.clean_text``) both ways:
  in the messages sent and in the reply and error texts received.
* 401/403 raise ``LLMError`` pointing at the API key, 404 and redirects at
  ``base_url`` (and the model name), other 4xx carry the server's own message.
* A body that is not JSON, or JSON without ``choices[0].message.content``,
  raises ``LLMError`` quoting (a truncated, redacted excerpt of) what arrived.
* Bad arguments (messages, limits, options) raise ``LLMArgumentError``, an
  ``LLMError`` that is also a ``ValueError``.
* The API key never appears in ``repr``/``str``, log records or error messages;
  any part of it a server echoes back (8 characters or more) is replaced by
  ``***`` before it reaches an exception.
"""

from __future__ import annotations

import base64
import json
import logging
import os
import time
from collections.abc import Callable, Sequence
from typing import Any

import httpx
import numpy as np

from robocritics.errors import LLMError

from ..limits import (
    DEFAULT_DEADLINE_S,
    DEFAULT_MAX_TOKENS,
    MAX_REPLY_CHARS,
    MAX_REQUEST_BYTES,
    MAX_RESPONSE_BYTES,
    clean_text,
)
from ..transport import (
    ACCEPT_ENCODING,
    Deadline,
    DeadlineTransport,
    NotJSONError,
    deadline_scope,
    iter_body,
    loads_json,
    read_body,
)

__all__ = ["OpenAICompatible"]

log = logging.getLogger("robocritics.llm")


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



from ..protocol import (
    ChatProgress,
    ChatReply,
    ContextLengthError,
    EmbeddingsUnavailableError,
    GenerationTimeoutError,
    LLMArgumentError,
)
from .wire import (
    _ERROR_BODY_BYTES,
    _EXCERPT_CHARS,
    _NAME_CHARS,
    _NO_EMBEDDINGS,
    _PROPS_BYTES,
    _STREAMED,
    ENV_API_KEYS,
    ENV_BASE_URL,
    ENV_EMBEDDING_MODEL,
    ENV_MODEL,
    _check_messages,
    _clean_message,
    _context_error,
    _count,
    _error_message,
    _normalise_base_url,
    _positive_int,
    _props_context,
    _redact_secret,
    _retry_after_seconds,
    _seconds,
    _StreamRefused,
    _temperature,
)

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

    Time: ``deadline_s`` (seconds) bounds each call (one HTTP exchange with
    all its retries and pauses; ``embed`` has one per batch) in total;
    ``timeout_s`` (seconds) bounds each network phase within it (connect,
    each read, write), so a stalled server is retried before the deadline.
    ``max_retries`` is the number of *extra* attempts after the first, so at
    most ``max_retries + 1`` requests are sent per call. Backoff before retry
    n (0-based) is ``min(backoff_base_s * 2**n, backoff_max_s)`` seconds,
    raised to the server's ``Retry-After`` × ``retry_after_scale``; a server
    asking for more than ``retry_after_cap_s`` is treated as down.
    ``sleep(seconds)`` does the waiting and ``clock()`` (seconds, monotonic)
    measures the deadline; tests pass ones that record the pauses instead.

    Size: ``max_response_bytes`` caps a response body (on the wire and
    decompressed), ``max_reply_chars`` the text of a chat reply and
    ``max_request_bytes`` a request body (``llm.limits`` has the defaults
    and their reasons).

    ``transport`` replaces the HTTP transport (by default a
    ``llm.transport.DeadlineTransport``); with another transport, or through a
    proxy that httpx takes from the environment (``HTTPS_PROXY`` ...), the
    deadline is checked between reads, each of which may take up to
    ``timeout_s``.

    Generation: ``max_tokens`` (default ``llm.limits.DEFAULT_MAX_TOKENS``; None sends none) caps every
    reply; a reply cut there has ``finish_reason == "length"``. With ``stream=True`` (default) the reply is
    requested as server-sent events and read token by token; ``idle_timeout_s`` (default ``timeout_s``) is
    then the longest silence between two pieces of it, and the total ``deadline_s`` still holds. A server
    that answers a streamed request with plain JSON is read as such; one that refuses ``stream`` (HTTP
    400/422 naming it) is asked again without, and the client stops streaming. A chat request that times
    out reading (the server was generating) raises ``GenerationTimeoutError`` and is never retried; leaving
    the call for any reason (deadline, size limit, Ctrl-C) closes its connection, so the server stops
    generating. ``on_progress(ChatProgress)`` is called when a request is sent, for each streamed token,
    and at the end.

    Final errors (never retried): a prompt over the model's context (``ContextLengthError``, with the
    context the server named), a server that cannot embed (``EmbeddingsUnavailableError``: HTTP 501, or
    500 saying the model "must be created with embedding=True" or that embeddings are not supported).

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
        deadline_s: float = DEFAULT_DEADLINE_S,
        backoff_base_s: float = 0.5,
        backoff_max_s: float = DEFAULT_BACKOFF_MAX_S,
        retry_after_cap_s: float = DEFAULT_RETRY_AFTER_CAP_S,
        retry_after_scale: float = 1.0,
        embedding_batch_size: int = 64,
        max_response_bytes: int = MAX_RESPONSE_BYTES,
        max_reply_chars: int = MAX_REPLY_CHARS,
        max_request_bytes: int = MAX_REQUEST_BYTES,
        sleep: Callable[[float], None] = time.sleep,
        clock: Callable[[], float] = time.monotonic,
        max_tokens: int | None = DEFAULT_MAX_TOKENS,
        stream: bool = True,
        idle_timeout_s: float | None = None,
        on_progress: Callable[[ChatProgress], None] | None = None,
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
        self.model = clean_text(str(model))
        self.embedding_model = embedding_model or os.environ.get(ENV_EMBEDDING_MODEL) or None
        if api_key is None:
            api_key = next((os.environ[v] for v in ENV_API_KEYS if os.environ.get(v)), None)
        self._api_key = _Secret(api_key) if api_key else None

        self.timeout_s = _seconds("timeout_s", timeout_s)
        self.deadline_s = _seconds("deadline_s", deadline_s)
        self.backoff_base_s = _seconds("backoff_base_s", backoff_base_s, zero=True)
        self.backoff_max_s = _seconds("backoff_max_s", backoff_max_s, zero=True)
        self.retry_after_cap_s = _seconds("retry_after_cap_s", retry_after_cap_s, zero=True)
        self.retry_after_scale = _seconds("retry_after_scale", retry_after_scale, zero=True)
        self.max_retries = _count("max_retries", max_retries, minimum=0)
        self.embedding_batch_size = _count("embedding_batch_size", embedding_batch_size)
        self.max_response_bytes = _count("max_response_bytes", max_response_bytes)
        self.max_reply_chars = _count("max_reply_chars", max_reply_chars)
        self.max_request_bytes = _count("max_request_bytes", max_request_bytes)
        self.temperature = _temperature(temperature)
        self.max_tokens = None if max_tokens is None else _count("max_tokens", max_tokens)
        self.stream = bool(stream)
        self.idle_timeout_s = self.timeout_s if idle_timeout_s is None else _seconds("idle_timeout_s", idle_timeout_s)
        self.on_progress = on_progress
        self._warned_pooling = False
        self._sleep = sleep
        self._clock = clock

        self._http = httpx.Client(
            timeout=httpx.Timeout(self.timeout_s),
            transport=transport if transport is not None else DeadlineTransport(),
            auth=_BearerAuth(self._api_key) if self._api_key else None,
            headers={"Accept": "application/json", "Accept-Encoding": ACCEPT_ENCODING},
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
            f"timeout_s={self.timeout_s}, deadline_s={self.deadline_s}, max_retries={self.max_retries})"
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
        the client's, ``max_tokens`` to the client's (``max_tokens=None`` sends
        none) and ``stream`` to the client's. Message texts are cleaned of lone
        surrogates. Raises ``LLMArgumentError`` (a ``ValueError``) for malformed
        ``messages`` or options and ``LLMError`` for everything the server does
        wrong (``GenerationTimeoutError``, ``ContextLengthError`` among them).
        """
        _check_messages(messages)
        if "temperature" in kw:
            kw["temperature"] = _temperature(kw["temperature"])
        stream = bool(kw.pop("stream", self.stream))
        payload: dict[str, Any] = {
            "model": self.model,
            "messages": [_clean_message(m) for m in messages],
            "temperature": self.temperature,
        }
        if self.max_tokens is not None:
            payload["max_tokens"] = self.max_tokens
        payload.update(kw)
        if payload.get("max_tokens") is None:
            payload.pop("max_tokens", None)
        else:
            payload["max_tokens"] = _count("max_tokens", payload["max_tokens"])
        what = f"chat completion with model {self.model!r}"
        started = self._clock()
        self._progress("waiting", 0, 0, started)
        if stream:
            payload["stream"] = True
            try:
                body, attempts = self._post("/chat/completions", payload, what, chat=True, started=started)
            except _StreamRefused as refused:
                log.warning("%s: the server refuses streaming (%s); asking without it from now on", what, refused)
                self.stream = False
                del payload["stream"]
                body, attempts = self._post("/chat/completions", payload, what, chat=True, started=started)
        else:
            body, attempts = self._post("/chat/completions", payload, what, chat=True, started=started)
        streamed = bool(body.pop(_STREAMED, False))
        content, finish_reason = self._parse_choice(body)
        if finish_reason == "length":
            log.warning(
                "model %s stopped at its token limit (max_tokens=%s); the reply is truncated",
                self.model,
                payload.get("max_tokens"),
            )
        raw_usage = body.get("usage")
        usage: dict[str, Any] = raw_usage if isinstance(raw_usage, dict) else {}
        model = body.get("model")
        reply = ChatReply(
            content=content,
            model=clean_text(model[:_NAME_CHARS]) if isinstance(model, str) and model else self.model,
            finish_reason=finish_reason,
            usage=usage,
            attempts=attempts,
            max_tokens=payload.get("max_tokens"),
            streamed=streamed,
        )
        self._progress("done", reply.completion_tokens or 0, len(content), started, [content])
        return reply

    def _progress(
        self, phase: str, tokens: int, chars: int, started: float, parts: Sequence[str] = ()
    ) -> None:
        if self.on_progress is not None:
            elapsed_s = max(self._clock() - started, 0.0)
            self.on_progress(ChatProgress(phase, tokens, chars, elapsed_s, parts, len(parts)))

    # -- the model's context ------------------------------------------------

    def server_context_tokens(self) -> int | None:
        """The model's context window in tokens, if the server says (else None); never raises for the server.

        Asks llama.cpp's ``GET /props`` (``n_ctx``, at the server's root, beside ``/v1``) and then
        ``GET {base_url}/models`` (vLLM's ``max_model_len``, llama.cpp's ``meta.n_ctx_train`` is not the
        context and is not used). Each request has at most ``min(timeout_s, 10)`` seconds and is not retried.
        """
        root = self.base_url.removesuffix("/v1")
        for url, pick in ((root + "/props", _props_context), (self._url("/models"), self._models_context)):
            body = self._get_json(url, min(self.timeout_s, 10.0))
            value = pick(body) if body is not None else None
            if value is not None:
                return value
        return None

    def _models_context(self, body: Any) -> int | None:
        data = body.get("data") if isinstance(body, dict) else None
        if not isinstance(data, list):
            return None
        for entry in data:
            if isinstance(entry, dict) and entry.get("id") == self.model:
                return _positive_int(entry.get("max_model_len"))
        return None

    def _get_json(self, url: str, seconds: float) -> Any:
        deadline = Deadline.after(seconds, self._clock)
        try:
            with deadline_scope(deadline), self._http.stream("GET", url, timeout=seconds) as response:
                if response.status_code != 200:
                    return None
                raw = read_body(response, max_bytes=_PROPS_BYTES, deadline=deadline, what="reply")
            return loads_json(raw, where=url)
        except (httpx.HTTPError, LLMError):
            return None

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
        if len(content) > self.max_reply_chars:
            raise LLMError(
                f"chat reply from {self._url('/chat/completions')} is {len(content):,} characters long; the limit "
                f"is {self.max_reply_chars:,} (max_reply_chars): a reply that long is not a program"
            )
        finish_reason = choice.get("finish_reason")
        finish = clean_text(finish_reason[:_NAME_CHARS]) if isinstance(finish_reason, str) else None
        return clean_text(content), finish

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
            raise LLMArgumentError("embed() takes a list of strings")
        texts = [clean_text(t) for t in texts]
        if not texts:
            return np.zeros((0, 0))
        rows: list[np.ndarray] = []
        for start in range(0, len(texts), self.embedding_batch_size):
            batch = texts[start : start + self.embedding_batch_size]
            payload = {"model": self.embedding_model, "input": batch}
            body, _ = self._post(
                "/embeddings", payload, what=f"embeddings with model {self.embedding_model!r}", embeddings=True
            )
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
        indices = [d.get("index") if isinstance(d, dict) else None for d in data]
        if all(isinstance(i, int) and not isinstance(i, bool) for i in indices):
            if sorted(indices) != list(range(expected)):
                raise LLMError(
                    f"embeddings reply's 'index' fields are not 0..{expected - 1} once each; "
                    f"received {self._excerpt(body)}"
                )
            items = [data[j] for j in np.argsort(np.asarray(indices), kind="stable")]
        else:  # no (usable) indices: the server's order is the texts' order
            items = list(data)
        vectors = []
        for item in items:
            raw = item.get("embedding") if isinstance(item, dict) else None
            try:
                if isinstance(raw, str):  # encoding_format="base64": little-endian float32
                    vector = np.frombuffer(base64.b64decode(raw), dtype="<f4").astype(np.float64)
                else:
                    vector = np.asarray(raw, dtype=np.float64)
            except (ValueError, TypeError, OverflowError) as exc:
                raise LLMError(
                    f"embeddings reply holds a vector that is not numbers; received {self._excerpt(body)}"
                ) from exc
            if vector.ndim == 2 and vector.shape[0] > 0 and vector.shape[1] > 0:
                # One vector per token (llama.cpp with --pooling none, a model without pooling): mean-pool them.
                if not self._warned_pooling:
                    log.warning(
                        "embeddings with model %r: the server returned one vector per token; they are mean-pooled "
                        "into one vector per text (start the server with pooling, e.g. llama.cpp --pooling mean)",
                        self.embedding_model,
                    )
                    self._warned_pooling = True
                vector = vector.mean(axis=0)
            if vector.ndim != 1 or vector.size == 0 or not np.all(np.isfinite(vector)):
                raise LLMError(
                    f"embeddings reply holds an empty, nested or non-finite vector; received {self._excerpt(body)}"
                )
            vectors.append(vector)
        return vectors

    # -- HTTP with retries and one deadline -------------------------------

    def _url(self, path: str) -> str:
        return self.base_url + path

    def _encode(self, payload: dict, what: str) -> bytes:
        try:
            content = json.dumps(payload, ensure_ascii=False, allow_nan=False).encode("utf-8")
        except (TypeError, ValueError) as exc:  # an option that is not JSON, NaN, a surrogate left in an option
            raise LLMArgumentError(f"{what}: the request cannot be sent as JSON ({exc})") from None
        if len(content) > self.max_request_bytes:
            raise LLMArgumentError(
                f"{what}: the request is {len(content):,} bytes; the limit is {self.max_request_bytes:,} "
                "(max_request_bytes): send shorter messages"
            )
        return content

    def _post(
        self,
        path: str,
        payload: dict,
        what: str,
        *,
        chat: bool = False,
        embeddings: bool = False,
        started: float | None = None,
    ) -> tuple[dict, int]:
        """POST JSON with retries, all within one deadline; return (decoded JSON object, attempts used).

        ``chat``: a read timeout (the server was generating) is final (``GenerationTimeoutError``).
        ``embeddings``: a server that cannot embed is final (``EmbeddingsUnavailableError``).
        """
        url = self._url(path)
        content = self._encode(payload, what)
        deadline = Deadline.after(self.deadline_s, self._clock)
        stream = bool(payload.get("stream"))
        started = self._clock() if started is None else started
        attempts = self.max_retries + 1
        last_problem = ""
        for attempt in range(attempts):
            if deadline.passed():
                raise self._deadline_error(what, url, attempt, last_problem)
            retry_after_s: float | None = None
            try:
                with deadline_scope(deadline):
                    outcome = self._exchange(url, content, what, deadline, stream=stream, embeddings=embeddings,
                                             started=started)  # fmt: skip
            except httpx.TimeoutException as exc:
                if deadline.passed():
                    raise self._deadline_error(what, url, attempt + 1, last_problem) from None
                if chat and isinstance(exc, httpx.ReadTimeout):
                    wait_s = self.idle_timeout_s if stream else self.timeout_s
                    raise GenerationTimeoutError(
                        f"{what} at {url}: the server sent nothing for {wait_s:g} s while generating "
                        f"(attempt {attempt + 1}); not retried, since the server may still be generating: the "
                        "connection was closed so that it stops. Raise the timeout, or lower max_tokens"
                    ) from None
                last_problem = f"timed out (timeout_s={self.timeout_s:g})"
            except httpx.TransportError as exc:
                last_problem = f"connection failed ({type(exc).__name__}: {self._safe_excerpt(str(exc))})"
            else:
                if isinstance(outcome, dict):
                    return outcome, attempt + 1
                last_problem, retry_after_s = outcome
            if attempt + 1 < attempts:
                delay_s = self._delay_s(attempt, retry_after_s, what, url, last_problem)
                remaining = deadline.remaining_s()
                if delay_s >= remaining:
                    raise LLMError(
                        f"{what} at {url}: attempt {attempt + 1} {last_problem}; the next attempt would start "
                        f"after the deadline (a {delay_s:.3g} s pause, {max(remaining, 0.0):.3g} s left of "
                        f"deadline_s={self.deadline_s:g})"
                    )
                log.warning(
                    "%s: attempt %d of %d %s; retrying in %.2f s", what, attempt + 1, attempts, last_problem, delay_s
                )
                self._sleep(delay_s)
        raise LLMError(f"{what} at {url} failed after {attempts} attempts; last error: {last_problem}")

    def _exchange(
        self,
        url: str,
        content: bytes,
        what: str,
        deadline: Deadline,
        *,
        stream: bool = False,
        embeddings: bool = False,
        started: float = 0.0,
    ) -> dict | tuple[str, float | None]:
        """One HTTP request: the decoded JSON object, or (problem, Retry-After seconds) for a retryable status.

        Raises ``LLMError`` for answers that retrying cannot fix and lets
        httpx's timeout and transport errors through (the caller decides).
        Leaving the block for any reason closes the response; a response not
        read to its end closes its connection, so the server stops sending.
        """
        phase_s = max(min(self.timeout_s, deadline.remaining_s()), 1e-3)
        timeout: float | httpx.Timeout = phase_s
        headers = {"Content-Type": "application/json"}
        if stream:
            timeout = httpx.Timeout(phase_s, read=max(min(self.idle_timeout_s, deadline.remaining_s()), 1e-3))
            headers["Accept"] = "text/event-stream, application/json"
        with self._http.stream("POST", url, content=content, headers=headers, timeout=timeout) as response:
            status = response.status_code
            if 300 <= status < 400:
                location = self._safe_excerpt(response.headers.get("location", "?"))
                raise LLMError(
                    f"{what} at {url} was redirected (HTTP {status}) to {location}: check base_url "
                    "(http vs https, a missing or extra path part)"
                )
            if status < 400:
                kind = response.headers.get("content-type", "").split(";")[0].strip().lower()
                if stream and kind == "text/event-stream":
                    return self._read_events(response, deadline, what, started)
                raw = read_body(response, max_bytes=self.max_response_bytes, deadline=deadline, what="reply")
                return self._decode_json(raw, response, what)
            raw = read_body(response, max_bytes=_ERROR_BODY_BYTES, deadline=deadline, what="error", stop_at_limit=True)
            message = self._server_message(raw)
            context = _context_error(message, raw)
            if context is not None:
                n_ctx, requested = context
                raise ContextLengthError(
                    f"{what} at {url} was rejected with HTTP {status}: the prompt is longer than the model's "
                    f"context{f' of {n_ctx} tokens' if n_ctx else ''}"
                    f"{self._server_says(raw)}: shorten the prompt (robocritics fits it when it knows the "
                    "context: --context-tokens), lower max_tokens, or give the model a larger context",
                    context_tokens=n_ctx,
                    requested_tokens=requested,
                )
            if stream and status in (400, 422) and "stream" in message.lower():
                raise _StreamRefused(f"HTTP {status}{self._server_says(raw)}")
            if status == 501 or (status == 500 and _NO_EMBEDDINGS.search(message)):
                error = EmbeddingsUnavailableError if embeddings else LLMError
                raise error(
                    f"{what} at {url} failed with HTTP {status}{self._server_says(raw)}: the server cannot do "
                    "this (not retried)"
                    + (": start it with embeddings enabled (llama.cpp --embeddings, llama-cpp-python "
                       "--embedding true) or use keyword (BM25) memory" if embeddings else "")
                )  # fmt: skip
            if status in RETRYABLE_STATUSES or status >= 500:
                return f"HTTP {status}{self._server_says(raw)}", _retry_after_seconds(response.headers)
            raise self._status_error(status, url, raw, what)

    def _read_events(self, response: httpx.Response, deadline: Deadline, what: str, started: float) -> dict:
        """A streamed (server-sent events) chat reply, read as it arrives, as the body a plain reply would have.

        Each ``data:`` event is a JSON chunk whose ``choices[0].delta.content``
        is the next piece of text; ``data: [DONE]`` ends the stream (reading
        stops there). Comments (``: ping``) count as activity. An ``error``
        event raises ``LLMError`` with the server's words.
        """
        url = response.request.url
        parts: list[str] = []
        chars = tokens = 0
        finish: str | None = None
        usage: dict[str, Any] = {}
        model: Any = None
        data: list[bytes] = []
        buffer = bytearray()
        events = 0

        def dispatch(event: bytes) -> bool:  # True: [DONE]
            nonlocal chars, tokens, finish, usage, model, events
            if event.strip() == b"[DONE]":
                return True
            chunk = loads_json(event, where=f"{what} at {url} (a streamed event)")
            if not isinstance(chunk, dict):
                raise LLMError(f"{what} at {url}: a streamed event is not a JSON object: {self._excerpt(chunk)}")
            events += 1
            message = _error_message(chunk)
            if message is not None and "choices" not in chunk:
                raise self._stream_error(message, event, what, url)
            if isinstance(chunk.get("model"), str):
                model = chunk["model"]
            if isinstance(chunk.get("usage"), dict):
                usage = chunk["usage"]
            choices = chunk.get("choices")
            if isinstance(choices, list) and choices and isinstance(choices[0], dict):
                choice = choices[0]
                delta = choice.get("delta")
                if not isinstance(delta, dict):
                    delta = choice.get("message") if isinstance(choice.get("message"), dict) else {}
                piece = delta.get("content")
                if isinstance(piece, str) and piece:
                    parts.append(piece)
                    chars += len(piece)
                    tokens += 1
                    if chars > self.max_reply_chars:
                        raise LLMError(
                            f"chat reply from {url} is longer than {self.max_reply_chars:,} characters "
                            "(max_reply_chars); stopped reading: a reply that long is not a program"
                        )
                    self._progress("receiving", tokens, chars, started, parts)
                if isinstance(choice.get("finish_reason"), str):
                    finish = choice["finish_reason"]
            return False

        done = False
        for piece in iter_body(response, max_bytes=self.max_response_bytes, deadline=deadline, what="streamed reply"):
            start = len(buffer)
            buffer += piece
            scan = max(start - 1, 0)
            cut = 0
            while True:
                end = buffer.find(b"\n", scan)
                if end < 0:
                    break
                line = bytes(buffer[cut:end]).rstrip(b"\r")
                cut = scan = end + 1
                if not line:
                    if data and dispatch(b"\n".join(data)):
                        done = True
                        break
                    data = []
                elif line.startswith(b":"):
                    continue
                else:
                    name, _, value = line.partition(b":")
                    if name == b"data":
                        data.append(value[1:] if value.startswith(b" ") else value)
            del buffer[:cut]
            if done:
                break
        tail = bytes(buffer).rstrip(b"\r")
        if not done and tail.startswith(b"data:"):  # a last line without its newline
            data.append(tail[5:].lstrip(b" ") if tail[5:6] == b" " else tail[5:])
        if not done and data:
            done = dispatch(b"\n".join(data))
        if not events:
            raise LLMError(f"{what} at {url}: the streamed reply ended before any data arrived")
        if finish is None and not done:
            raise LLMError(
                f"{what} at {url}: the streamed reply ended after {tokens} tokens without a finish reason or "
                "[DONE]: the server stopped in the middle"
            )
        return {
            "model": model,
            "choices": [{"index": 0, "message": {"role": "assistant", "content": "".join(parts)},
                         "finish_reason": finish}],
            "usage": usage if usage.get("completion_tokens") else {**usage, "completion_tokens": tokens},
            _STREAMED: True,
        }  # fmt: skip

    def _stream_error(self, message: str, event: bytes, what: str, url: Any) -> LLMError:
        """The error of a stream the server stopped with an ``error`` event saying ``message``."""
        context = _context_error(message, event)
        if context is not None:
            return ContextLengthError(
                f"{what} at {url}: the server stopped the stream: {self._safe_excerpt(message)}",
                context_tokens=context[0],
                requested_tokens=context[1],
            )
        return LLMError(f"{what} at {url}: the server stopped the stream with an error: {self._safe_excerpt(message)}")

    def _deadline_error(self, what: str, url: str, attempts: int, last_problem: str) -> LLMError:
        tried = f" after {attempts} attempt{'s' if attempts != 1 else ''}" if attempts else ""
        last = f"; before that: {last_problem}" if last_problem else ""
        return LLMError(
            f"{what} at {url} did not finish within its deadline of {self.deadline_s:g} s (deadline_s){tried}{last}"
        )

    def _delay_s(
        self, attempt: int, retry_after_s: float | None, what: str = "", url: str = "", problem: str = ""
    ) -> float:
        delay = min(self.backoff_base_s * (2.0**attempt), self.backoff_max_s)
        if retry_after_s is not None:
            asked = retry_after_s * self.retry_after_scale
            if asked > self.retry_after_cap_s:
                raise LLMError(
                    f"{what} at {url}: {problem}, and the server asks to retry after {retry_after_s:.6g} s, more "
                    f"than retry_after_cap_s={self.retry_after_cap_s:g} s: it is treated as down; try again later"
                )
            delay = max(delay, asked)
        return max(delay, 0.0)

    def _status_error(self, status: int, url: str, raw: bytes, what: str) -> LLMError:
        says = self._server_says(raw)
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

    def _server_message(self, raw: bytes) -> str:
        """The server's error message in an error body (the raw text when it is not an OpenAI-style error)."""
        try:
            body = loads_json(raw, where="the error") if raw.strip() else None
        except LLMError:
            body = None
        message = _error_message(body) if body is not None else None
        return message if message is not None else raw.decode("utf-8", errors="replace").strip()

    def _server_says(self, raw: bytes) -> str:
        """' (server says: ...)' from an error body (at most ``_ERROR_BODY_BYTES`` of it), or ''."""
        try:
            body = loads_json(raw, where="the error") if raw.strip() else None
        except LLMError:
            body = None
        message = _error_message(body) if body is not None else None
        if message is None:
            message = raw.decode("utf-8", errors="replace").strip()
        if not message:
            return ""
        return f" (server says: {self._safe_excerpt(message)})"

    def _decode_json(self, raw: bytes, response: httpx.Response, what: str) -> dict:
        where = f"{what} at {response.request.url}"
        try:
            body = loads_json(raw, where=where)
        except NotJSONError:
            content_type = self._safe_excerpt(response.headers.get("content-type", "no content-type"))
            text = raw.decode("utf-8", errors="replace")
            raise LLMError(
                f"{where}: the server answered HTTP {response.status_code} ({content_type}) with a body that is "
                f"not JSON: {self._safe_excerpt(text)!r}"
            ) from None
        if not isinstance(body, dict):
            raise LLMError(f"{where}: expected a JSON object, received {self._excerpt(body)}")
        return body

    def _what_arrived(self, body: dict) -> str:
        """The server's error message in ``body`` if it has one, else an excerpt of ``body``."""
        server_message = _error_message(body)
        if server_message:
            return f"the server's error: {self._safe_excerpt(server_message)}"
        return f"received {self._excerpt(body)}"

    def _excerpt(self, value: Any) -> str:
        try:
            text = json.dumps(value, ensure_ascii=False)
        except (TypeError, ValueError, RecursionError):
            text = repr(value)[: 4 * _EXCERPT_CHARS]
        return self._safe_excerpt(text)

    def _safe_excerpt(self, text: str) -> str:
        """At most ``_EXCERPT_CHARS`` of ``text``, redacted and cleaned, saying how long the original was."""
        head = clean_text(self._redact(text[: 2 * _EXCERPT_CHARS]))
        if len(text) <= _EXCERPT_CHARS and len(head) <= _EXCERPT_CHARS:
            return head
        return head[:_EXCERPT_CHARS] + f"... [{len(text)} chars, truncated]"

    def _redact(self, text: str) -> str:
        """Replace the API key, and any run of 8+ of its characters, with '***'."""
        if not self._api_key or not text:
            return text
        return _redact_secret(text, self._api_key.reveal())
