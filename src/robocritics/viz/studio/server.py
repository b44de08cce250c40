"""The studio: its state (revisions, chat, the one running job, the last deploy) and the work behind the API.

Security model (docs/studio.md): the studio can move a robot, so

* it binds 127.0.0.1 unless told otherwise, and :class:`Studio` refuses a non-loopback host without a token;
* with a token, every request (page and API) must carry it: ``?token=`` on the first visit (the page then gets
  it as an HttpOnly, SameSite=Strict cookie and drops it from its address), the cookie, or the
  ``X-Studio-Token`` header; compared with :func:`hmac.compare_digest`; otherwise 401;
* even without a token, other web sites open in the same browser are kept out: API calls need
  ``Content-Type: application/json`` and the ``X-Studio`` header (a cross-origin page cannot send either without
  a CORS preflight, which is never answered), the ``Host`` header must name the bound port on a loopback name
  (DNS rebinding), and an ``Origin``, when present, must be the studio's own;
* request bodies are capped at :data:`MAX_BODY_BYTES` and programs at :data:`MAX_PROGRAM_CHARS`; a body that is
  not what a route takes is a 400 with a JSON error (:mod:`.handler`).

Work is one job at a time (:mod:`.jobs`): a Run, a Fix or chat turn, a repair, a Deploy. Simulation runs in the
:class:`~robocritics.viz.studio.worker.Evaluator`'s resource-limited child process; the server is threaded, so
every page keeps polling ``GET /api/state`` (the job, its progress, a pending approval, the chat) while one runs.
"""

from __future__ import annotations

import threading
import time
from typing import Any, Iterator

from ...errors import RoboCriticsError
from .common import (APPROVAL_TIMEOUT_S, CANCELLED_TURN_WAIT_S, CHAT_ENTRY_CHARS, CHAT_LOG_ENTRIES, MAX_BODY_BYTES,
                     MAX_CHAT_CHARS, MAX_PROGRAM_CHARS, StudioBusy, StudioError, is_loopback)
from .jobs import Busy, Cancelled, Job, JobBoard
from .imported import IMPORTED_DEPLOY, imported_motion, recording_summary
from .revisions import FULL_REVISIONS, MAX_REVISIONS, Revision

__all__ = ["Studio", "StudioError", "StudioBusy", "is_loopback", "MAX_BODY_BYTES", "MAX_PROGRAM_CHARS",
           "APPROVAL_TIMEOUT_S", "MAX_CHAT_CHARS"]

def _subset(report, selected: set[str]):
    """``report`` with only the verdicts of the ``selected`` critics (their score)."""
    return report.model_copy(update={"verdicts": [v for v in report.verdicts if v.critic in selected]})


class Studio:
    """The studio web app for one scene.

    ``Studio(scene, program=None, *, host="127.0.0.1", port=0, token=None, model=None, deploy=None,
    critics=None, goals=None, timeout_s=60, run_program=False, approval_timeout_s=APPROVAL_TIMEOUT_S)``:
    ``scene`` a :class:`~robocritics.scene.Scene` (or its name/path); ``program`` the editor's first text
    (``run_program``: Run it as soon as the studio starts); ``model`` a
    :class:`~robocritics.llm.protocol.ChatModel` for chat and Fix (None: chat disabled, the page says why; Fix
    applies the critics' own repairs only); ``deploy`` ``{"host", "rtde_port", "dashboard_port",
    "secondary_port"}`` of a UR controller (None: Deploy disabled); ``critics`` the critics run (default: all
    installed); ``timeout_s`` the wall-clock bound of one simulation, s; ``approval_timeout_s`` how long a
    revision waits for Approve/Reject before it counts as rejected, s.

    ``motion``: the path of motion from another tool (:mod:`robocritics.formats`) to judge instead of a program:
    a URScript file (its text is the editor's, Run checks the edited script; the critics name its lines) or a
    recording (ur_rtde or generic CSV, JointTrajectory JSON, MoveIt YAML, rosbag2: the editor shows a read-only
    summary whose findings name times). Both are read and run in the worker's limited child. Fix and chat are off
    for them (the repairs and the model write the skill API, not URScript, and a recording has no program), and
    so is Deploy (:data:`IMPORTED_DEPLOY`). ``motion_options``: the options of
    :meth:`~.worker.Evaluator.evaluate_motion` (a script's installation: ``tcp``, ``payload_kg``, ``start_q``,
    ``gripper_io``, ``passes``; a rosbag's ``topic``).
    """

    def __init__(self, scene, program: str | None = None, *, host: str = "127.0.0.1", port: int = 0,
                 token: str | None = None, model=None, deploy: dict[str, Any] | None = None, critics=None,
                 goals=None, timeout_s: float = 60.0, run_program: bool = False, robot=None,
                 approval_timeout_s: float = APPROVAL_TIMEOUT_S,
                 no_model_reason: str = "no LLM endpoint is configured (start the studio with --base-url and --model)",
                 motion=None, motion_options: dict[str, Any] | None = None):
        from ...goals import parse_goals
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
        self.goals = parse_goals(goals, self.scene)  # a bad goal (GoalError) fails here, before serving
        self.motion = imported_motion(motion, bool(self.goals)) if motion is not None else None
        self.motion_options = dict(motion_options or {})
        if self.motion is not None and self.motion["kind"] == "urscript" and not self.program:
            self.program = self.motion.pop("text")
        if self.motion is not None:
            self.motion.pop("text", None)
        self.timeout_s = float(timeout_s)
        self.run_program = bool(run_program)
        self.robot = robot  # None: the UR3e (Robot.from_urdf for a vendor arm; docs/robots.md)
        self.revisions: list[Revision] = []
        self.chat_log: list[dict[str, str]] = []
        self.chat_version = 0  # entries ever said (the log keeps the last CHAT_LOG_ENTRIES)
        self.jobs = JobBoard(approval_timeout_s)
        self.last_deploy: dict[str, Any] | None = None
        self._lock = threading.Lock()
        self._evaluator = None
        self._evaluator_lock = threading.Lock()
        self._loop = None
        self._turn_thread: threading.Thread | None = None
        self._turn_job: Job | None = None
        self._attempt_revision: dict[int, int] = {}  # Loop attempt index -> revision number
        self._selected: list[str] | None = None
        from ...critic.plugins import get_critics

        self._installed: list[str] = list(get_critics())  # the critics ticked on the page of the running turn
        self._server = None
        self._thread: threading.Thread | None = None
        self._requested_port = int(port)

    # --- lifecycle -------------------------------------------------------------------------------

    def start(self) -> "Studio":
        from .handler import serve

        self._server = serve(self, self.host, self._requested_port)
        self._thread = threading.Thread(target=self._server.serve_forever, name="robocritics-studio", daemon=True)
        self._thread.start()
        # Warm the worker (imports, robot model) now, so the first Run does not pay for it; Run --program.
        first = (self._initial_run if self.run_program and (self.program.strip() or self.motion)
                 else (lambda: self.evaluator))
        threading.Thread(target=first, name="robocritics-studio-warm", daemon=True).start()
        return self

    def _initial_run(self) -> None:
        try:
            self.run(self.program)
        except (StudioError, RoboCriticsError):
            pass  # e.g. closed while starting: the page shows the editor's text

    @property
    def port(self) -> int:
        assert self._server is not None, "start() the studio first"
        return self._server.server_address[1]

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        query = f"?token={self.token}" if self.token else ""
        return f"http://{host}:{self.port}/{query}"

    def urls(self) -> list[str]:
        """The URLs to open: :attr:`url`, or for a wildcard host (0.0.0.0, ::) one per address of this machine."""
        from .addresses import local_addresses

        if self.host not in ("0.0.0.0", "::", ""):
            return [self.url]
        query = f"?token={self.token}" if self.token else ""
        return [f"http://{f'[{a}]' if ':' in a else a}:{self.port}/{query}"
                for a in local_addresses(ipv6=self.host == "::")]

    def stop(self) -> None:
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
            self._server = None
        job = self.jobs.cancel("the studio is stopping")
        deadline = time.monotonic() + 5.0
        while job is not None and not job.done and time.monotonic() < deadline:  # a deploy stops the arm first
            time.sleep(0.05)
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

    # --- state -------------------------------------------------------------------------------------

    @property
    def evaluator(self):
        """The worker process (started once; :meth:`start` warms it up in the background)."""
        with self._evaluator_lock:
            if self._evaluator is None:
                from .worker import Evaluator

                self._evaluator = Evaluator(self.scene, self.robot, critics=self.critics, goals=self.goals,
                                            timeout_s=self.timeout_s)
            return self._evaluator

    def installed_critics(self) -> list[str]:
        """The installed critics' names (read once, before serving: every page polls the state, and the plugin
        registry is not meant to be read from many request threads at once)."""
        return list(self._installed)

    def state(self, chat_seen: int | None = None) -> dict[str, Any]:
        """Everything every page shows. ``chat_seen``: the ``chat_version`` the page has; its ``chat_log`` is
        None when nothing was said since (every page polls this)."""
        with self._lock:
            revisions = [r.summary() for r in self.revisions]
            chat_log = None if chat_seen == self.chat_version else list(self.chat_log)
        return {
            "scene": self.scene.name,
            "program": self.program,
            "critics": self.installed_critics(),
            "selected": self.critics or self.installed_critics(),
            "goals": [str(g) for g in self.goals],
            "chat": self.motion["why"] if self.motion else None if self.model is not None else self.no_model_reason,
            "deploy": IMPORTED_DEPLOY if self.motion else None if self.deploy_target else
            "no UR controller is configured (--deploy-host)",
            "motion": None if self.motion is None else {k: self.motion[k] for k in ("kind", "name", "why")},
            "revisions": revisions,
            "max_program_chars": MAX_PROGRAM_CHARS,
            "full_revisions": FULL_REVISIONS,
            "job": self.jobs.snapshot(),
            "chat_log": chat_log,
            "chat_version": self.chat_version,
            "last_deploy": self.last_deploy,
        }

    @property
    def next_index(self) -> int:
        """The number the next revision gets (the first ones are forgotten past MAX_REVISIONS; numbers go on)."""
        return self.revisions[-1].index + 1 if self.revisions else 1

    def revision(self, index: int) -> Revision:
        with self._lock:
            first = self.revisions[0].index if self.revisions else 1
            if not first <= index < self.next_index:
                forgotten = f" (only the last {MAX_REVISIONS} are kept)" if 0 < index < first else ""
                raise LookupError(f"there is no revision {index}{forgotten}")
            return self.revisions[index - first]

    def _say(self, role: str, text: str) -> None:
        """Add to the chat every page shows (``role``: user, assistant or note)."""
        text = text if len(text) <= CHAT_ENTRY_CHARS else text[:CHAT_ENTRY_CHARS] + " …(cut)"
        with self._lock:
            self.chat_log.append({"role": role, "text": text})
            self.chat_version += 1
            del self.chat_log[:-CHAT_LOG_ENTRIES]

    def _add(self, kind: str, program: str, execution, full_report, error: str | None, *, diff: str = "",
             duration_s: float = 0.0, selected: list[str] | None = None) -> Revision:
        """Record a revision (the next number); compact the ones older than the last FULL_REVISIONS."""
        shown = full_report
        if full_report is not None and selected is not None:
            shown = _subset(full_report, set(selected) | {"runtime", "task_outcome"})
        with self._lock:
            revision = Revision(self.next_index, kind, program, execution=execution, report=shown,
                                error=error, diff=diff, duration_s=duration_s, deploy_report=full_report)
            self.revisions.append(revision)
            del self.revisions[:-MAX_REVISIONS]
            for old in self.revisions[:-FULL_REVISIONS]:
                if not old.compact:
                    old.compact_away()
            self.program = program
        self._forget_old_attempts()
        return revision

    def _forget_old_attempts(self) -> None:
        """The Loop keeps every attempt; drop the runs of all but the current and the last few (memory bound)."""
        loop = self._loop
        if loop is None:
            return
        for attempt in loop.attempts[:-FULL_REVISIONS]:
            if attempt is not loop.current:
                attempt.execution = None
        for attempt in loop.attempts[:-MAX_REVISIONS]:  # as old as the revisions forgotten: their reports too
            if attempt is not loop.current:
                attempt.report = None
                self._attempt_revision.pop(attempt.index, None)

    # --- Run -------------------------------------------------------------------------------------------

    def _begin(self, kind: str, detail: str = "") -> Job:
        try:
            return self.jobs.begin(kind, detail)
        except Busy as exc:
            raise StudioBusy(str(exc)) from None

    def check(self, program: str) -> dict[str, Any]:
        """Simulate and critique ``program`` with every critic in the worker: the keyword arguments of
        :meth:`_add` (a program that does not run: the ``runtime`` critic's Error, its line when known)."""
        from ...critic import runtime_report
        from ...errors import ProgramError
        from .worker import EvaluatorError, _rebuild

        if self.motion is None:
            evaluation = self.evaluator.evaluate(program)
        elif self.motion["kind"] == "urscript":
            evaluation = self.evaluator.evaluate_motion("urscript", program, self.motion["name"], **self.motion_options)
        else:
            evaluation = self.evaluator.evaluate_motion("recording", self.motion["path"], **self.motion_options)
        if evaluation.error is None:
            return dict(execution=evaluation.execution, full_report=evaluation.report, error=None,
                        duration_s=evaluation.duration_s)
        e = evaluation.error
        where = f" (line {e['line']})" if e.get("line") else ""
        error = _rebuild(e)
        if isinstance(error, EvaluatorError):
            error = ProgramError(f"the program could not be checked: {e['message']}", int(e.get("line") or 0))
        elif not hasattr(error, "line"):  # e.g. the interpreter's budget: a program error at its line
            error = ProgramError(e["message"], int(e.get("line") or 0))
        return dict(execution=None, full_report=runtime_report(error), error=f"{e['type']}{where}: {e['message']}",
                    duration_s=evaluation.duration_s)

    def run(self, program: str, critics: list[str] | None = None) -> Revision:
        """Simulate and critique ``program`` (every critic; ``critics`` are the ones scored and shown ticked);
        record and return the revision. A Run while a turn waits for its approval cancels that turn."""
        job = self._begin("run")
        job.status = "simulating" if self.motion is None else f"reading {self.motion['name']}"
        try:
            result = self.check(program)
            if self.motion is not None and self.motion["kind"] == "recording":  # the editor shows what was read
                program = recording_summary(self.motion["name"], result["execution"], result["full_report"])
            revision = self._add("run", program, selected=critics, **result)
        finally:
            self.jobs.end(job)
        self._adopt(revision)
        return revision

    # --- Fix and chat: the Loop with the model, or the critics' repairs alone --------------------------

    def _loop_for(self, automation: str):
        from ...llm.loop import Loop

        if self._loop is None:
            self._loop = Loop(self.model, self.scene, robot=self.robot, critics=self.critics, goals=self.goals,
                              approve=self._approve,
                              simulate=self._loop_simulate, repairs=self._loop_repair,
                              on_attempt=self._on_attempt)
        self._loop.automation = automation
        return self._loop

    def _loop_simulate(self, program: str):
        if self._turn_job is not None:
            self._turn_job.status = "simulating the revision"
        return self.evaluator.loop_simulate(program)

    def _loop_repair(self, program: str):
        if self._turn_job is not None:
            self._turn_job.status = "applying the critics' repairs"
        return self.evaluator.loop_repair(program)

    def _adopt(self, revision: Revision) -> None:
        """Make ``revision`` the loop's current program, so Fix sends its feedback."""
        if self._loop is None or revision.deploy_report is None:
            return
        from ...llm.loop import Attempt

        loop = self._loop
        if loop.task is None:
            loop.task = "improve this robot program"
        attempt = Attempt(index=len(loop.attempts) + 1, kind="user", request=loop.task, prompt="", reply="",
                          program=revision.program, execution=revision.execution, report=revision.deploy_report,
                          error=None, score=revision.deploy_report.score)
        if revision.execution is None:  # a program that did not run: the model is owed its runtime feedback
            attempt.error = revision.error
        loop.attempts.append(attempt)
        loop.current = attempt
        self._attempt_revision[attempt.index] = revision.index

    def _title(self, diff: str) -> tuple[str, str]:
        """The diff with the studio's revision numbers in its header (the Loop numbers its attempts)."""
        lines = diff.split("\n")
        nxt = self.next_index
        repairs = "(critic repairs)" in "".join(lines[:2])
        current = self._loop.current if self._loop is not None else None
        base = self._attempt_revision.get(current.index) if current is not None else None
        old = f"#{base}" if base else "current"
        new = f"#{nxt}" + (" (critic repairs)" if repairs else "")
        if len(lines) >= 2 and lines[0].startswith("--- ") and lines[1].startswith("+++ "):
            lines[0], lines[1] = f"--- {old}", f"+++ {new}"
        return "\n".join(lines), f"{new} from {old}"

    def _approve(self, program: str, diff: str) -> bool:
        """The Loop's approval: post the diff (every page shows it) and wait for the answer or the deadline."""
        job = self._turn_job
        assert job is not None
        if job.cancel.is_set():
            raise Cancelled(job.cancel_reason)
        diff, title = self._title(diff)
        if self._loop is not None and self._loop.automation == "auto":
            return True
        return self.jobs.ask(job, program, diff, title)

    def _on_attempt(self, attempt) -> None:
        job = self._turn_job
        current = self._attempt_revision.get(self._loop.current.index) if self._loop.current else None
        if attempt.source != "repair" and attempt.reply:
            self._say("assistant", attempt.reply)
        if attempt.approved is False:
            reason = job.approval.reason if job is not None and job.approval is not None else "rejected"
            what = "critic repairs" if attempt.source == "repair" else "model's revision"
            self._say("note", f"✗ The {what} was not applied ({reason}); #{current} stays current.")
            return
        if attempt.program is None:
            self._say("note", "The reply had no program: " + (attempt.error or "").split("\n")[0])
            return
        if not attempt.changed:
            said = "says the program is complete and " if attempt.complete else ""
            self._say("note", f"The model {said}sent back the program of #{current} unchanged: no new revision.")
            return
        revision = self._add(attempt.kind, attempt.program, attempt.execution, attempt.report, attempt.error,
                             diff=self._title(attempt.diff)[0] if attempt.diff else "", selected=self._selected)
        self._attempt_revision[attempt.index] = revision.index
        if attempt.source == "repair":
            done = "; ".join(f"line {c.line}: {c.what}" for c in attempt.changes)
            self._say("note", f"#{revision.index}: {len(attempt.changes)} critic repair(s) — {done}")
        if job is not None:
            job.events.append({"type": "revision", "revision": revision.full()})

    def llm_turn(self, action: str, *, text: str = "", critics: list[str] | None = None,
                 automation: str = "guided", index: int | None = None,
                 selected: list[str] | None = None) -> Iterator[dict[str, Any]]:
        """Start one chat or Fix turn in a thread; return its events (text so far, revisions, done/error) as they
        come. Without a model, Fix applies the critics' own repairs (chat raises StudioError at once)."""
        if self.motion is not None:
            raise StudioError(self.motion["why"])
        if self.model is None and action == "chat":
            raise StudioError(self.no_model_reason)
        kind = "chat" if action == "chat" else ("fix" if self.model is not None else "repair")
        shown = self._shown(index)
        if action != "chat" and shown is None:
            raise StudioError("nothing to fix yet: Run the program first")
        if action != "chat" and shown.compact:
            raise StudioError(f"revision {shown.index}'s run is no longer kept (only the last {FULL_REVISIONS} "
                              "are): Run it again to fix it")
        previous = self._turn_thread
        if previous is not None and previous.is_alive():  # a cancelled turn still ending: let it end
            previous.join(CANCELLED_TURN_WAIT_S)
            if previous.is_alive():
                raise StudioBusy(f"{kind} refused: the cancelled turn has not ended yet; try again")
        job = self._begin(kind, "" if action == "chat" else ", ".join(critics or []) or "all")
        job.events = []
        self._selected = selected
        self._say("user", text if action == "chat" else "Fix " + (", ".join(critics) if critics else "all"))
        if kind == "repair":
            work = lambda: self._repair_turn(job, shown, automation)  # noqa: E731
        else:
            loop = self._loop_for(automation)
            if shown is not None and (loop.current is None or
                                      self._attempt_revision.get(loop.current.index) != shown.index):
                self._adopt(shown)
            work = lambda: self._model_turn(job, loop, action, text, critics)  # noqa: E731
        thread = threading.Thread(target=self._turn, args=(job, work), name="robocritics-studio-turn", daemon=True)
        self._turn_thread, self._turn_job = thread, job
        thread.start()
        return self._events(job, thread)

    def _shown(self, index: int | None) -> Revision | None:
        """Revision ``index`` (StudioError if there is none: a Fix of #7 must not fix another), else the latest."""
        if index is None:
            with self._lock:
                return self.revisions[-1] if self.revisions else None
        try:
            return self.revision(index)
        except LookupError as exc:
            raise StudioError(str(exc)) from None

    def _turn(self, job: Job, work) -> None:
        try:
            work()
        except Cancelled as exc:
            self._say("note", f"✗ The {job.kind} turn was cancelled: {exc}")
            job.events.append({"type": "error", "error": f"{job.kind} cancelled: {exc}"})
        except Exception as exc:  # noqa: BLE001 - an LLM or loop error: shown in the chat and the terminal
            self._say("note", f"{job.kind} failed: {type(exc).__name__}: {exc}")
            job.events.append({"type": "error", "error": f"{type(exc).__name__}: {exc}"})
        else:
            job.events.append({"type": "done"})
        finally:
            self.jobs.end(job)

    def _model_turn(self, job: Job, loop, action: str, text: str, critics: list[str] | None) -> None:
        previous = getattr(self.model, "on_progress", None)

        def progress(p) -> None:
            if job.cancel.is_set():
                raise Cancelled(job.cancel_reason)
            job.status = "receiving the model's reply" if p.phase == "receiving" else "waiting for the model"
            job.reply = (p.text, p.phase)  # the latest only: a long reply streamed is not kept once per token

        job.status = "waiting for the model" if action == "chat" else "checking what to fix"
        if hasattr(self.model, "on_progress"):
            self.model.on_progress = progress
        try:
            if action == "chat":
                loop.request(text) if loop.task is None else loop.refine(text)
            else:
                loop.fix(self._fixable(loop, critics or self._selected))
        finally:
            if hasattr(self.model, "on_progress"):
                self.model.on_progress = previous

    @staticmethod
    def _fixable(loop, names: list[str] | None) -> list[str] | None:
        """``names`` that gave a verdict on the current program (a critic that did not run, e.g. task_outcome
        without goals, has nothing to fix); None for all."""
        report = loop.current.report if loop.current is not None else None
        if report is not None and report.critics == ["runtime"]:
            return ["runtime"]  # a program that did not run: its runtime Error is what there is to fix
        if not names or report is None:
            return None
        return [n for n in names if n in report.critics] or None

    def _repair_turn(self, job: Job, shown: Revision, automation: str) -> None:
        """Fix without a model: the critics' own repairs in the worker, approved like any revision."""
        from ...llm.loop import unified_diff

        job.status = "applying the critics' repairs"
        result = self.evaluator.loop_repair(shown.program)
        if job.cancel.is_set():
            raise Cancelled(job.cancel_reason)
        program = result.program if result.program.endswith("\n") else result.program + "\n"
        if not result.changes or program.strip() == shown.program.strip():
            self._say("note", f"The critics' repairs have nothing to change in #{shown.index} (they fix Errors "
                              "they can place in the program); for the rest, connect an LLM (--base-url, --model) or "
                              "edit the program.")
            return
        new = f"#{self.next_index} (critic repairs)"
        diff = unified_diff(shown.program, program, f"#{shown.index}", new)
        if automation != "auto" and not self.jobs.ask(job, program, diff, f"{new} from #{shown.index}"):
            reason = job.approval.reason if job.approval is not None else "rejected"
            self._say("note", f"✗ The critic repairs were not applied ({reason}); #{shown.index} stays current.")
            return
        job.status = "simulating the revision"
        revision = self._add("repair", program, diff=diff, selected=self._selected, **self.check(program))
        done = "; ".join(f"line {c.line}: {c.what}" for c in result.changes)
        self._say("note", f"#{revision.index}: {len(result.changes)} critic repair(s) — {done}")
        job.events.append({"type": "revision", "revision": revision.full()})

    @staticmethod
    def _events(job: Job, thread: threading.Thread) -> Iterator[dict[str, Any]]:
        sent, reply = 0, None
        while True:
            thread.join(0.05)
            finished = not thread.is_alive()
            if job.reply is not reply:
                reply = job.reply
                yield {"type": "text", "text": reply[0], "phase": reply[1]}
            while sent < len(job.events):
                yield job.events[sent]
                sent += 1
            if finished:
                return

    def answer(self, ident: int, ok: bool) -> None:
        try:
            self.jobs.answer(ident, ok)
        except LookupError as exc:
            raise StudioError(str(exc)) from None

    def cancel(self) -> dict[str, Any]:
        """Stop the running job: a deploy stops the arm (the same stop path as a fault), a turn is cancelled."""
        job = self.jobs.cancel("stopped on request (Stop)")
        if job is None:
            return {"ok": False, "message": "nothing is running"}
        return {"ok": True, "message": f"stopping the {job.kind}"}

    # --- Deploy ----------------------------------------------------------------------------------------

    def deploy(self, index: int, program: str | None = None) -> dict[str, Any]:
        """Start deploying revision ``index``'s trajectory — exactly the motion shown — through the deploy gate.

        Refused (StudioError) when no controller is configured, the editor's ``program`` differs from the
        revision's, the revision's run is no longer kept, any critic (selected or not) gives an Error, or another
        job runs. Progress and the result are in :meth:`state` (``job``, ``last_deploy``)."""
        if self.motion is not None:
            raise StudioError(IMPORTED_DEPLOY)
        if not self.deploy_target:
            raise StudioError("no UR controller is configured (start the studio with --deploy-host)")
        try:
            revision = self.revision(index)
        except LookupError as exc:
            raise StudioError(str(exc)) from None
        if program is not None and program != revision.program:
            raise StudioError(f"the editor differs from revision {index}: Run it first (Deploy sends exactly the "
                              "motion that was checked and shown)")
        if revision.execution is None or revision.deploy_report is None:
            raise StudioError(f"revision {index} has no motion to deploy" + (
                f" any more (only the last {FULL_REVISIONS} runs are kept): Run it again" if revision.compact else ""))
        if revision.blockers:
            raise StudioError(f"revision {index} has an Error from {', '.join(revision.blockers)}: the deploy gate "
                              "refuses it (every critic counts, ticked or not)")
        job = self._begin("deploy", f"revision {index}")
        job.status = "connecting to the controller"
        self.last_deploy = None
        threading.Thread(target=self._deploy_job, args=(job, revision), name="robocritics-studio-deploy",
                         daemon=True).start()
        return {"ok": True, "job": job.id, "message": f"deploying revision {index}"}

    def _deploy_job(self, job: Job, revision: Revision) -> None:
        from ...deploy import DeployFault, URArm
        from ...errors import DeployError

        target = dict(self.deploy_target or {})

        def progress(p) -> None:
            job.status = p.phase
            job.progress = {"setpoints_sent": p.setpoints_sent, "setpoints_total": p.setpoints_total,
                            "time_s": round(p.time_s, 3), "duration_s": round(p.duration_s, 3),
                            "tracking_error_rad": p.tracking_error_rad,
                            "max_tracking_error_rad": p.max_tracking_error_rad}

        outcome: dict[str, Any] = {"revision": revision.index, "job": job.id,
                                   "trajectory_hash": revision.trajectory_hash}
        try:
            with URArm(target.pop("host"), **target) as arm:
                job.status = "checking the arm (deploy gate)"
                result = arm.deploy(revision.execution, revision.deploy_report, stop=job.cancel, progress=progress)
            outcome.update(ok=True, message=result.summary(), deployed_hash=result.trajectory_hash)
        except DeployFault as exc:
            outcome.update(ok=False, stopped=exc.stopped, cause=exc.cause, message=str(exc))
            if exc.cause == "stop_requested" and job.stop_requested_at is not None:
                outcome["stop_latency_s"] = round(self.jobs.clock() - job.stop_requested_at, 3)
        except DeployError as exc:
            outcome.update(ok=False, message=f"deploy refused: {exc}")
        except Exception as exc:  # noqa: BLE001 - never leave the job running; the page shows what happened
            outcome.update(ok=False, message=f"deploy failed: {type(exc).__name__}: {exc}")
        finally:
            self.last_deploy = outcome
            self.jobs.end(job)
