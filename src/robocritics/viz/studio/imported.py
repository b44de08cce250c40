"""Motion from other tools in the studio (issue 25): a URScript file or a recording, judged and replayed.

The file is read and run in the worker's limited child (:meth:`~.worker.Evaluator.evaluate_motion`), bounded
as :mod:`robocritics.formats` bounds it. What the studio does not offer for it, and why, is said here once.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .common import MAX_PROGRAM_CHARS, StudioError

__all__ = ["IMPORTED_DEPLOY", "imported_motion", "recording_summary"]

#: Why Deploy is refused for imported motion. The deploy path streams a trajectory the studio planned from a
#: program; a URScript file's or a recording's samples were timed by UR's model or by another tool, and
#: `robocritics deploy` does not take them either, so the studio does not offer a second way to move the arm.
IMPORTED_DEPLOY = ("imported motion (URScript or a recording) is judged and replayed here, not deployed: run a "
                   "script on the controller after its check, or deploy a robot program (robocritics deploy)")
_WHY = {
    "urscript": "Fix and chat write programs in robocritics' skill API, not URScript: edit the script and Run it",
    "recording": "a recording is motion that already happened: it has no program to fix or chat about",
}
#: Findings listed in a recording's summary (the critics panel and the replay's timelines show all of them).
_SUMMARY_FINDINGS = 40


def imported_motion(path, has_goals: bool) -> dict[str, Any]:
    """``{"kind", "path", "name", "why", "text"?}`` of the motion file at ``path``; StudioError for a file that is
    not motion robocritics reads, is missing, or is a URScript file longer than the editor takes; ``text`` is a
    URScript file's contents."""
    from ...formats import motion_kind

    p = Path(path)
    kind = motion_kind(p)
    if kind is None:
        raise StudioError(f"{p}: not a URScript file or a recording (docs/formats.md lists the suffixes)")
    if not p.exists():
        raise StudioError(f"{p}: no such file")
    if has_goals:
        raise StudioError(f"{p} is motion from another tool; it does not say what the gripper held, so goals cannot "
                          "be checked (give no --goal)")
    kind = "urscript" if kind == "urscript" else "recording"
    motion: dict[str, Any] = {"kind": kind, "path": str(p), "name": p.name, "why": _WHY[kind]}
    if kind == "urscript":
        if p.stat().st_size > 4 * MAX_PROGRAM_CHARS:
            raise StudioError(f"{p}: longer than the editor takes ({MAX_PROGRAM_CHARS:,} characters)")
        text = p.read_text(encoding="utf-8", errors="replace")
        if len(text) > MAX_PROGRAM_CHARS:
            raise StudioError(f"{p}: {len(text):,} characters; the editor takes {MAX_PROGRAM_CHARS:,}")
        motion["text"] = text
    return motion


def recording_summary(name: str, execution, report) -> str:
    """What the read-only editor shows for a recording: its source, length, and each finding with its times."""
    lines = [f"# {name} (read-only: a recording is judged and replayed, not edited)"]
    if execution is None:
        lines.append("# it could not be read: see the terminal")
        return "\n".join(lines) + "\n"
    traj = execution.trajectory
    duration = float(traj.time[-1]) if len(traj.time) else 0.0
    lines.append(f"# source: {execution.source}")
    lines.append(f"# {traj.q.shape[1]} joints, {len(traj.time):,} samples, {duration:.2f} s")
    findings = [v for v in (report.verdicts if report is not None else []) if v.flag.value.lower() != "ok"]
    lines.append(f"# findings: {len(findings) or 'none'}")
    for v in findings[:_SUMMARY_FINDINGS]:
        window = v.evidence.time_window_s
        at = f"{window[0]:.2f}-{window[1]:.2f} s" if window else "whole run"
        lines.append(f"#   {at}  {v.flag.value.capitalize()} [{v.critic}]: {v.message}")
    return "\n".join(lines) + "\n"
