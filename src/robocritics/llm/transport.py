"""Bounded HTTP for the LLM client: a request deadline every socket operation obeys, and capped bodies.

Three pieces, each usable on its own (the chat client uses all three; a
streaming (SSE) reader can reuse the last two):

* :class:`DeadlineTransport` — an ``httpx`` transport whose every connect,
  write and read waits at most until the deadline of the current request
  (:func:`deadline_scope`), on top of httpx's per-phase timeouts. Without it
  a server that sends one byte every second never trips a read timeout and
  a request can last forever.
* :func:`iter_body` — the decoded chunks of a streamed response, with the
  number of bytes capped both on the wire and after decompression (gzip
  and deflate are inflated here, at most the cap at a time, so a "zip bomb"
  never allocates more than the cap), and the deadline checked between
  chunks. :func:`read_body` collects them.
* :func:`loads_json` — ``json.loads`` after a linear scan that refuses
  deep nesting (the decoder recurses per level) and absurd numbers of
  arrays/objects (memory), with every failure a :class:`LLMError`.
"""

from __future__ import annotations

import contextvars
import json
import re
import time
import zlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import httpcore
import httpx
import numpy as np

from ..errors import LLMError
from .limits import MAX_JSON_CONTAINERS, MAX_JSON_DEPTH

__all__ = [
    "ACCEPT_ENCODING",
    "Deadline",
    "DeadlineTransport",
    "deadline_scope",
    "iter_body",
    "NotJSONError",
    "check_json_shape",
    "loads_json",
    "read_body",
]

#: The content codings the client asks for and can inflate with a bounded output.
ACCEPT_ENCODING = "gzip, deflate"

Clock = Callable[[], float]


@dataclass(frozen=True)
class Deadline:
    """An absolute deadline ``at_s`` on ``clock`` (seconds), with the configured length for messages."""

    at_s: float
    clock: Clock
    length_s: float

    def remaining_s(self) -> float:
        return self.at_s - self.clock()

    def passed(self) -> bool:
        return self.remaining_s() <= 0.0

    @classmethod
    def after(cls, length_s: float, clock: Clock = time.monotonic) -> Deadline:
        return cls(clock() + length_s, clock, length_s)


_CURRENT: contextvars.ContextVar[Deadline | None] = contextvars.ContextVar("robocritics_llm_deadline", default=None)


@contextmanager
def deadline_scope(deadline: Deadline) -> Iterator[Deadline]:
    """Make ``deadline`` the one :class:`DeadlineTransport` enforces in this thread (or task), for the block."""
    token = _CURRENT.set(deadline)
    try:
        yield deadline
    finally:
        _CURRENT.reset(token)


def _bounded(timeout: float | None, on_expiry: type[Exception]) -> float | None:
    """``timeout`` lowered to the time left before the current deadline; ``on_expiry`` raised when none is left."""
    deadline = _CURRENT.get()
    if deadline is None:
        return timeout
    remaining = deadline.remaining_s()
    if remaining <= 0.0:
        raise on_expiry(f"the request deadline of {deadline.length_s:g} s has passed")
    return remaining if timeout is None else min(timeout, remaining)


class _DeadlineStream(httpcore.NetworkStream):
    """A network stream whose reads and writes end at the current deadline."""

    def __init__(self, stream: httpcore.NetworkStream):
        self._stream = stream

    def read(self, max_bytes: int, timeout: float | None = None) -> bytes:
        return self._stream.read(max_bytes, _bounded(timeout, httpcore.ReadTimeout))

    def write(self, buffer: bytes, timeout: float | None = None) -> None:
        self._stream.write(buffer, _bounded(timeout, httpcore.WriteTimeout))

    def close(self) -> None:
        self._stream.close()

    def start_tls(self, ssl_context: Any, server_hostname: str | None = None, timeout: float | None = None):
        stream = self._stream.start_tls(ssl_context, server_hostname, _bounded(timeout, httpcore.ConnectTimeout))
        return _DeadlineStream(stream)

    def get_extra_info(self, info: str) -> Any:
        return self._stream.get_extra_info(info)


class _DeadlineBackend(httpcore.NetworkBackend):
    """httpcore's socket backend, with every connection's operations bounded by the current deadline."""

    def __init__(self) -> None:
        self._backend = httpcore.SyncBackend()

    def connect_tcp(self, host, port, timeout=None, local_address=None, socket_options=None):
        stream = self._backend.connect_tcp(
            host, port, _bounded(timeout, httpcore.ConnectTimeout), local_address, socket_options
        )
        return _DeadlineStream(stream)

    def connect_unix_socket(self, path, timeout=None, socket_options=None):
        stream = self._backend.connect_unix_socket(path, _bounded(timeout, httpcore.ConnectTimeout), socket_options)
        return _DeadlineStream(stream)

    def sleep(self, seconds: float) -> None:
        self._backend.sleep(seconds)


# httpcore's exceptions as the httpx ones callers catch (most specific first).
_EXCEPTIONS: tuple[tuple[type[Exception], type[httpx.HTTPError]], ...] = (
    (httpcore.ConnectTimeout, httpx.ConnectTimeout),
    (httpcore.ReadTimeout, httpx.ReadTimeout),
    (httpcore.WriteTimeout, httpx.WriteTimeout),
    (httpcore.PoolTimeout, httpx.PoolTimeout),
    (httpcore.TimeoutException, httpx.TimeoutException),
    (httpcore.ConnectError, httpx.ConnectError),
    (httpcore.ReadError, httpx.ReadError),
    (httpcore.WriteError, httpx.WriteError),
    (httpcore.NetworkError, httpx.NetworkError),
    (httpcore.ProxyError, httpx.ProxyError),
    (httpcore.UnsupportedProtocol, httpx.UnsupportedProtocol),
    (httpcore.RemoteProtocolError, httpx.RemoteProtocolError),
    (httpcore.LocalProtocolError, httpx.LocalProtocolError),
    (httpcore.ProtocolError, httpx.ProtocolError),
)


@contextmanager
def _httpx_errors() -> Iterator[None]:
    try:
        yield
    except Exception as exc:
        for core, mapped in _EXCEPTIONS:
            if isinstance(exc, core):
                raise mapped(str(exc)) from exc
        raise


class _Stream(httpx.SyncByteStream):
    def __init__(self, stream: Any):
        self._stream = stream

    def __iter__(self) -> Iterator[bytes]:
        with _httpx_errors():
            yield from self._stream

    def close(self) -> None:
        if hasattr(self._stream, "close"):
            self._stream.close()


class DeadlineTransport(httpx.BaseTransport):
    """HTTP/1.1 over httpcore's connection pool, with every socket operation bounded by :func:`deadline_scope`.

    Outside a deadline scope it behaves like ``httpx.HTTPTransport()``.
    """

    def __init__(self) -> None:
        self._pool = httpcore.ConnectionPool(
            ssl_context=httpx.create_ssl_context(),
            max_connections=100,
            max_keepalive_connections=20,
            keepalive_expiry=5.0,
            network_backend=_DeadlineBackend(),
        )

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        assert isinstance(request.stream, httpx.SyncByteStream)
        core_request = httpcore.Request(
            method=request.method,
            url=httpcore.URL(
                scheme=request.url.raw_scheme,
                host=request.url.raw_host,
                port=request.url.port,
                target=request.url.raw_path,
            ),
            headers=request.headers.raw,
            content=request.stream,
            extensions=request.extensions,
        )
        with _httpx_errors():
            response = self._pool.handle_request(core_request)
        return httpx.Response(
            status_code=response.status,
            headers=response.headers,
            stream=_Stream(response.stream),
            extensions=response.extensions,
        )

    def close(self) -> None:
        self._pool.close()


# --- bodies -----------------------------------------------------------------------------------------


class _Inflater:
    """Inflates gzip or deflate data, never producing more than asked for at once."""

    def __init__(self, coding: str):
        self.coding = coding
        # deflate is zlib-wrapped by the standard, raw by some servers: try the first, fall back to the second.
        self._wbits = 16 + zlib.MAX_WBITS if coding == "gzip" else zlib.MAX_WBITS
        self._inflate = zlib.decompressobj(self._wbits)
        self._started = False

    def feed(self, data: bytes, max_out: int) -> bytes:
        """Inflate ``data``; at most ``max_out`` bytes come out (exactly ``max_out`` means: more would follow)."""
        try:
            out = self._inflate.decompress(data, max_out)
        except zlib.error:
            if self.coding != "deflate" or self._started:
                raise
            self._wbits = -zlib.MAX_WBITS
            self._inflate = zlib.decompressobj(self._wbits)
            out = self._inflate.decompress(data, max_out)
        self._started = True
        return out

    def unfinished(self) -> bool:
        return bool(self._inflate.unconsumed_tail)


def _coding(response: httpx.Response) -> str:
    value = response.headers.get("content-encoding", "").strip().lower()
    if value in ("", "identity"):
        return ""
    if value in ("gzip", "x-gzip"):
        return "gzip"
    if value == "deflate":
        return "deflate"
    raise LLMError(
        f"the server at {response.request.url} sent a body with Content-Encoding {value[:60]!r}; "
        f"only {ACCEPT_ENCODING} (which the client asks for) can be read"
    )


def iter_body(
    response: httpx.Response,
    *,
    max_bytes: int,
    deadline: Deadline | None = None,
    what: str = "reply",
    stop_at_limit: bool = False,
) -> Iterator[bytes]:
    """The decoded body of a streamed ``response``, chunk by chunk as it arrives.

    Raises :class:`LLMError` as soon as more than ``max_bytes`` arrive on the
    wire or come out of decompression (inflating one chunk is itself capped,
    so memory stays within ``max_bytes``), when the body is not valid
    gzip/deflate, and when ``deadline`` passes between two chunks. With
    ``stop_at_limit`` reaching ``max_bytes`` is not an error: the chunks end
    there (for error pages, which are only quoted). Network errors propagate
    as ``httpx`` exceptions, so the caller decides whether to retry.
    """
    url = response.request.url
    coding = _coding(response)
    inflater = _Inflater(coding) if coding else None
    wire = decoded = 0
    for chunk in response.iter_raw():
        wire += len(chunk)
        if wire > max_bytes and not stop_at_limit:
            raise LLMError(f"the {what} from {url} is larger than the limit of {max_bytes:,} bytes; stopped reading")
        if inflater is not None and chunk:
            try:
                chunk = inflater.feed(chunk, max_bytes - decoded + 1)
            except zlib.error as exc:
                raise LLMError(f"the {what} from {url} is not valid {coding} data ({exc})") from None
            if (decoded + len(chunk) > max_bytes or inflater.unfinished()) and not stop_at_limit:
                raise LLMError(
                    f"the {what} from {url} inflates ({coding}) to more than the limit of {max_bytes:,} bytes "
                    f"({wire:,} bytes received); stopped reading"
                )
        chunk = chunk[: max_bytes - decoded]
        decoded += len(chunk)
        if chunk:
            yield chunk
        if stop_at_limit and (decoded >= max_bytes or wire >= max_bytes):
            return
        if deadline is not None and deadline.passed():
            raise LLMError(
                f"the {what} from {url} was still arriving when the request deadline of {deadline.length_s:g} s "
                f"passed ({wire:,} bytes received)"
            )


def read_body(
    response: httpx.Response,
    *,
    max_bytes: int,
    deadline: Deadline | None = None,
    what: str = "reply",
    stop_at_limit: bool = False,
) -> bytes:
    """All of :func:`iter_body` (same arguments) as one bytes object."""
    buffer = bytearray()
    for chunk in iter_body(response, max_bytes=max_bytes, deadline=deadline, what=what, stop_at_limit=stop_at_limit):
        buffer += chunk
    return bytes(buffer)


# --- JSON -------------------------------------------------------------------------------------------

# A JSON string, escapes included; unrolled so that long strings cost no backtracking.
_JSON_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)
_OPEN = (ord("["), ord("{"))
_CLOSE = (ord("]"), ord("}"))


def check_json_shape(raw: bytes, *, where: str) -> None:
    """Raise :class:`LLMError` if JSON text ``raw`` nests deeper than ``MAX_JSON_DEPTH`` or holds more than
    ``MAX_JSON_CONTAINERS`` arrays and objects.

    A linear scan of the bracket structure (brackets inside strings do not
    count) that never recurses; malformed text is left to the decoder.
    """
    opens = raw.count(b"[") + raw.count(b"{")
    if opens <= MAX_JSON_DEPTH:
        return  # neither limit can be exceeded: the depth is at most the number of brackets
    structure = _JSON_STRING.sub(b'""', raw) if b'"' in raw else raw
    codes = np.frombuffer(structure, dtype=np.uint8)
    is_open = (codes == _OPEN[0]) | (codes == _OPEN[1])
    containers = int(np.count_nonzero(is_open))
    if containers > MAX_JSON_CONTAINERS:
        raise LLMError(
            f"the JSON from {where} holds {containers:,} arrays and objects; the limit is {MAX_JSON_CONTAINERS:,}"
        )
    if containers <= MAX_JSON_DEPTH:
        return
    is_close = (codes == _CLOSE[0]) | (codes == _CLOSE[1])
    steps = is_open[is_open | is_close].astype(np.int32) * 2 - 1  # +1 per opening, -1 per closing bracket
    depth = int(np.cumsum(steps).max(initial=0))
    if depth > MAX_JSON_DEPTH:
        raise LLMError(f"the JSON from {where} nests {depth:,} levels deep; the limit is {MAX_JSON_DEPTH}")


def loads_json(raw: bytes, *, where: str) -> Any:
    """Decode JSON ``raw`` (UTF-8; undecodable bytes become U+FFFD) after :func:`check_json_shape`.

    Every failure is an :class:`LLMError` naming ``where`` (e.g. the URL);
    text that is not JSON raises its subclass ``NotJSONError``.
    """
    check_json_shape(raw, where=where)
    text = raw.decode("utf-8", errors="replace")
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, a number beyond int's digit limit
        raise NotJSONError(f"the body from {where} is not JSON: {exc}") from None


class NotJSONError(LLMError):
    """A body is not JSON text (the client words its own error, quoting what arrived)."""
