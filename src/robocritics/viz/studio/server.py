"""The studio's HTTP server: one inlined page and a small JSON API, on loopback by default.

Security model (docs/studio.md): the studio can move a robot, so

* it binds 127.0.0.1 unless told otherwise, and :class:`Studio` refuses a non-loopback host without a token;
* with a token, every request (page and API) must carry it (``?token=`` for the page, the ``X-Studio-Token``
  header for API calls), compared with :func:`hmac.compare_digest`; otherwise 401;
* even without a token, other web sites open in the same browser are kept out: API calls need
  ``Content-Type: application/json`` and the ``X-Studio`` header (a cross-origin page cannot send either without
  a CORS preflight, which is never answered), the ``Host`` header must name the bound port on a loopback name
  (DNS rebinding), and an ``Origin``, when present, must be the studio's own;
* request bodies are capped at :data:`MAX_BODY_BYTES` and programs at :data:`MAX_PROGRAM_CHARS`.

Simulation runs in the :class:`~robocritics.viz.studio.worker.Evaluator`'s resource-limited child process; the
server is threaded, so other requests are answered while a run or an LLM call is going.
"""

from __future__ import annotations

import hmac
import logging
import sys
import ipaddress
import json
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Iterator
from urllib.parse import parse_qs, urlsplit

from ...errors import RoboCriticsError

__all__ = ["Studio", "StudioError", "is_loopback", "MAX_BODY_BYTES", "MAX_PROGRAM_CHARS", "APPROVAL_TIMEOUT_S"]

#: Largest request body accepted, bytes.
MAX_BODY_BYTES = 1_000_000
#: Longest program accepted, characters.
MAX_PROGRAM_CHARS = 200_000
#: Seconds a revision waits for the page's approve/reject before it is rejected.
APPROVAL_TIMEOUT_S = 600.0
#: Longest chat message accepted, characters.
MAX_CHAT_CHARS = 20_000


class _QuietServer(ThreadingHTTPServer):
    """A browser that closes a connection mid-request is normal, not a traceback on stderr; other errors are logged."""

    def handle_error(self, request, client_address) -> None:
        exc = sys.exc_info()[1]
        if isinstance(exc, (ConnectionError, TimeoutError)):
            return
        logging.getLogger(__name__).exception("studio: request from %s failed", client_address[0])


class StudioError(RoboCriticsError):
    """The studio cannot start as configured (e.g. a non-loopback host without a token)."""


def is_loopback(host: str) -> bool:
    """True for ``localhost``, any 127.0.0.0/8 address and ::1."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


#: Error types of a program that does not run (sandbox, planning, motion budget): reported by the runtime critic.
RUNTIME_ERRORS = ("ProgramError", "PlanningError", "MotionBudgetError")


class _Revision:
    """One checked program: a user Run or an LLM attempt."""

    def __init__(self, index: int, kind: str, program: str, execution=None, report=None, error: str | None = None,
                 diff: str = "", duration_s: float = 0.0):
        self.index = index
        self.kind = kind
        self.program = program
        self.execution = execution
        self.report = report
        self.error = error
        self.diff = diff
        self.duration_s = duration_s

    def summary(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "kind": self.kind,
            "score": None if self.report is None else self.report.score,
            "has_errors": self.report is None or self.report.has_errors,
            "error": self.error,
        }

    def full(self) -> dict[str, Any]:
        from .. import replay_data

        verdicts = []
        if self.report is not None:
            for v in self.report.verdicts:
                verdicts.append({
                    "critic": v.critic, "flag": v.flag.value.lower(), "message": v.message, "hint": v.hint,
                    "lines": list(v.evidence.lines),
                })
        return {
            **self.summary(),
            "program": self.program,
            "diff": self.diff,
            "verdicts": verdicts,
            "feedback": self.error if self.report is None else self.report.feedback(),
            "replay": None if self.execution is None else replay_data(self.execution, self.report),
            "duration_s": self.duration_s,
        }


class Studio:
    """The studio web app for one scene.

    ``Studio(scene, program=None, *, host="127.0.0.1", port=0, token=None, model=None, deploy=None,
    critics=None, evaluator=None)``: ``scene`` a :class:`~robocritics.scene.Scene` (or its name/path);
    ``program`` the editor's first text; ``model`` a :class:`~robocritics.llm.providers.openai_compatible.ChatModel` for chat and Fix
    (None: both disabled, the page says why); ``deploy`` ``{"host", "rtde_port", "dashboard_port",
    "secondary_port"}`` of a UR controller (None: Deploy disabled); ``critics`` the critics run (default: all
    installed); ``timeout_s`` the wall-clock bound of one simulation, s.
    """

    def __init__(self, scene, program: str | None = None, *, host: str = "127.0.0.1", port: int = 0,
                 token: str | None = None, model=None, deploy: dict[str, Any] | None = None, critics=None,
                 goals=None, timeout_s: float = 60.0, no_model_reason: str = "no LLM endpoint is configured (start the studio "
                 "with --base-url and --model)"):
        from ...scene import Scene

        if not is_loopback(host) and not token:
            raise StudioError(f"refusing to bind the studio to {host}, which is not loopback, without a token: "
                              "anyone who can reach it could move the robot (give a token)")
        self.scene = scene if isinstance(scene, Scene) else Scene.resolve(scene)
        self.program = program or ""
        self.host = host
        self.token = token or None
        self.model = model
        self.no_model_reason = no_model_reason
        self.deploy_target = dict(deploy) if deploy else None
        self.critics = list(critics) if critics else None
        from ...goals import parse_goals

        self.goals = parse_goals(goals, self.scene)  # a bad goal (GoalError) fails here, before serving
        self.timeout_s = float(timeout_s)
        self.revisions: list[_Revision] = []
        self._lock = threading.Lock()
        self._run_lock = threading.Lock()  # one simulation / LLM turn at a time
        self._evaluator = None
        self._evaluator_lock = threading.Lock()
        self._loop = None
        self._approvals: dict[int, dict[str, Any]] = {}
        self._approval_cond = threading.Condition(self._lock)
        self._events: list[dict[str, Any]] = []  # the events of the LLM turn in progress
        self._server: ThreadingHTTPServer | None = None
        self._thread: threading.Thread | None = None
        self._requested_port = int(port)

    # --- lifecycle -------------------------------------------------------------------------------

    def start(self) -> "Studio":
        handler = type("StudioHandler", (_Handler,), {"studio": self})
        self._server = _QuietServer((self.host, self._requested_port), handler)
        self._server.daemon_threads = True
        self._thread = threading.Thread(target=self._server.serve_forever, name="robocritics-studio", daemon=True)
        self._thread.start()
        # Warm the worker (imports, robot model) now, so the first Run does not pay for it.
        threading.Thread(target=lambda: self.evaluator, name="robocritics-studio-warm", daemon=True).start()
        return self

    @property
    def port(self) -> int:
        assert self._server is not None, "start() the studio first"
        return self._server.server_address[1]

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        query = f"?token={self.token}" if self.token else ""
        return f"http://{host}:{self.port}/{query}"

    def stop(self) -> None:
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
            self._server = None
        with self._lock:
            for pending in self._approvals.values():
                pending.setdefault("answer", False)
            self._approval_cond.notify_all()
        if self._evaluator is not None:
            self._evaluator.close()
            self._evaluator = None
        if self._loop is not None:
            self._loop.close()
            self._loop = None

    def __enter__(self) -> "Studio":
        return self.start()

    def __exit__(self, *exc_info) -> None:
        self.stop()

    def serve_forever(self) -> None:
        """Block until Ctrl-C (KeyboardInterrupt), then stop cleanly."""
        try:
            while self._thread is not None and self._thread.is_alive():
                self._thread.join(0.5)
        finally:
            self.stop()

    # --- the work behind the API -------------------------------------------------------------------

    @property
    def evaluator(self):
        """The worker process (started once; :meth:`start` warms it up in the background)."""
        with self._evaluator_lock:
            if self._evaluator is None:
                from .worker import Evaluator

                self._evaluator = Evaluator(self.scene, critics=self.critics, goals=self.goals,
                                            timeout_s=self.timeout_s)
            return self._evaluator

    def installed_critics(self) -> list[str]:
        from ...critic.plugins import get_critics

        return list(get_critics())

    def state(self) -> dict[str, Any]:
        return {
            "scene": self.scene.name,
            "program": self.program,
            "critics": self.installed_critics(),
            "selected": self.critics or self.installed_critics(),
            "goals": [str(g) for g in self.goals],
            "chat": None if self.model is not None else self.no_model_reason,
            "deploy": None if self.deploy_target else "no UR controller is configured (--deploy-host)",
            "revisions": [r.summary() for r in self.revisions],
            "max_program_chars": MAX_PROGRAM_CHARS,
        }

    def _add(self, revision_kwargs: dict[str, Any]) -> _Revision:
        with self._lock:
            revision = _Revision(len(self.revisions) + 1, **revision_kwargs)
            self.revisions.append(revision)
            return revision

    def run(self, program: str, critics: list[str] | None = None) -> _Revision:
        """Simulate and critique ``program`` in the worker; record and return the revision."""
        with self._run_lock:
            evaluation = self.evaluator.evaluate(program, critics=critics or None)
            error, report = None, evaluation.report
            if evaluation.error is not None:
                e = evaluation.error
                where = f" (line {e['line']})" if e.get("line") else ""
                error = f"{e['type']}{where}: {e['message']}"
                if e["type"] in RUNTIME_ERRORS:  # the runtime critic's Error verdict: scored, listed, fixable
                    from ...critic import runtime_report
                    from .worker import _rebuild

                    report = runtime_report(_rebuild(e))
            revision = self._add(dict(kind="run", program=program, execution=evaluation.execution,
                                      report=report, error=error, duration_s=evaluation.duration_s))
            self.program = program
            self._adopt(revision)
            return revision

    def _loop_for(self, automation: str):
        from ...llm.loop import Loop

        if self.model is None:
            raise StudioError(self.no_model_reason)
        if self._loop is None:
            self._loop = Loop(self.model, self.scene, critics=self.critics, goals=self.goals, approve=self._approve,
                              simulate=self.evaluator.loop_simulate, repairs=self.evaluator.loop_repair,
                              on_attempt=self._on_attempt)
        self._loop.automation = automation
        return self._loop

    def _adopt(self, revision: _Revision) -> None:
        """Make a user Run the loop's current program, so Fix sends its feedback."""
        if self._loop is None or revision.report is None:
            return
        from ...llm.loop import Attempt

        loop = self._loop
        if loop.task is None:
            loop.task = "improve this robot program"
        attempt = Attempt(index=len(loop.attempts) + 1, kind="user", request=loop.task, prompt="", reply="",
                          program=revision.program, execution=revision.execution, report=revision.report,
                          score=revision.report.score)
        loop.attempts.append(attempt)
        loop.current = attempt

    def _on_attempt(self, attempt) -> None:
        if attempt.approved is False or attempt.program is None:
            return
        revision = self._add(dict(kind=attempt.kind, program=attempt.program, execution=attempt.execution,
                                  report=attempt.report, error=attempt.error, diff=attempt.diff))
        self.program = attempt.program
        self._events.append({"type": "revision", "revision": revision.full()})

    def _approve(self, program: str, diff: str) -> bool:
        """Loop's approval callback: post the diff to the page and wait (bounded) for its answer.

        In ``auto`` automation revisions are approved without asking (the page still shows each one)."""
        if self._loop is not None and self._loop.automation == "auto":
            return True
        with self._lock:
            ident = len(self._approvals) + 1
            pending = {"program": program, "diff": diff}
            self._approvals[ident] = pending
        self._events.append({"type": "approval", "id": ident, "diff": diff, "program": program})
        deadline = time.monotonic() + APPROVAL_TIMEOUT_S
        with self._lock:
            while "answer" not in pending and time.monotonic() < deadline:
                self._approval_cond.wait(min(1.0, max(0.0, deadline - time.monotonic())))
            return bool(pending.get("answer", False))

    def answer(self, ident: int, ok: bool) -> None:
        with self._lock:
            pending = self._approvals.get(ident)
            if pending is None:
                raise StudioError(f"no revision waiting for approval has id {ident}")
            pending["answer"] = bool(ok)
            self._approval_cond.notify_all()

    def llm_turn(self, action: str, *, text: str = "", critics: list[str] | None = None,
                 automation: str = "guided", index: int | None = None) -> Iterator[dict[str, Any]]:
        """Start one chat or Fix turn in a thread; return its events (text so far, approvals, revisions,
        done/error) as they come. Raises StudioError at once when no model is configured."""
        loop = self._loop_for(automation)
        # The revision on the page (the user may have gone back in the history) is the one to fix or refine.
        shown = self.revisions[index - 1] if index and 0 < index <= len(self.revisions) else (
            self.revisions[-1] if self.revisions else None)
        if shown is not None and (loop.current is None or loop.current.program != shown.program):
            self.program = shown.program
            self._adopt(shown)
        return self._turn_events(loop, action, text, critics)

    def _turn_events(self, loop, action: str, text: str, critics: list[str] | None) -> Iterator[dict[str, Any]]:
        events: list[dict[str, Any]] = []
        self._events = events
        done = threading.Event()
        outcome: dict[str, Any] = {}
        previous = getattr(self.model, "on_progress", None)

        def progress(p) -> None:
            events.append({"type": "text", "text": p.text})

        def work() -> None:
            try:
                with self._run_lock:
                    if hasattr(self.model, "on_progress"):
                        self.model.on_progress = progress
                    if action == "chat":
                        loop.request(text) if loop.task is None else loop.refine(text)
                    else:
                        loop.fix(critics or None)
            except Exception as exc:  # shown in the page's terminal: an LLM or loop error
                outcome["error"] = f"{type(exc).__name__}: {exc}"
            finally:
                if hasattr(self.model, "on_progress"):
                    self.model.on_progress = previous
                done.set()

        threading.Thread(target=work, name="robocritics-studio-llm", daemon=True).start()
        sent = 0
        while True:
            finished = done.wait(0.05)
            while sent < len(events):
                yield events[sent]
                sent += 1
            if finished:
                break
        yield {"type": "error", "error": outcome["error"]} if "error" in outcome else {"type": "done"}

    def deploy(self, index: int) -> dict[str, Any]:
        """Deploy revision ``index`` through the deploy gate: planned from the arm's joints, all critics."""
        from ...deploy import URArm
        from ...errors import DeployError
        from ...pipeline import check

        if not self.deploy_target:
            raise StudioError("no UR controller is configured (start the studio with --deploy-host)")
        revision = self.revisions[index - 1] if 0 < index <= len(self.revisions) else None
        if revision is None:
            raise StudioError(f"there is no revision {index}")
        if revision.report is None or revision.report.has_errors:
            raise StudioError(f"revision {index} has an Error; the deploy gate refuses it")
        target = dict(self.deploy_target)
        with self._run_lock:
            try:
                with URArm(target.pop("host"), **target) as arm:
                    checked = check(revision.program, self.scene, start_q=arm.actual_q())  # every installed critic
                    if checked.execution is None:
                        return {"ok": False, "message": f"deploy stopped: {checked.report.verdicts[0].message}"}
                    result = arm.deploy(checked.execution, checked.report)
            except DeployError as exc:
                return {"ok": False, "message": f"deploy stopped: {exc}"}
        return {"ok": True, "message": result.summary()}


class _Handler(BaseHTTPRequestHandler):
    studio: Studio
    server_version = "robocritics-studio"
    protocol_version = "HTTP/1.1"  # chunked NDJSON streams for chat and Fix

    def log_message(self, format: str, *args) -> None:  # quiet: the CLI prints the URL, not every request
        pass

    # --- checks ------------------------------------------------------------------------------------

    def _refuse(self, status: int, message: str) -> None:
        body = json.dumps({"error": message}).encode()
        self.send_response(status)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

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
        given = self.headers.get("X-Studio-Token") or (query.get("token") or [""])[0]
        return hmac.compare_digest(given.encode(), token.encode())

    def _checked(self, api: bool) -> dict[str, list[str]] | None:
        parts = urlsplit(self.path)
        query = parse_qs(parts.query)
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
        except ValueError:
            self._refuse(400, "request body is not JSON")
            return None
        if not isinstance(body, dict):
            self._refuse(400, "request body must be a JSON object")
            return None
        return body

    def _json(self, value: Any, status: int = 200) -> None:
        body = json.dumps(value, allow_nan=False).encode()
        self.send_response(status)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    # --- routes ------------------------------------------------------------------------------------

    def do_GET(self) -> None:
        path = urlsplit(self.path).path
        if self._checked(api=path.startswith("/api/")) is None:
            return
        if path == "/":
            from .page import studio_page

            body = studio_page().encode()
            self.send_response(200)
            self.send_header("Content-Type", "text/html; charset=utf-8")
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Content-Security-Policy", "default-src 'self' 'unsafe-inline' blob: data:; "
                             "connect-src 'self'")
            self.end_headers()
            self.wfile.write(body)
        elif path == "/api/state":
            self._json(self.studio.state())
        elif path.startswith("/api/revision/"):
            try:
                index = int(path.rsplit("/", 1)[1])
                revision = self.studio.revisions[index - 1]
                assert index > 0
            except (ValueError, IndexError, AssertionError):
                self._refuse(404, f"no revision {path.rsplit('/', 1)[1]!r}")
                return
            self._json(revision.full())
        else:
            self._refuse(404, f"no page {path!r}")

    def do_POST(self) -> None:
        path = urlsplit(self.path).path
        if self._checked(api=True) is None:
            return
        body = self._body()
        if body is None:
            return
        try:
            if path == "/api/run":
                program = body.get("program")
                if not isinstance(program, str) or len(program) > MAX_PROGRAM_CHARS:
                    self._refuse(400, f"program must be a string of at most {MAX_PROGRAM_CHARS} characters")
                    return
                critics = body.get("critics")
                self._json(self.studio.run(program, critics if isinstance(critics, list) else None).full())
            elif path in ("/api/chat", "/api/fix"):
                text = body.get("text", "")
                if not isinstance(text, str) or len(text) > MAX_CHAT_CHARS:
                    self._refuse(400, f"text must be a string of at most {MAX_CHAT_CHARS} characters")
                    return
                automation = body.get("automation", "guided")
                if automation not in ("manual", "guided", "auto"):
                    self._refuse(400, "automation must be manual, guided or auto")
                    return
                critics = body.get("critics")
                events = self.studio.llm_turn("chat" if path == "/api/chat" else "fix", text=text,
                                              critics=critics if isinstance(critics, list) else None,
                                              automation=automation,
                                              index=body.get("index") if isinstance(body.get("index"), int) else None)
                self._stream(events)
            elif path == "/api/approve":
                self.studio.answer(int(body.get("id", 0)), bool(body.get("ok")))
                self._json({"ok": True})
            elif path == "/api/deploy":
                self._json(self.studio.deploy(int(body.get("index", 0))))
            else:
                self._refuse(404, f"no API {path!r}")
        except StudioError as exc:
            self._refuse(409, str(exc))

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
