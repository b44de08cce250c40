"""What a critic returns: a :class:`Flag`, a :class:`Verdict` with its :class:`Evidence`
and an optional downsampled :class:`Signal`, plus helpers critics use to build them.

Everything here is re-exported by :mod:`robocritics.critic`; plugin authors
import from there.
"""

from __future__ import annotations

import math
from enum import Enum
from typing import TYPE_CHECKING, Any, Literal, Sequence

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from .._arrays import unique_values

if TYPE_CHECKING:  # pragma: no cover
    from ..trajectory import Trajectory

__all__ = [
    "Flag",
    "Evidence",
    "Signal",
    "Verdict",
    "make_evidence",
    "make_signal",
    "threshold_verdict",
    "format_lines",
    "format_skills",
    "during",
    "fmt_length",
    "fmt_value",
    "runs",
    "MAX_SIGNAL_POINTS",
]

MAX_SIGNAL_POINTS = 400


class Flag(str, Enum):
    """A critic's outcome. ``score`` is the paper's per-critic quality points."""

    OK = "OK"
    WARNING = "WARNING"
    ERROR = "ERROR"

    @property
    def score(self) -> int:
        """2 for OK, 1 for WARNING, 0 for ERROR (paper: program quality index)."""
        return {"OK": 2, "WARNING": 1, "ERROR": 0}[self.value]

    @property
    def label(self) -> str:
        """``OK``, ``Warning`` or ``Error``, as the paper writes it in feedback."""
        return {"OK": "OK", "WARNING": "Warning", "ERROR": "Error"}[self.value]

    @classmethod
    def worst(cls, flags: Sequence["Flag"]) -> "Flag":
        return min(flags, key=lambda f: f.score, default=cls.OK)

    def __str__(self) -> str:
        return self.value


class _Model(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class Evidence(_Model):
    """Where and on what a critic's finding was measured.

    Sample indices index the trajectory's arrays. For a finding that holds on
    a set of samples (every sample over a threshold), ``first_sample`` /
    ``last_sample`` bound the set, ``sample_ranges`` lists its runs (inclusive,
    at most 20 in time order: of more, the run holding ``worst_sample`` and the
    rest spread evenly from the first to the last, :func:`kept_runs`), and ``time_window_s`` is ``(time[first], time[last])``.
    ``worst_sample`` is where the measured ``value`` was taken. ``lines`` and
    ``skills`` come from the trajectory's step provenance of those samples.
    """

    time_window_s: tuple[float, float] | None = None
    worst_time_s: float | None = None
    first_sample: int | None = None
    worst_sample: int | None = None
    last_sample: int | None = None
    # `lambda: []`, not `list`: pydantic reads a default factory's signature, and a builtin's costs a
    # tokenizer regex compiled once per process (~3 ms of a cold `robocritics check`; tests/test_lazy_imports.py)
    sample_ranges: list[tuple[int, int]] = Field(default_factory=lambda: [])
    samples_flagged: int = 0
    links: list[str] = Field(default_factory=lambda: [])
    objects: list[str] = Field(default_factory=lambda: [])
    lines: list[int] = Field(default_factory=lambda: [])
    skills: list[str] = Field(default_factory=lambda: [])


class Signal(_Model):
    """A critic's per-sample measure over time, downsampled to at most 400 points.

    Downsampling keeps, in each bucket of consecutive samples, the sample that
    is *worst* for the critic (largest value if ``worse == "above"``, smallest
    if ``"below"``), so peaks and dips survive. ``None`` marks samples with no
    measure (e.g. every pair excluded as an intended contact).
    """

    label: str
    unit: str
    time_s: list[float]
    value: list[float | None]
    warning: float | None = None
    error: float | None = None
    worse: Literal["above", "below"] = "above"


class Verdict(_Model):
    """One critic's result on one trajectory.

    ``message`` says what is wrong in plain words (with the measured value);
    ``hint`` says how to fix it (naming skills and program lines). ``value`` is
    the worst measured value, ``threshold`` the threshold it was judged against
    (the one it crossed, or the warning threshold when OK), both in ``unit``.
    """

    critic: str
    flag: Flag
    message: str
    hint: str = ""
    value: float | None = None
    threshold: float | None = None
    unit: str = ""
    evidence: Evidence = Field(default_factory=Evidence)
    signal: Signal | None = None
    details: dict[str, Any] = Field(default_factory=dict)

    @property
    def score(self) -> int:
        return self.flag.score

    @property
    def ok(self) -> bool:
        return self.flag is Flag.OK

    def feedback(self) -> str:
        """The paper-style line sent to an LLM: ``"Warning: <message> <hint>"``."""
        return f"{self.flag.label}: {self.message}" + (f" {self.hint}" if self.hint else "")


# --- helpers for critic authors ----------------------------------------------------


def runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and end (inclusive) indices of the runs of True in a 1-D boolean array."""
    m = np.asarray(mask, dtype=bool).astype(np.int8)
    edges = np.diff(np.concatenate(([0], m, [0])))
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1


def kept_runs(starts: np.ndarray, ends: np.ndarray, max_runs: int, worst: int | None = None) -> list[int]:
    """Which of the runs ``starts[k]..ends[k]`` (time order) a bounded evidence lists: all of up to ``max_runs``;
    of more, ``max_runs`` of them spread evenly over the motion (the first and the last always) with the run
    holding sample ``worst`` in place of the spread one nearest it, so a long program's timeline marks where
    its findings recur and where the worst is, not only its first minutes."""
    n = len(starts)
    if n <= max_runs:
        return list(range(n))
    if max_runs <= 0:
        return []
    keep = np.round(np.linspace(0, n - 1, max_runs)).astype(np.int64)
    if worst is not None:
        holding = int(np.searchsorted(starts, worst, side="right")) - 1
        if holding >= 0 and worst <= ends[holding] and holding not in keep:
            inner = np.abs(keep[1:-1] - holding) if max_runs > 2 else np.abs(keep - holding)
            keep[int(np.argmin(inner)) + (1 if max_runs > 2 else 0)] = holding
    return sorted(set(keep.tolist()))


def make_evidence(
    trajectory: "Trajectory",
    samples: np.ndarray | None = None,
    *,
    worst: int | None = None,
    links: Sequence[str] = (),
    objects: Sequence[str] = (),
    max_ranges: int = 20,
) -> Evidence:
    """Evidence for the samples where a finding holds.

    ``samples`` is a boolean mask ``(T,)`` or an array of sample indices (None or
    empty: only ``worst`` is reported, and lines/skills come from it).
    """
    time = trajectory.time
    T = len(time)
    if samples is None:
        idx = np.empty(0, dtype=np.int64)
    else:
        samples = np.asarray(samples)
        if samples.dtype == bool:
            idx = np.flatnonzero(samples)
        else:
            idx = unique_values(samples.astype(np.int64))
    fields: dict[str, Any] = {"links": list(dict.fromkeys(links)), "objects": list(dict.fromkeys(objects))}
    if worst is not None:
        worst = int(min(max(worst, 0), T - 1))
        fields["worst_sample"] = worst
        fields["worst_time_s"] = float(time[worst])
    if idx.size:
        mask = np.zeros(T, dtype=bool)
        mask[idx] = True
        starts, ends = runs(mask)
        fields.update(
            first_sample=int(idx[0]),
            last_sample=int(idx[-1]),
            time_window_s=(float(time[idx[0]]), float(time[idx[-1]])),
            sample_ranges=[(int(starts[k]), int(ends[k])) for k in kept_runs(starts, ends, max_ranges, worst)],
            samples_flagged=int(idx.size),
            lines=trajectory.lines(idx),
            skills=trajectory.skills(idx),
        )
    elif worst is not None:
        fields.update(
            time_window_s=(float(time[worst]), float(time[worst])),
            lines=trajectory.lines(np.array([worst])),
            skills=trajectory.skills(np.array([worst])),
        )
    return Evidence(**fields)


def make_signal(
    time: np.ndarray,
    values: np.ndarray,
    *,
    label: str,
    unit: str,
    warning: float | None = None,
    error: float | None = None,
    worse: Literal["above", "below"] = "above",
    max_points: int = MAX_SIGNAL_POINTS,
) -> Signal:
    """Downsample a per-sample measure to at most ``max_points``, keeping each bucket's worst sample."""
    time = np.asarray(time, dtype=float)
    values = np.asarray(values, dtype=float)
    n = values.shape[0]
    if n > max_points:
        # worst sample of each bucket of the inner samples, plus the first and last sample
        inner = n - 2
        size = -(-inner // (max_points - 2))
        buckets = -(-inner // size)
        key = values[1:-1] if worse == "above" else -values[1:-1]
        key = np.where(np.isnan(key), -np.inf, key)
        padded = np.full(buckets * size, -np.inf)
        padded[:inner] = key
        pick = np.argmax(padded.reshape(buckets, size), axis=1) + np.arange(buckets) * size + 1
        pick = np.concatenate(([0], np.minimum(pick, n - 2), [n - 1]))
        time, values = time[pick], values[pick]
    value = values.tolist()  # Python floats, bit for bit; a non-finite value is None (no measure)
    finite = np.isfinite(values)
    if not finite.all():
        for i in np.flatnonzero(~finite).tolist():
            value[i] = None
    return Signal(
        label=label,
        unit=unit,
        time_s=time.tolist(),
        value=value,
        warning=warning,
        error=error,
        worse=worse,
    )


def threshold_verdict(
    critic: str,
    trajectory: "Trajectory | None",
    flag: Flag,
    samples: np.ndarray | None = None,
    *,
    message: str,
    hint: str = "",
    value: float | None = None,
    threshold: float | None = None,
    unit: str = "",
    worst: int | None = None,
    links: Sequence[str] = (),
    objects: Sequence[str] = (),
    evidence: Evidence | None = None,
    signal: Signal | None = None,
    details: dict[str, Any] | None = None,
) -> Verdict:
    """A critic's :class:`Verdict` of ``value`` judged against ``threshold``, its evidence built in the same call.

    The evidence is ``evidence`` if given, else ``make_evidence(trajectory, samples, worst=worst,
    links=links, objects=objects)`` (``samples``: the mask or indices of the samples where the
    threshold is crossed; None for an OK verdict, which reports the ``worst`` sample only), else
    empty when ``trajectory`` is None. ``{during}`` in ``hint`` is replaced by :func:`during` of
    that evidence (the skills and program lines involved). A critic whose branches share the
    signal, details and unit can bind them once::

        verdict = functools.partial(threshold_verdict, self.name, trajectory, unit="m", signal=signal, details=details)
        if worst < params.d_min_m:
            return verdict(Flag.ERROR, per_sample < params.d_min_m, worst=wt, value=worst, threshold=params.d_min_m,
                           message=f"...", hint="To avoid it, you can consider ...{during}.")
        return verdict(Flag.OK, worst=wt, value=worst, threshold=params.d_max_m, message=f"...")
    """
    if evidence is None:
        evidence = (
            Evidence() if trajectory is None else make_evidence(trajectory, samples, worst=worst, links=links, objects=objects)
        )
    return Verdict(
        critic=critic,
        flag=flag,
        message=message,
        hint=hint.replace("{during}", during(evidence)),
        value=value,
        threshold=threshold,
        unit=unit,
        evidence=evidence,
        signal=signal,
        details={} if details is None else details,
    )


def format_lines(lines: Sequence[int]) -> str:
    """``[4, 5, 6]`` -> ``"lines 4-6"``; ``[2, 4, 5, 9]`` -> ``"lines 2, 4-5 and 9"``; ``[]`` -> ``""``."""
    lines = sorted({int(x) for x in lines if int(x) > 0})
    if not lines:
        return ""
    parts: list[str] = []
    start = prev = lines[0]
    for x in lines[1:] + [None]:  # type: ignore[list-item]
        if x is not None and x == prev + 1:
            prev = x
            continue
        parts.append(str(start) if start == prev else f"{start}-{prev}")
        if x is not None:
            start = prev = x
    if len(lines) == 1:
        return f"line {parts[0]}"
    text = parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]
    return f"lines {text}"


def format_skills(skills: Sequence[str]) -> str:
    """``["move_to"]`` -> ``"[move_to]"`` (the paper's bracket style)."""
    return "[" + ", ".join(dict.fromkeys(skills)) + "]" if skills else ""


def during(evidence: Evidence, noun: str = "actions") -> str:
    """`` during [move_to] actions on lines 4-6`` from evidence provenance ('' when there is none)."""
    out = ""
    if evidence.skills:
        out += f" during {format_skills(evidence.skills)} {noun}"
    if evidence.lines:
        out += f" on {format_lines(evidence.lines)}"
    return out


def fmt_value(x: float, digits: int = 3) -> str:
    """A number with ``digits`` significant digits, no trailing zeros: 1.0 -> '1', 1.3249 -> '1.32'."""
    if x is None or not math.isfinite(x):
        return str(x)
    return f"{x:.{digits}g}"


def fmt_length(metres: float) -> str:
    """A distance in friendly units: 0.0032 -> '3.2 mm', 0.032 -> '3.2 cm', 1.2 -> '1.2 m'."""
    a = abs(metres)
    if a < 0.01:
        return f"{metres * 1000:.1f} mm"
    if a < 1.0:
        return f"{metres * 100:.1f} cm"
    return f"{metres:.3g} m"
