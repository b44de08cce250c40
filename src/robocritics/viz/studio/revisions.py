"""The studio's revisions: every user Run, every repair and every model attempt, numbered #1, #2, … in order.

The most recent :data:`FULL_REVISIONS` keep their whole run (the Execution for the replay and for Deploy, the
Report); older ones are compacted to what the history shows (program, score, verdict texts, feedback), so a
long session does not keep every run's trajectory in memory (issue 22: 1.8 GB after 20 Runs of a 5-min program).
"""

from __future__ import annotations

from typing import Any

__all__ = ["FULL_REVISIONS", "MAX_REVISIONS", "Revision", "verdict_rows"]

#: Revisions kept with their whole run (trajectory, report); older ones keep only what the history shows.
FULL_REVISIONS = 3
#: Revisions kept at all (the history lists them; numbers go on): a compact one still holds its program (up to
#: 200,000 characters) and verdict texts, ~0.2 MB, so a studio Run 10,000 times grew by 2 GB (issue 22, round 3).
MAX_REVISIONS = 200


def verdict_rows(report) -> list[dict[str, Any]]:
    """The verdicts as the page lists them (critic, flag, message, hint, program lines)."""
    if report is None:
        return []
    return [{"critic": v.critic, "flag": v.flag.value.lower(), "message": v.message, "hint": v.hint,
             "lines": list(v.evidence.lines),
             "window": None if v.evidence.time_window_s is None else [round(t, 3) for t in v.evidence.time_window_s]}
            for v in report.verdicts]


class Revision:
    """One checked program. ``report`` is what the selected critics said (the score, the rows); ``blockers``
    names every critic — selected or not — whose Error keeps Deploy off; ``deploy_report`` is the report of
    every critic on exactly ``execution``'s trajectory (what the deploy gate checks)."""

    def __init__(self, index: int, kind: str, program: str, execution=None, report=None, error: str | None = None,
                 diff: str = "", duration_s: float = 0.0, deploy_report=None, note: str = ""):
        self.index = index
        self.kind = kind
        self.program = program
        self.execution = execution
        self.report = report
        self.deploy_report = deploy_report
        self.error = error
        self.diff = diff
        self.duration_s = duration_s
        self.note = note
        self.score = None if report is None else report.score
        self.has_errors = report is None or report.has_errors
        self.blockers = sorted({v.critic for v in (deploy_report or report).errors}) if (deploy_report or report) \
            else []
        self.trajectory_hash = "" if execution is None else execution.trajectory.content_hash()
        self.compact = False
        self._rows = verdict_rows(report)
        self._feedback = error if report is None else report.feedback()

    def compact_away(self) -> None:
        """Drop the run (trajectory, reports): keep the program and what the history shows."""
        self.execution = self.report = self.deploy_report = None
        self.compact = True

    def summary(self) -> dict[str, Any]:
        return {"index": self.index, "kind": self.kind, "score": self.score, "has_errors": self.has_errors,
                "error": self.error, "compact": self.compact}

    def full(self) -> dict[str, Any]:
        from .. import replay_data

        replay = None
        if self.execution is not None and self.report is not None:
            replay = replay_data(self.execution, self.report)
        return {
            **self.summary(),
            "program": self.program,
            "diff": self.diff,
            "note": self.note,
            "verdicts": self._rows,
            "feedback": self._feedback or "",
            "replay": replay,
            "duration_s": self.duration_s,
            "blockers": self.blockers,
            "trajectory_hash": self.trajectory_hash,
            "deployable": self.execution is not None and not self.blockers and self.report is not None,
        }
