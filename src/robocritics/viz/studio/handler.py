"""The studio's HTTP routes: the checks of the security model (:mod:`.server`), body validation, JSON answers.

Every request that is not what a route takes gets a 4xx with ``{"error": "..."}``: a body that is not JSON or is
nested too deeply, an id that is not an integer, a critic name that is not a string or not installed (400);
another job running or a refusal (409). Nothing from a request can end in a dropped connection or a traceback.
"""

from __future__ import annotations

import hmac
import json
import logging
import sys
from http.cookies import SimpleCookie
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Iterator
from urllib.parse import parse_qs, urlsplit

from .common import MAX_BODY_BYTES, MAX_CHAT_CHARS, MAX_PROGRAM_CHARS, StudioError, is_loopback

__all__ = ["serve"]

log = logging.getLogger(__name__)


class _QuietServer(ThreadingHTTPServer):
    """A browser that closes a connection mid-request is normal, not a traceback on stderr; other errors are logged."""

    daemon_threads = True

    def handle_error(self, request, client_address) -> None:
        exc = sys.exc_info()[1]
        if isinstance(exc, (ConnectionError, TimeoutError)):
            return
        log.error("studio: request from %s failed: %s: %s", client_address[0], type(exc).__name__, exc)


def serve(studio: Any, host: str, port: int) -> ThreadingHTTPServer:
    """A threaded HTTP server for ``studio`` on ``host``:``port`` (not yet serving)."""
    handler = type("StudioHandler", (_Handler,), {"studio": studio})
    return _QuietServer((host, port), handler)


class BadRequest(ValueError):
    """The request body is not what the route takes (HTTP 400)."""


#: Largest id or revision number a request may name: an id of 4,000 digits was quoted whole in the answer.
MAX_ID = 10**12


def _int(body: dict[str, Any], key: str) -> int:
    value = body.get(key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise BadRequest(f"{key} must be an integer, got {type(value).__name__}")
    if not 0 <= value <= MAX_ID:
        raise BadRequest(f"{key} must be an integer from 0 to {MAX_ID:,}")
    return value


def _critics(body: dict[str, Any], key: str, installed: list[str]) -> list[str] | None:
    value = body.get(key)
    if value is None:
        return None
    if not isinstance(value, list) or len(value) > 1000 or not all(isinstance(c, str) for c in value):
        raise BadRequest(f"{key} must be a list of critic names (strings)")
    unknown = [c for c in value if c not in installed and c != "task_outcome"]
    if unknown:
        raise BadRequest(f"{key}: unknown critic {unknown[0][:80]!r} (installed: {', '.join(installed)})")
    return value


def _text(body: dict[str, Any], key: str, limit: int, default: str = "") -> str:
    value = body.get(key, default)
    if not isinstance(value, str) or len(value) > limit:
        raise BadRequest(f"{key} must be a string of at most {limit} characters")
    return value


class _Handler(BaseHTTPRequestHandler):
    studio: Any  # the Studio (server.py imports this module: no import back)
    server_version = "robocritics-studio"
    protocol_version = "HTTP/1.1"  # chunked NDJSON streams for chat and Fix

    def log_message(self, format: str, *args) -> None:  # quiet: the CLI prints the URL, not every request
        pass

    # --- checks ------------------------------------------------------------------------------------

    def _refuse(self, status: int, message: str) -> None:
        self._json({"error": message}, status)

    @property
    def _cookie_name(self) -> str:
        return f"robocritics_studio_{self.studio.port}"  # cookies are per host, not per port

    def _host_ok(self) -> bool:
        host = self.headers.get("Host", "")
        port = str(self.studio.port)
        allowed = {f"{self.studio.host}:{port}", f"localhost:{port}", f"127.0.0.1:{port}", f"[::1]:{port}"}
        if ":" in self.studio.host:
            allowed.add(f"[{self.studio.host}]:{port}")
        return host in allowed or (not is_loopback(self.studio.host) and host.endswith(f":{port}"))

    def _origin_ok(self) -> bool:
        origin = self.headers.get("Origin")
        return origin is None or origin == f"http://{self.headers.get('Host', '')}"

    def _token_ok(self, query: dict[str, list[str]]) -> bool:
        token = self.studio.token
        if token is None:
            return True
        cookie = SimpleCookie()
        try:
            cookie.load(self.headers.get("Cookie", ""))
        except Exception:  # noqa: BLE001 - a malformed cookie header is no token
            cookie = SimpleCookie()
        morsel = cookie.get(self._cookie_name)
        for given in (self.headers.get("X-Studio-Token"), (query.get("token") or [None])[0],
                      morsel.value if morsel else None):
            if given and hmac.compare_digest(given.encode(), token.encode()):
                return True
        return False

    def _checked(self, api: bool) -> dict[str, list[str]] | None:
        query = parse_qs(urlsplit(self.path).query)
        if not self._host_ok():
            self._refuse(403, "Host header is not this studio's (DNS rebinding?)")
            return None
        if not self._origin_ok():
            self._refuse(403, "cross-origin request refused")
            return None
        if not self._token_ok(query):
            self._refuse(401, "this studio needs its token (open the URL it printed)")
            return None
        if api and self.command == "POST":
            if self.headers.get("Content-Type", "").split(";")[0].strip() != "application/json" or \
                    self.headers.get("X-Studio") != "1":
                self._refuse(403, "API calls need Content-Type: application/json and X-Studio: 1")
                return None
        return query

    def _body(self) -> dict[str, Any] | None:
        try:
            length = int(self.headers.get("Content-Length", "0"))
        except ValueError:
            length = -1
        if length < 0 or length > MAX_BODY_BYTES:
            self._refuse(413, f"request body must be at most {MAX_BODY_BYTES} bytes")
            return None
        try:
            body = json.loads(self.rfile.read(length) or b"{}")
        except (ValueError, RecursionError):  # RecursionError: nested deeper than the parser's stack
            self._refuse(400, "request body is not JSON (or is nested too deeply)")
            return None
        if not isinstance(body, dict):
            self._refuse(400, "request body must be a JSON object")
            return None
        return body

    def _json(self, value: Any, status: int = 200, headers: dict[str, str] | None = None) -> None:
        body = json.dumps(value, allow_nan=False).encode()
        self.send_response(status)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        for name, text in (headers or {}).items():
            self.send_header(name, text)
        self.end_headers()
        self.wfile.write(body)

    # --- routes ------------------------------------------------------------------------------------

    def do_GET(self) -> None:
        path = urlsplit(self.path).path
        query = self._checked(api=path.startswith("/api/"))
        if query is None:
            return
        if path == "/":
            self._page(query)
        elif path == "/api/state":
            seen = (query.get("chat") or [""])[0]
            self._json(self.studio.state(int(seen) if seen.isdigit() and len(seen) < 12 else None))
        elif path.startswith("/api/revision/"):
            name = path.rsplit("/", 1)[1]
            try:
                index = self.studio.next_index - 1 if name == "latest" else int(name)
                revision = self.studio.revision(index)
            except (ValueError, LookupError):
                self._refuse(404, f"no revision {name[:40]!r}")
                return
            self._json(revision.full())
        else:
            self._refuse(404, f"no page {path[:200]!r}")

    def _page(self, query: dict[str, list[str]]) -> None:
        from .page import studio_page

        body = studio_page().encode()
        self.send_response(200)
        self.send_header("Content-Type", "text/html; charset=utf-8")
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("Content-Security-Policy", "default-src 'self' 'unsafe-inline' blob: data:; "
                         "connect-src 'self'")
        if self.studio.token and query.get("token"):  # the first visit: from now on the token is a cookie
            self.send_header("Set-Cookie", f"{self._cookie_name}={self.studio.token}; HttpOnly; SameSite=Strict; "
                             "Path=/")
        self.end_headers()
        self.wfile.write(body)

    def do_POST(self) -> None:
        path = urlsplit(self.path).path
        if self._checked(api=True) is None:
            return
        body = self._body()
        if body is None:
            return
        try:
            self._post(path, body)
        except BadRequest as exc:
            self._refuse(400, str(exc))
        except StudioError as exc:  # StudioBusy too: another job runs
            self._refuse(409, str(exc))
        except (ConnectionError, TimeoutError):
            return  # the page went away mid-answer (a reload during a Fix): its job goes on, /api/state shows it
        except Exception as exc:  # noqa: BLE001 - a bug: an answer, one log line, no traceback to the client
            log.error("studio: %s failed: %s: %s", path, type(exc).__name__, exc)
            self._refuse(500, f"{type(exc).__name__}: {exc}")

    def _post(self, path: str, body: dict[str, Any]) -> None:
        studio = self.studio
        installed = studio.installed_critics()
        if path == "/api/run":
            program = _text(body, "program", MAX_PROGRAM_CHARS, default=None)  # type: ignore[arg-type]
            self._json(studio.run(program, _critics(body, "critics", installed)).full())
        elif path in ("/api/chat", "/api/fix"):
            text = _text(body, "text", MAX_CHAT_CHARS)
            automation = body.get("automation", "guided")
            if automation not in ("manual", "guided", "auto"):
                raise BadRequest("automation must be manual, guided or auto")
            index = _int(body, "index") if body.get("index") is not None else None
            events = studio.llm_turn("chat" if path == "/api/chat" else "fix", text=text,
                                     critics=_critics(body, "critics", installed), automation=automation,
                                     index=index, selected=_critics(body, "selected", installed))
            self._stream(events)
        elif path == "/api/approve":
            ok = body.get("ok")
            if not isinstance(ok, bool):
                raise BadRequest("ok must be true or false")
            studio.answer(_int(body, "id"), ok)
            self._json({"ok": True})
        elif path == "/api/deploy":
            program = body.get("program")
            if program is not None and not isinstance(program, str):
                raise BadRequest("program must be a string")
            self._json(studio.deploy(_int(body, "index"), program))
        elif path == "/api/stop":
            self._json(studio.cancel())
        else:
            self._refuse(404, f"no API {path[:200]!r}")

    def _stream(self, events: Iterator[dict[str, Any]]) -> None:
        """Send ``events`` as NDJSON, one line per event, flushed as each arrives (chunked transfer)."""
        self.send_response(200)
        self.send_header("Content-Type", "application/x-ndjson")
        self.send_header("Cache-Control", "no-store")
        self.send_header("Transfer-Encoding", "chunked")
        self.end_headers()
        for event in events:
            line = (json.dumps(event, allow_nan=False) + "\n").encode()
            self.wfile.write(f"{len(line):x}\r\n".encode() + line + b"\r\n")
            self.wfile.flush()
        self.wfile.write(b"0\r\n\r\n")
        self.wfile.flush()
