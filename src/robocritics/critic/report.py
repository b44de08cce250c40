"""The verdicts of one critique run: score, feedback text, terminal text, JSON, notebook HTML.

``Report.score`` is the paper's 0-10 program quality index over the five built-in
motion critics (:data:`~robocritics.critic.plugins.BUILTIN_CRITICS`): each scores 2 (OK),
1 (Warning) or 0 (Error) and the score is their sum; when only some of the five
ran, the sum is scaled to 0-10 (``10 * sum / (2 n)``). Every other critic that ran
(a plugin's, or one passed to ``critique()``) is reported beside the score, not in
it, and counts toward pass/fail (:attr:`Report.has_errors`, :attr:`Report.passed`).
A report with none of the five scores its own critics the same way.

``trajectory_hash`` is the :meth:`~robocritics.trajectory.Trajectory.content_hash`
of the motion judged, so a report can be bound to the exact motion that will be deployed.
"""

from __future__ import annotations

import math
import textwrap
from typing import Any, Iterable

from pydantic import BaseModel, ConfigDict, Field, computed_field

from .._suggest import did_you_mean
from ..errors import CriticError
from .plugins import BUILTIN_CRITICS
from .verdict import Flag, Signal, Verdict, fmt_value, format_lines

__all__ = ["Report", "BUILTIN_CRITICS", "ALL_PASSED", "format_score"]

ALL_PASSED = "All selected critics passed."

_FLAG_COLOURS = {"OK": "#1a7f37", "WARNING": "#b35900", "ERROR": "#c62828"}


def format_score(score: float | None) -> str:
    """A 0-10 score as people read it: ``"7/10"``, ``"8.3/10"``; ``"-"`` for None (not scored)."""
    if score is None:
        return "-"
    return f"{int(score)}/10" if float(score).is_integer() else f"{score:.1f}/10"


class Report(BaseModel):
    """Verdicts of one run of :func:`robocritics.critic.critique`, in the order the critics ran."""

    model_config = ConfigDict(frozen=True, extra="ignore")

    verdicts: list[Verdict]
    trajectory_hash: str = Field(description="Trajectory.content_hash() of the motion judged")
    samples: int = 0
    duration_s: float = 0.0
    params: dict[str, dict[str, Any]] = Field(default_factory=dict, description="the parameters each critic ran with")
    source: str | None = Field(None, description="where the motion came from when not a simulated program (URScript, a recording)")

    # --- the numbers ---------------------------------------------------------------

    @computed_field  # type: ignore[prop-decorator]
    @property
    def score(self) -> float:
        """Program quality index, 0-10, over :attr:`scored_verdicts`: the sum of their 2/1/0 points,
        scaled to 0-10 when fewer than five are scored."""
        scored = self.scored_verdicts
        if not scored:
            return 10.0
        total = sum(v.flag.score for v in scored)
        return round(10.0 * total / (2 * len(scored)), 2)

    @property
    def score_text(self) -> str:
        """:attr:`score` formatted, e.g. ``"7/10"`` (:func:`format_score`)."""
        return format_score(self.score)

    @property
    def scored_verdicts(self) -> list[Verdict]:
        """The verdicts the score is made of: those of the five built-in motion critics that ran
        (every verdict when none of the five ran)."""
        motion = [v for v in self.verdicts if v.critic in BUILTIN_CRITICS]
        return motion or list(self.verdicts)

    @property
    def other_verdicts(self) -> list[Verdict]:
        """Verdicts of the critics that ran beside the score (plugins, ad-hoc critics); they count toward
        :attr:`has_errors` and :attr:`passed` but not toward :attr:`score`."""
        others = [v for v in self.verdicts if v.critic not in BUILTIN_CRITICS]
        return others if len(others) < len(self.verdicts) else []

    @property
    def passed(self) -> bool:
        """Whether every critic that ran, scored or not, gave OK."""
        return all(v.flag is Flag.OK for v in self.verdicts)

    @property
    def critics(self) -> list[str]:
        return [v.critic for v in self.verdicts]

    @property
    def has_errors(self) -> bool:
        """Whether any critic that ran, scored or not, gave an Error."""
        return any(v.flag is Flag.ERROR for v in self.verdicts)

    @property
    def errors(self) -> list[Verdict]:
        return [v for v in self.verdicts if v.flag is Flag.ERROR]

    @property
    def warnings(self) -> list[Verdict]:
        return [v for v in self.verdicts if v.flag is Flag.WARNING]

    @property
    def flag(self) -> Flag:
        """The worst flag of all verdicts."""
        return Flag.worst([v.flag for v in self.verdicts])

    def verdict(self, name: str) -> Verdict:
        for v in self.verdicts:
            if v.critic == name:
                return v
        raise CriticError(self._not_here(name))

    def _not_here(self, name: str) -> str:
        ran = ", ".join(self.critics) or "none"
        return f"no verdict of critic {name!r} in this report{did_you_mean(name, self.critics)} (critics that ran: {ran})"

    def flag_of(self, name: str) -> Flag:
        """The flag the critic ``name`` gave (CriticError if it did not run)."""
        return self.verdict(name).flag

    # --- text for an LLM -----------------------------------------------------------

    def feedback(self, critics: Iterable[str] | None = None) -> str:
        """The structured message sent to an LLM, one paper-style line per non-OK verdict.

        ``"Warning: Joint speed is higher than the recommended value of 1 m/s (...).
        To minimize joint speed, you can consider reducing the speed of the robot
        during [move_to] actions on lines 4-6. This potentially increases the cycle
        time of the program."`` Errors come first. ``critics`` restricts the lines to
        those critics; when none of them flagged anything the text is
        ``"All selected critics passed."``.
        """
        selected = self.verdicts
        if critics is not None:
            names = [critics] if isinstance(critics, str) else list(critics)
            for name in names:
                if name not in self.critics:
                    raise CriticError(self._not_here(name))
            selected = [v for v in self.verdicts if v.critic in names]
        flagged = [v for v in selected if v.flag is not Flag.OK]
        if not flagged:
            return ALL_PASSED
        flagged.sort(key=lambda v: v.flag.score)  # stable: errors, then warnings, each in run order
        return "\n".join(v.feedback() for v in flagged)

    # --- text for a terminal -------------------------------------------------------

    def summary(self) -> str:
        """One line: the score, the errors and warnings of every critic, the critics beside the score, the motion."""
        n_err, n_warn = len(self.errors), len(self.warnings)
        parts = []
        if n_err:
            parts.append(f"{n_err} error{'s' if n_err != 1 else ''}")
        if n_warn:
            parts.append(f"{n_warn} warning{'s' if n_warn != 1 else ''}")
        status = ", ".join(parts) if parts else "all passed"
        beside = ", ".join(f"{v.critic} {v.flag.label}" for v in self.other_verdicts)
        return (
            f"RoboCritics report: score {self.score_text} ({status})"
            + (f"; beside the score: {beside}" if beside else "")
            + (
                f"; {self.samples} samples, {self.duration_s:.2f} s, trajectory {self.trajectory_hash[:12]}"
                if self.trajectory_hash
                else "; no motion (the program did not run)"  # robocritics.critic.runtime_report
            )
        )

    def to_text(self, width: int = 100) -> str:
        """A plain-text rendering for terminals (no colour codes)."""
        out = [self.summary()] + ([f"  motion from {self.source}"] if self.source else [])
        name_w = max([len(v.critic) for v in self.verdicts] + [10])
        indent = " " * (2 + 8 + 1 + name_w + 2)
        for v in self.verdicts:
            head = f"  {v.flag.value:<8} {v.critic:<{name_w}}  "
            out.append(textwrap.fill(v.message, width=width, initial_indent=head, subsequent_indent=indent))
            if v.hint:
                out.append(textwrap.fill("Hint: " + v.hint, width=width, initial_indent=indent, subsequent_indent=indent + "  "))
            where = _evidence_text(v)
            if where:
                out.append(textwrap.fill(where, width=width, initial_indent=indent, subsequent_indent=indent + "  "))
        return "\n".join(out)

    def __str__(self) -> str:
        return self.to_text()

    # --- JSON ----------------------------------------------------------------------

    def to_json(self, indent: int | None = 2) -> str:
        """JSON text (includes the computed ``score``); :meth:`from_json` reads it back."""
        return self.model_dump_json(indent=indent)

    @classmethod
    def from_json(cls, text: str | bytes) -> "Report":
        try:
            return cls.model_validate_json(text)
        except Exception as exc:  # pydantic.ValidationError or bad JSON
            raise CriticError(f"not a robocritics report: {exc}") from None

    # --- notebooks -----------------------------------------------------------------

    def _repr_html_(self) -> str:
        """An HTML table of the verdicts plus an inline SVG plot of each critic's signal."""
        from html import escape as esc  # here: html.entities' table costs ~1 ms to load, and check never renders HTML
        rows = []
        for v in self.verdicts:
            colour = _FLAG_COLOURS[v.flag.value]
            measured = ""
            if v.value is not None:
                measured = f"{fmt_value(v.value)} {esc(v.unit)}"
                if v.threshold is not None:
                    measured += f" <small>(threshold {fmt_value(v.threshold)} {esc(v.unit)})</small>"
            rows.append(
                "<tr>"
                f'<td style="color:{colour};font-weight:bold">{esc(v.flag.value)}</td>'
                f"<td><code>{esc(v.critic)}</code></td>"
                f"<td>{esc(v.message)}" + (f"<br><i>Hint:</i> {esc(v.hint)}" if v.hint else "") + "</td>"
                f"<td>{measured}</td>"
                f"<td>{esc(_evidence_text(v))}</td>"
                "</tr>"
            )
        plots = "".join(
            f'<figure style="margin:4px 0"><figcaption><code>{esc(v.critic)}</code>: {esc(v.signal.label)}</figcaption>'
            f"{signal_svg(v.signal, worst_time=v.evidence.worst_time_s)}</figure>"
            for v in self.verdicts
            if v.signal is not None and v.signal.time_s
        )
        return (
            '<div class="robocritics-report">'
            f"<p><b>{esc(self.summary())}</b></p>"
            '<table style="border-collapse:collapse" border="1" cellpadding="4">'
            "<thead><tr><th>flag</th><th>critic</th><th>finding</th><th>measured</th><th>evidence</th></tr></thead>"
            f"<tbody>{''.join(rows)}</tbody></table>{plots}</div>"
        )


def _evidence_text(v: Verdict) -> str:
    e = v.evidence
    parts = []
    if v.value is not None:
        s = f"worst {fmt_value(v.value)} {v.unit}".rstrip()
        if v.threshold is not None:
            s += f" (threshold {fmt_value(v.threshold)} {v.unit})".replace(" )", ")")
        parts.append(s)
    if e.worst_sample is not None and e.worst_time_s is not None:
        parts.append(f"at {e.worst_time_s:.3f} s (sample {e.worst_sample})")
    if e.samples_flagged and e.time_window_s is not None:
        a, b = e.time_window_s
        parts.append(f"{e.samples_flagged} samples flagged in {a:.3f}-{b:.3f} s")
    if e.links:
        parts.append("links " + ", ".join(e.links))
    if e.objects:
        parts.append("objects " + ", ".join(e.objects))
    if e.lines:
        parts.append(format_lines(e.lines))
    if e.skills:
        parts.append("skills " + ", ".join(e.skills))
    return "; ".join(parts)


def _num(x: float) -> str:
    return f"{x:.4g}"


def signal_svg(signal: Signal, *, worst_time: float | None = None, width: int = 560, height: int = 140) -> str:
    """An inline SVG line plot of a signal over time with its warning and error thresholds."""
    from html import escape as esc  # here, as in Report._repr_html_
    left, right, top, bottom = 56, 12, 10, 26
    pw, ph = width - left - right, height - top - bottom
    t = signal.time_s
    vals = [v for v in signal.value if v is not None]
    thresholds = [x for x in (signal.warning, signal.error) if x is not None]
    if not t:
        return ""
    t0, t1 = min(t), max(t)
    if t1 - t0 <= 0:
        t0, t1 = t0 - 0.5, t1 + 0.5
    if signal.worse == "above":
        lo = min([0.0] + vals)
        hi = max(vals + thresholds + [1e-9]) * 1.1
    else:  # distances: show up to 3x the warning threshold so the thresholds stay visible
        lo = min(vals + thresholds + [0.0])
        cap = 3 * max(thresholds) if thresholds else None
        hi = max(vals + thresholds + [1e-9])
        if cap is not None and cap > 0:
            hi = min(hi, cap)
        hi = hi + 0.05 * (hi - lo or 1.0)
    if hi - lo <= 0:
        hi = lo + 1.0

    def X(x: float) -> float:
        return left + (x - t0) / (t1 - t0) * pw

    def Y(y: float) -> float:
        y = min(max(y, lo), hi)
        return top + (hi - y) / (hi - lo) * ph

    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}" '
        f'font-family="sans-serif" font-size="10" role="img" aria-label="{esc(signal.label)}">',
        f'<rect x="{left}" y="{top}" width="{pw}" height="{ph}" fill="#fafafa" stroke="#999"/>',
    ]
    # polylines, broken at missing values
    segment: list[str] = []
    lines: list[list[str]] = []
    for ti, vi in zip(t, signal.value):
        if vi is None or not math.isfinite(vi):
            if segment:
                lines.append(segment)
            segment = []
            continue
        segment.append(f"{X(ti):.1f},{Y(vi):.1f}")
    if segment:
        lines.append(segment)
    for seg in lines:
        if len(seg) == 1:
            x, y = seg[0].split(",")
            parts.append(f'<circle cx="{x}" cy="{y}" r="1.5" fill="#1f5fbf"/>')
        else:
            parts.append(f'<polyline fill="none" stroke="#1f5fbf" stroke-width="1.2" points="{" ".join(seg)}"/>')
    for value, name, colour in ((signal.warning, "warning", "#e08a00"), (signal.error, "error", "#c62828")):
        if value is None or not (lo <= value <= hi):
            continue
        y = Y(value)
        parts.append(
            f'<line x1="{left}" y1="{y:.1f}" x2="{left + pw}" y2="{y:.1f}" stroke="{colour}" stroke-dasharray="5,3"/>'
            f'<text x="{left + pw - 2}" y="{y - 2:.1f}" text-anchor="end" fill="{colour}">{name} {_num(value)} {esc(signal.unit)}</text>'
        )
    if worst_time is not None and t0 <= worst_time <= t1:
        x = X(worst_time)
        parts.append(f'<line x1="{x:.1f}" y1="{top}" x2="{x:.1f}" y2="{top + ph}" stroke="#555" stroke-dasharray="2,2"/>')
    parts.append(
        f'<text x="{left - 4}" y="{top + 8}" text-anchor="end">{_num(hi)}</text>'
        f'<text x="{left - 4}" y="{top + ph}" text-anchor="end">{_num(lo)}</text>'
        f'<text x="{left - 4}" y="{top + ph / 2 + 3:.1f}" text-anchor="end">{esc(signal.unit)}</text>'
        f'<text x="{left}" y="{height - 8}">{_num(t0)} s</text>'
        f'<text x="{left + pw}" y="{height - 8}" text-anchor="end">{_num(t1)} s</text>'
        f'<text x="{left + pw / 2:.1f}" y="{height - 8}" text-anchor="middle">time (s)</text>'
        "</svg>"
    )
    return "".join(parts)
