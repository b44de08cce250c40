"""The studio's one job at a time: what the server is doing (run, fix, chat, repair, deploy), its progress, its
pending approval, and how it is cancelled.

Every page (any tab, after any reload) reads the same :meth:`Job.snapshot` through ``GET /api/state``, so what
one page started every page shows, and a pending approval survives a reload. Waiting for an approval never
blocks anything but the job itself: a Run while a turn waits for its approval cancels that turn
(:meth:`JobBoard.begin`), and an approval whose deadline passes counts as rejected.
"""

from __future__ import annotations

import itertools
import threading
import time
from typing import Any, Callable

__all__ = ["Approval", "Cancelled", "Job", "JobBoard", "Busy", "KINDS"]

#: The kinds of job, one at a time.
KINDS = ("run", "fix", "chat", "repair", "deploy")


class Cancelled(BaseException):
    """Raised inside a cancelled job's thread (from its approval wait or its model's progress callback).

    A BaseException, so that no ``except Exception`` on the way (a model client's retry, a critic's guard) can
    swallow it: the Loop undoes the turn and re-raises it, as for any exception from ``approve``."""


class Busy(Exception):
    """A job was refused because another one is running (the message says which and why)."""


class Approval:
    """A revision waiting for the page's Approve/Reject, with a deadline (monotonic s) after which it is rejected."""

    _ids = itertools.count(1)

    def __init__(self, program: str, diff: str, title: str, timeout_s: float, clock: Callable[[], float]):
        self.id = next(self._ids)
        self.program = program
        self.diff = diff
        self.title = title
        self.deadline = clock() + timeout_s
        self.answer: bool | None = None
        self.reason = ""

    def snapshot(self, now: float) -> dict[str, Any]:
        return {"id": self.id, "diff": self.diff, "program": self.program, "title": self.title,
                "seconds_left": max(0.0, round(self.deadline - now, 1))}


class Job:
    """One piece of work: ``kind`` (:data:`KINDS`), what it is doing (``status``, ``progress``), its pending
    approval, a ``cancel`` event, and when done its ``outcome`` (ok, message)."""

    _ids = itertools.count(1)

    def __init__(self, kind: str, detail: str, clock: Callable[[], float]):
        assert kind in KINDS, kind
        self.id = next(self._ids)
        self.kind = kind
        self.detail = detail
        self.started = clock()
        self.status = ""
        self.progress: dict[str, Any] = {}
        self.approval: Approval | None = None
        self.cancel = threading.Event()
        self.cancel_reason = ""
        self.done = False
        self.events: list[dict[str, Any]] = []  # a turn's revisions and its end, for the page that started it
        self.reply: tuple[str, str] | None = None  # the model's reply so far and its phase (waiting, receiving)
        self.stop_requested_at: float | None = None  # monotonic s of a Stop (a deploy reports its latency)

    def snapshot(self, now: float) -> dict[str, Any]:
        return {"id": self.id, "kind": self.kind, "detail": self.detail, "status": self.status,
                "elapsed_s": round(now - self.started, 1), "progress": dict(self.progress),
                "approval": None if self.approval is None or self.approval.answer is not None
                else self.approval.snapshot(now),
                "cancelling": self.cancel.is_set(),
                # the model's reply so far, for pages that did not start the turn (its end, if long)
                "reply": self.reply[0][-2000:] if self.reply else ""}


class JobBoard:
    """The one running job (or none), the approvals of the running job, and their deadlines.

    ``approval_timeout_s``: seconds an approval waits before it counts as rejected. ``clock``: monotonic seconds
    (injected by tests)."""

    def __init__(self, approval_timeout_s: float, clock: Callable[[], float] = time.monotonic):
        self.approval_timeout_s = float(approval_timeout_s)
        self.clock = clock
        self._cond = threading.Condition()
        self.job: Job | None = None

    def begin(self, kind: str, detail: str = "") -> Job:
        """Start a job of ``kind``; raise :class:`Busy` when another runs. A Run while a turn waits for its
        approval cancels that turn (its approval counts as rejected) and starts."""
        with self._cond:
            running = self.job
            if running is not None and not running.done:
                waiting = running.approval is not None and running.approval.answer is None
                if kind == "run" and waiting:
                    self._cancel(running, "cancelled by a Run while it waited for your approval")
                else:
                    what = f"a {running.kind}" + (f" of {running.detail}" if running.detail else "")
                    hint = " (Stop it first)" if running.kind == "deploy" else " (wait for it to end)"
                    raise Busy(f"{kind} refused: {what} is running{hint}")
            job = Job(kind, detail, self.clock)
            self.job = job
            return job

    def end(self, job: Job) -> None:
        with self._cond:
            job.done = True
            if self.job is job:
                self.job = None
            self._cond.notify_all()

    def cancel(self, reason: str) -> Job | None:
        """Cancel the running job (a deploy: stop the arm); return it, or None when nothing runs."""
        with self._cond:
            job = self.job
            if job is not None and not job.done:
                self._cancel(job, reason)
                return job
            return None

    def _cancel(self, job: Job, reason: str) -> None:
        job.cancel_reason = job.cancel_reason or reason
        if job.stop_requested_at is None:
            job.stop_requested_at = self.clock()
        job.cancel.set()
        if job.approval is not None and job.approval.answer is None:
            job.approval.answer, job.approval.reason = False, reason
        if self.job is job and job.kind != "deploy":  # a cancelled turn no longer holds the studio
            self.job = None
        self._cond.notify_all()

    def ask(self, job: Job, program: str, diff: str, title: str) -> bool:
        """Post an approval for ``job`` and wait for its answer or its deadline (then: rejected).

        Raises :class:`Cancelled` when the job is cancelled meanwhile."""
        with self._cond:
            if job.cancel.is_set():
                raise Cancelled(job.cancel_reason)
            approval = Approval(program, diff, title, self.approval_timeout_s, self.clock)
            job.approval = approval
            job.status = "waiting for your approval"
            try:
                while approval.answer is None:
                    left = approval.deadline - self.clock()
                    if left <= 0:
                        approval.answer = False
                        approval.reason = f"no answer within {self.approval_timeout_s:g} s: rejected"
                        break
                    self._cond.wait(min(0.5, left))
                if job.cancel.is_set():
                    raise Cancelled(job.cancel_reason)
                return approval.answer
            finally:
                job.status = ""

    def answer(self, ident: int, ok: bool) -> Approval:
        """Answer the pending approval ``ident``; LookupError when no approval of that id waits."""
        with self._cond:
            job = self.job
            approval = None if job is None else job.approval
            if approval is None or approval.id != ident or approval.answer is not None:
                raise LookupError(f"no revision waiting for approval has id {ident}")
            approval.answer = bool(ok)
            approval.reason = "approved" if ok else "rejected by you"
            self._cond.notify_all()
            return approval

    def snapshot(self) -> dict[str, Any] | None:
        with self._cond:
            return None if self.job is None else self.job.snapshot(self.clock())
