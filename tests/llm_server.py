"""A real OpenAI-compatible HTTP server on 127.0.0.1 for tests.

``LLMServer`` listens on an ephemeral loopback port (threaded, HTTP/1.1 with
keep-alive) and answers ``POST /v1/chat/completions`` and ``POST
/v1/embeddings`` with the JSON shapes OpenAI uses. What it answers is scripted:

* ``server.script(...)`` queues actions; each incoming request (to either
  endpoint) takes the next one: ``Reply(text)``, ``Fail(status,
  retry_after=...)``, ``Delay(seconds, then=...)``, ``Garbage(body)``,
  ``RawJSON(obj)``, ``Drop()``, ``Stream(chunks, interval_s=...)`` (a body
  sent piece by piece: one byte every few seconds, or 50 MB of chunks) and
  ``SlowHeaders(interval_s)`` (the status line itself, a byte at a time).
  ``server.reply(*texts)`` is shorthand for queuing ``Reply`` actions;
  ``chat_body(text)`` is the JSON body a ``Reply`` sends, for hand-made bodies.
* With the queue empty, chat requests go to ``server.responder`` (a callable
  ``request_json -> str | Action``; by default it echoes the last user message)
  and embedding requests get ``hashed_embedding`` vectors.

Real-server behaviour, switched by attributes (any time):

* Streaming: a chat request with ``"stream": true`` is answered with
  server-sent events (``data: {chunk}\n\n`` per token, then ``data: [DONE]``),
  one token every ``token_interval_s`` seconds; ``stream_mode = "ignore"``
  answers plain JSON instead (servers that do not stream), ``"refuse"`` answers
  400 "stream is not supported". A client that hangs up mid-stream is noticed
  at the next token: ``tokens_sent`` stops growing and ``cancelled`` is set.
* ``max_tokens`` is honoured: a reply longer than that many tokens (``tokens``:
  a word with its following whitespace) is cut there with ``finish_reason:
  "length"``.
* ``context_tokens``: a prompt (``count_tokens``, words and punctuation) plus
  ``max_tokens`` over it gets llama-cpp-python's HTTP 400 "Requested tokens (N)
  exceed context window of M" (``context_style = "llama.cpp"``: llama.cpp's
  "exceeds the available context size" with ``n_ctx``); ``GET /props`` answers
  llama.cpp's ``default_generation_settings.n_ctx`` when ``props`` is set.
* ``embedding_mode``: ``"ok"``; ``"no-embedding"`` (llama-cpp-python without
  ``embedding=True``: HTTP 500 "Llama model must be created with embedding=True
  to call this method"); ``"not-implemented"`` (llama.cpp without
  ``--embeddings``: HTTP 501); ``"per-token"`` (no pooling: one vector per token).

Every request is recorded (``server.requests``: path, headers, raw body,
decoded JSON, arrival time) so a test can assert what the client really sent.
``require_api_key`` makes the server answer 401 to any other key, echoing the
key it received in the error message the way careless servers do.

Use it as a context manager or through the ``llm_server`` fixture in
``tests/llm_fixtures.py``.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import socket
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Union

# -- scripted actions --------------------------------------------------------


@dataclass(frozen=True)
class Reply:
    """Answer a chat request with assistant message ``content``."""

    content: str
    finish_reason: str = "stop"


@dataclass(frozen=True)
class Fail:
    """Answer with HTTP ``status`` and an OpenAI-style error body (or ``body`` verbatim).

    ``retry_after`` (seconds) becomes a ``Retry-After`` header.
    """

    status: int
    retry_after: float | str | None = None
    body: str | None = None
    headers: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Delay:
    """Wait ``seconds`` (or until the server stops) before answering with ``then`` (default: the normal answer)."""

    seconds: float
    then: Action | None = None


@dataclass(frozen=True)
class Garbage:
    """Answer HTTP ``status`` with ``body`` bytes that are not what the client expects (plus ``headers``)."""

    body: bytes | str = b"<html><body>502 Bad Gateway... just kidding, not JSON</body></html>"
    status: int = 200
    content_type: str = "text/html"
    headers: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Stream:
    """Answer HTTP ``status`` with the body ``chunks()`` yields, each chunk sent and flushed on its own.

    ``interval_s`` is the pause before each chunk (a pause ends early when the
    server stops). With ``length`` the body is announced with that
    Content-Length; without, it is sent with chunked transfer encoding.
    """

    chunks: Callable[[], Iterable[bytes]]
    interval_s: float = 0.0
    length: int | None = None
    status: int = 200
    content_type: str = "application/json"
    headers: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class SlowHeaders:
    """Send the status line and headers one byte every ``interval_s`` seconds (until the server stops)."""

    interval_s: float


@dataclass(frozen=True)
class RawJSON:
    """Answer HTTP ``status`` with ``obj`` serialised as JSON, whatever it is."""

    obj: Any
    status: int = 200


@dataclass(frozen=True)
class Drop:
    """Read the request, then close the connection without sending any response."""


Action = Union[Reply, Fail, Delay, Garbage, RawJSON, Drop, Stream, SlowHeaders]


def chat_body(content: str, model: str = "test-chat", finish_reason: str = "stop") -> bytes:
    """The JSON body of a chat completion whose message is ``content`` (what ``Reply`` sends, minus usage)."""
    return json.dumps(
        {
            "object": "chat.completion",
            "model": model,
            "choices": [
                {"index": 0, "message": {"role": "assistant", "content": content}, "finish_reason": finish_reason}
            ],
        }
    ).encode()


def drip(body: bytes, interval_s: float) -> Stream:
    """``body`` (with its Content-Length announced) one byte every ``interval_s`` seconds."""
    return Stream(lambda: (body[i : i + 1] for i in range(len(body))), interval_s=interval_s, length=len(body))


@dataclass(frozen=True)
class RecordedRequest:
    """One request as the server received it. ``time_s`` is ``time.monotonic()`` at arrival."""

    method: str
    path: str
    headers: dict[str, str]
    body: bytes
    json: Any
    time_s: float

    @property
    def messages(self) -> list[dict]:
        """The chat messages of a chat request ([] otherwise)."""
        return list(self.json.get("messages", [])) if isinstance(self.json, dict) else []

    @property
    def text(self) -> str:
        """All message contents (or embedding inputs) joined by newlines, for `in` assertions."""
        if not isinstance(self.json, dict):
            return ""
        if "messages" in self.json:
            return "\n".join(str(m.get("content", "")) for m in self.json["messages"])
        inputs = self.json.get("input", [])
        return "\n".join(inputs) if isinstance(inputs, list) else str(inputs)


# -- deterministic embeddings -----------------------------------------------

_TOKEN = re.compile(r"[a-z0-9]+")


def hashed_embedding(text: str, dim: int, model: str = "") -> list[float]:
    """A unit vector of length ``dim``: signed hashed bag of lower-case words.

    Deterministic across processes (blake2b, not ``hash``). The model name
    seeds the hash, so different models give unrelated vectors for the same
    text. Texts without words give a vector of zeros.
    """
    vector = [0.0] * dim
    for token in _TOKEN.findall(text.lower()):
        digest = hashlib.blake2b(f"{model}\x00{token}".encode(), digest_size=8).digest()
        bucket = int.from_bytes(digest[:4], "little") % dim
        sign = 1.0 if digest[4] & 1 else -1.0
        vector[bucket] += sign
    norm = math.sqrt(sum(v * v for v in vector))
    return [v / norm for v in vector] if norm else vector


_PROMPT_TOKEN = re.compile(r"\w+|[^\w\s]")
_REPLY_TOKEN = re.compile(r"\s*\S+\s*|\s+")


def count_tokens(messages: list[dict]) -> int:
    """The server's prompt length: words and punctuation marks of every message, plus 4 per message."""
    return sum(len(_PROMPT_TOKEN.findall(str(m.get("content", "")))) + 4 for m in messages)


def tokens(text: str) -> list[str]:
    """A reply as the server generates it: pieces of one word each with its surrounding whitespace."""
    return _REPLY_TOKEN.findall(text)


def echo_last_user_message(request: dict) -> str:
    """Default chat responder: the content of the last user message."""
    for message in reversed(request.get("messages", [])):
        if message.get("role") == "user":
            return str(message.get("content", ""))
    return ""


# -- the server ---------------------------------------------------------------


class _QuietServer(ThreadingHTTPServer):
    """A client that hangs up mid-reply (a deadline, Ctrl-C) is what many tests do on purpose: not a traceback
    on stderr, where it would land in the output a CLI test reads."""

    def handle_error(self, request, client_address) -> None:
        import sys

        if isinstance(sys.exc_info()[1], (ConnectionError, TimeoutError)):
            return
        super().handle_error(request, client_address)


class LLMServer:
    """An OpenAI-compatible server on 127.0.0.1:<ephemeral port>; see the module docstring.

    ``url`` is the base URL to give a client (``http://127.0.0.1:PORT/v1``).
    ``models``, if given, is the set of model names it knows; any other gets 404
    like Ollama's "model not found". ``embedding_dim`` may be changed at any time.
    """

    def __init__(
        self,
        *,
        embedding_dim: int = 64,
        require_api_key: str | None = None,
        models: set[str] | None = None,
        responder: Callable[[dict], str | Action] = echo_last_user_message,
    ):
        self.embedding_dim = embedding_dim
        self.require_api_key = require_api_key
        self.models = models
        self.responder = responder
        self.requests: list[RecordedRequest] = []
        self.stream_mode = "sse"  # "sse" | "ignore" | "refuse"
        self.token_interval_s = 0.0
        self.context_tokens: int | None = None
        self.context_style = "llama-cpp-python"  # or "llama.cpp"
        self.props = False
        self.embedding_mode = "ok"  # "ok" | "no-embedding" | "not-implemented" | "per-token"
        self.tokens_sent = 0
        self.cancelled = threading.Event()
        self._actions: deque[Action] = deque()
        self._lock = threading.Lock()
        self._stopping = threading.Event()  # ends every Delay, so stopping never waits for one
        self._httpd: ThreadingHTTPServer | None = None
        self._thread: threading.Thread | None = None

    # lifecycle

    def start(self) -> LLMServer:
        self._stopping.clear()
        handler = _make_handler(self)
        self._httpd = _QuietServer(("127.0.0.1", 0), handler)
        self._httpd.daemon_threads = True
        self._thread = threading.Thread(
            target=self._httpd.serve_forever, kwargs={"poll_interval": 0.02}, name="llm-test-server", daemon=True
        )
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stopping.set()
        if self._httpd is not None:
            self._httpd.shutdown()
            self._httpd.server_close()
            self._httpd = None

    def __enter__(self) -> LLMServer:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    @property
    def port(self) -> int:
        assert self._httpd is not None, "server not started"
        return self._httpd.server_address[1]

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/v1"

    # scripting

    def script(self, *actions: Action) -> None:
        """Queue actions; each request takes the next one, in order."""
        with self._lock:
            self._actions.extend(actions)

    def reply(self, *contents: str) -> None:
        """Queue chat replies with these contents."""
        self.script(*(Reply(c) for c in contents))

    @property
    def pending(self) -> int:
        """How many scripted actions have not been used yet."""
        with self._lock:
            return len(self._actions)

    def _next_action(self) -> Action | None:
        with self._lock:
            return self._actions.popleft() if self._actions else None

    def _record(self, request: RecordedRequest) -> None:
        with self._lock:
            self.requests.append(request)

    # views of what was received

    def chat_requests(self) -> list[RecordedRequest]:
        with self._lock:
            return [r for r in self.requests if r.path.endswith("/chat/completions")]

    def embedding_requests(self) -> list[RecordedRequest]:
        with self._lock:
            return [r for r in self.requests if r.path.endswith("/embeddings")]


def _make_handler(server: LLMServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        protocol_version = "HTTP/1.1"
        server_version = "robocritics-test-llm/1.0"

        def log_message(self, format: str, *args: Any) -> None:  # keep test output clean
            pass

        def do_GET(self) -> None:
            if self.path.rstrip("/") == "/props" and server.props and server.context_tokens:
                self._send_json(
                    200,
                    {"default_generation_settings": {"n_ctx": server.context_tokens}, "total_slots": 1,
                     "chat_template": "{{ messages }}"},
                )  # fmt: skip
            elif self.path.rstrip("/") == "/v1/models":
                self._send_json(
                    200, {"object": "list", "data": [{"id": m, "object": "model"} for m in sorted(server.models or [])]}
                )
            else:
                self._send_json(404, {"error": {"message": f"no route {self.path}"}})

        def do_POST(self) -> None:
            arrived = time.monotonic()
            length = int(self.headers.get("Content-Length") or 0)
            raw = self.rfile.read(length) if length else b""
            try:
                decoded = json.loads(raw) if raw else None
            except ValueError:
                decoded = None
            server._record(
                RecordedRequest(
                    method="POST",
                    path=self.path,
                    headers={k.lower(): v for k, v in self.headers.items()},
                    body=raw,
                    json=decoded,
                    time_s=arrived,
                )
            )
            try:
                self._answer(decoded)
            except (BrokenPipeError, ConnectionResetError, TimeoutError):
                self.close_connection = True  # the client gave up (e.g. its timeout); nothing to do

        def _answer(self, request: Any) -> None:
            if server.require_api_key is not None:
                auth = self.headers.get("Authorization", "")
                given = auth.removeprefix("Bearer ").strip()
                if given != server.require_api_key:
                    self._send_json(
                        401,
                        {
                            "error": {
                                "message": f"Incorrect API key provided: {given}.",
                                "type": "invalid_request_error",
                            }
                        },
                    )
                    return
            action = server._next_action()
            self._perform(action, request)

        def _perform(self, action: Action | None, request: Any) -> None:
            if isinstance(action, Delay):
                if server._stopping.wait(action.seconds):
                    self.close_connection = True
                    return
                self._perform(action.then, request)
            elif isinstance(action, Fail):
                headers = dict(action.headers)
                if action.retry_after is not None:
                    headers["Retry-After"] = str(action.retry_after)
                if action.body is not None:
                    self._send(action.status, action.body.encode(), "application/json", headers)
                else:
                    body = {"error": {"message": f"scripted failure {action.status}", "code": action.status}}
                    self._send_json(action.status, body, headers)
            elif isinstance(action, Garbage):
                body = action.body.encode() if isinstance(action.body, str) else action.body
                self._send(action.status, body, action.content_type, action.headers)
            elif isinstance(action, Stream):
                self._stream(action)
            elif isinstance(action, SlowHeaders):
                self.close_connection = True
                head = b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: 2\r\n\r\n{}" * 1000
                for i in range(len(head)):
                    if server._stopping.wait(action.interval_s):
                        return
                    self.wfile.write(head[i : i + 1])
                    self.wfile.flush()
            elif isinstance(action, RawJSON):
                self._send_json(action.status, action.obj)
            elif isinstance(action, Drop):
                self.close_connection = True
                self.connection.shutdown(socket.SHUT_RDWR)
            else:
                self._route(action, request)

        def _route(self, action: Reply | None, request: Any) -> None:
            path = self.path.rstrip("/")
            if not isinstance(request, dict):
                self._send_json(400, {"error": {"message": "request body is not a JSON object"}})
                return
            model = request.get("model")
            if server.models is not None and model not in server.models:
                self._send_json(404, {"error": {"message": f'model "{model}" not found, try pulling it first'}})
                return
            if path == "/v1/chat/completions":
                if action is None:
                    answer = server.responder(request)
                    if not isinstance(answer, str):
                        self._perform(answer, request)
                        return
                    action = Reply(answer)
                self._send_chat(request, action)
            elif path == "/v1/embeddings":
                self._send_embeddings(request)
            else:
                self._send_json(404, {"error": {"message": f"no route {self.path}"}})

        def _send_chat(self, request: dict, reply: Reply) -> None:
            messages = request.get("messages", [])
            max_tokens = request.get("max_tokens")
            if server.context_tokens is not None:
                prompt = count_tokens(messages)
                wanted = prompt + (max_tokens if isinstance(max_tokens, int) else 0)
                if wanted > server.context_tokens:
                    if server.context_style == "llama.cpp":
                        error = {
                            "code": 400,
                            "message": "the request exceeds the available context size, try increasing it",
                            "type": "exceed_context_size_error",
                            "n_prompt_tokens": prompt,
                            "n_ctx": server.context_tokens,
                        }
                    else:  # llama-cpp-python's server
                        error = {
                            "message": f"Requested tokens ({wanted}) exceed context window of {server.context_tokens}",
                            "type": "invalid_request_error",
                            "param": "messages",
                            "code": "context_length_exceeded",
                        }
                    self._send_json(400, {"error": error})
                    return
            pieces = tokens(reply.content)
            finish = reply.finish_reason
            if isinstance(max_tokens, int) and max_tokens >= 0 and len(pieces) > max_tokens:
                pieces, finish = pieces[:max_tokens], "length"
            reply = Reply("".join(pieces), finish)
            if request.get("stream") is True and server.stream_mode == "refuse":
                self._send_json(400, {"error": {"message": "stream is not supported by this server"}})
                return
            if request.get("stream") is True and server.stream_mode == "sse":
                self._send_events(request, pieces, finish, count_tokens(messages))
                return
            prompt_words = sum(len(str(m.get("content", "")).split()) for m in messages)
            completion_words = len(pieces)
            self._send_json(
                200,
                {
                    "id": f"chatcmpl-{len(server.requests)}",
                    "object": "chat.completion",
                    "created": int(time.time()),
                    "model": request.get("model"),
                    "choices": [
                        {
                            "index": 0,
                            "message": {"role": "assistant", "content": reply.content},
                            "finish_reason": reply.finish_reason,
                        }
                    ],
                    "usage": {
                        "prompt_tokens": prompt_words,
                        "completion_tokens": completion_words,
                        "total_tokens": prompt_words + completion_words,
                    },
                },
            )

        def _send_events(self, request: dict, pieces: list[str], finish: str, prompt_tokens: int) -> None:
            """The reply as server-sent events, one token each, as llama.cpp and OpenAI stream them."""
            self.send_response(200)
            self.send_header("Content-Type", "text/event-stream")
            self.send_header("Cache-Control", "no-cache")
            self.send_header("Transfer-Encoding", "chunked")
            self.end_headers()
            self.close_connection = True
            ident = f"chatcmpl-{len(server.requests)}"

            def event(obj: Any) -> None:
                data = b"data: " + (obj if isinstance(obj, bytes) else json.dumps(obj).encode()) + b"\n\n"
                self.wfile.write(b"%x\r\n%s\r\n" % (len(data), data))
                self.wfile.flush()

            def chunk(delta: dict, finish_reason: str | None) -> dict:
                return {
                    "id": ident,
                    "object": "chat.completion.chunk",
                    "created": int(time.time()),
                    "model": request.get("model"),
                    "choices": [{"index": 0, "delta": delta, "finish_reason": finish_reason}],
                }

            try:
                event(chunk({"role": "assistant", "content": ""}, None))
                for piece in pieces:
                    if server.token_interval_s and server._stopping.wait(server.token_interval_s):
                        return
                    event(chunk({"content": piece}, None))
                    with server._lock:
                        server.tokens_sent += 1
                last = chunk({}, finish)
                last["usage"] = {
                    "prompt_tokens": prompt_tokens,
                    "completion_tokens": len(pieces),
                    "total_tokens": prompt_tokens + len(pieces),
                }
                event(last)
                event(b"[DONE]")
                self.wfile.write(b"0\r\n\r\n")
                self.wfile.flush()
            except (BrokenPipeError, ConnectionResetError, ConnectionAbortedError):
                server.cancelled.set()  # the client hung up: stop generating

        def _send_embeddings(self, request: dict) -> None:
            if server.embedding_mode == "no-embedding":
                self._send_json(
                    500,
                    {"error": {"message": "Llama model must be created with embedding=True to call this method",
                               "type": "internal_server_error"}},
                )  # fmt: skip
                return
            if server.embedding_mode == "not-implemented":
                self._send_json(
                    501,
                    {"error": {"code": 501, "message": "This server does not support embeddings. Start it with "
                               "`--embeddings`", "type": "not_supported_error"}},
                )  # fmt: skip
                return
            inputs = request.get("input")
            if isinstance(inputs, str):
                inputs = [inputs]
            if not isinstance(inputs, list) or not all(isinstance(t, str) for t in inputs):
                self._send_json(400, {"error": {"message": "'input' must be a string or a list of strings"}})
                return
            model = str(request.get("model"))
            if server.embedding_mode == "per-token":  # no pooling: one vector per token of each text
                data = [
                    {"object": "embedding", "index": i,
                     "embedding": [hashed_embedding(w, server.embedding_dim, model) for w in (t.split() or [t])]}
                    for i, t in enumerate(inputs)
                ]  # fmt: skip
            else:
                data = [
                    {"object": "embedding", "index": i, "embedding": hashed_embedding(t, server.embedding_dim, model)}
                    for i, t in enumerate(inputs)
                ]
            tokens = sum(len(t.split()) for t in inputs)
            self._send_json(
                200,
                {
                    "object": "list",
                    "data": data,
                    "model": model,
                    "usage": {"prompt_tokens": tokens, "total_tokens": tokens},
                },
            )

        def _stream(self, action: Stream) -> None:
            self.send_response(action.status)
            self.send_header("Content-Type", action.content_type)
            if action.length is not None:
                self.send_header("Content-Length", str(action.length))
            else:
                self.send_header("Transfer-Encoding", "chunked")
            for name, value in action.headers.items():
                self.send_header(name, value)
            self.end_headers()
            self.wfile.flush()
            for chunk in action.chunks():
                if action.interval_s and server._stopping.wait(action.interval_s):
                    self.close_connection = True
                    return
                if server._stopping.is_set():
                    self.close_connection = True
                    return
                if action.length is None:
                    self.wfile.write(b"%x\r\n%s\r\n" % (len(chunk), chunk))
                else:
                    self.wfile.write(chunk)
                self.wfile.flush()
            if action.length is None:
                self.wfile.write(b"0\r\n\r\n")
                self.wfile.flush()

        def _send_json(self, status: int, obj: Any, headers: dict[str, str] | None = None) -> None:
            self._send(status, json.dumps(obj).encode(), "application/json", headers)

        def _send(self, status: int, body: bytes, content_type: str, headers: dict[str, str] | None = None) -> None:
            self.send_response(status)
            self.send_header("Content-Type", content_type)
            self.send_header("Content-Length", str(len(body)))
            for name, value in (headers or {}).items():
                self.send_header(name, value)
            self.end_headers()
            self.wfile.write(body)
            self.wfile.flush()

    return Handler


def gzip_bomb(inflated_mib: int) -> bytes:
    """A gzip body of about ``inflated_mib`` MiB of zeros in ~1 KB per MiB (2048 MiB → 2 MB), built in milliseconds.

    Every MiB is compressed after a full flush, so the segments are identical
    and the stream is their repetition. The trailer's checksum is not that of
    the data: a client must stop long before it (at its size limit).
    """
    import zlib

    mib = bytes(1 << 20)
    deflate = zlib.compressobj(9, zlib.DEFLATED, 16 + zlib.MAX_WBITS)
    first = deflate.compress(mib) + deflate.flush(zlib.Z_FULL_FLUSH)
    segment = deflate.compress(mib) + deflate.flush(zlib.Z_FULL_FLUSH)
    return first + segment * (inflated_mib - 1) + deflate.flush()
