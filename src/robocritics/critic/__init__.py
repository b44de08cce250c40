"""The critic SDK: the :class:`Critic` protocol, :func:`critique`, and what critics return.

A critic reads a whole run, an :class:`~robocritics.execution.Execution` (its
:class:`~robocritics.trajectory.Trajectory`, the paper's s_1..s_T, the scene at start
and end, the robot, the program's plan when there is one, the goals), and returns one
:class:`Verdict`: a :class:`Flag` (OK / WARNING / ERROR, scoring 2 / 1 / 0), a
message saying what is wrong, a hint saying how to fix it, the measured value
against its threshold, and evidence (time window, samples, links, objects,
program lines and skills).

Critics are plugins: each is registered through the ``robocritics``
entry-point group by a ``register_critics(register)`` hook (see
:mod:`robocritics.critic.hookspecs`), the built-in ones exactly like third-party ones;
:func:`register` adds one from a notebook through the same plugin manager.
:func:`get_critics` lists the installed critics; :func:`critique` runs them.

Writing a critic::

    from pydantic import Field
    from robocritics import hookimpl
    from robocritics.critic import CriticParams, Flag, Verdict

    class CycleTime:
        name = "cycle_time"
        description = "Trajectory duration against a target cycle time."

        class Params(CriticParams):
            target_s: float = Field(30.0, gt=0, description="target cycle time, s (task-specific)")

        def check(self, execution, params):
            duration_s = execution.trajectory.duration_s
            ...
            return Verdict(critic=self.name, flag=Flag.OK, message="...")

    @hookimpl                      # in a package, named by a `robocritics` entry point
    def register_critics(register):
        register(CycleTime())

    robocritics.critic.register(CycleTime())   # or, in a notebook
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Any, Iterable, Mapping, Protocol, Union, runtime_checkable

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    StringConstraints,
    ValidationError,
    ValidationInfo,
    field_validator,
)


from .._suggest import did_you_mean
from ..errors import CriticError, RoboCriticsError
from .plugins import (
    critic_distributions,
    critic_sources,
    get_critics,
    plugin_errors,
    register,
    takes_execution,
    unregister,
    validate_critic,
)
from .chunked import Reduction, judge_in_chunks
from .report import ALL_PASSED, BUILTIN_CRITICS, Report, format_score, signal_svg
from .verdict import (
    MAX_SIGNAL_POINTS,
    Evidence,
    Flag,
    Signal,
    Verdict,
    during,
    fmt_length,
    fmt_value,
    format_lines,
    format_skills,
    make_evidence,
    make_signal,
    runs,
    threshold_verdict,
)

if TYPE_CHECKING:  # pragma: no cover
    from ..goals import Goal
    from ..program.plan import Plan
    from ..scene import Scene
    from ..execution import Execution
    from ..trajectory import Trajectory

__all__ = [
    "Critic",
    "CriticParams",
    "Flag",
    "Evidence",
    "Signal",
    "Verdict",
    "Report",
    "critique",
    "as_execution",
    "takes_execution",
    "runtime_report",
    "RUNTIME",
    "select_critics",
    "get_critics",
    "critic_sources",
    "critic_distributions",
    "plugin_errors",
    "register",
    "unregister",
    "validate_critic",
    "resolve_params",
    "ParamName",
    "ParamNames",
    "MAX_PARAM_NAMES",
    "MAX_PARAM_NAME_CHARS",
    "BUILTIN_CRITICS",
    "ALL_PASSED",
    "MAX_SIGNAL_POINTS",
    "make_evidence",
    "make_signal",
    "threshold_verdict",
    "format_lines",
    "format_skills",
    "format_score",
    "during",
    "fmt_value",
    "fmt_length",
    "runs",
    "signal_svg",
    "Reduction",
    "judge_in_chunks",
]


@runtime_checkable
class Critic(Protocol):
    """What a critic is.

    * ``name``: unique, e.g. ``"joint_speed"`` (the key in :func:`get_critics`,
      in ``critique(critics=[...])`` and in ``critique(params={...})``);
    * ``description``: one sentence for listings;
    * ``Params``: a pydantic model of the critic's thresholds; every field has a
      default, says its unit (in its name or description) and where the number
      comes from;
    * ``check(execution, params) -> Verdict``: pure (no I/O, no global state, deterministic), vectorised over
      samples. ``execution`` is the run (:class:`~robocritics.execution.Execution`: the trajectory, the scene at
      start and end, the robot, the plan or None, the goals, where the motion came from). The older
      ``check(trajectory, scene, params)`` is still accepted: the two are told apart by the number of
      parameters (:func:`takes_execution`);
    * optionally ``requested(execution) -> bool``: an on-demand critic, run when the run asks for it (or when
      named) rather than by default;
    * optionally ``reduction(execution, params) -> Reduction``: the same judgement fed chunk by chunk
      (:mod:`robocritics.critic.chunked`), so a long run (a compact trajectory, whose frames and proximity are made
      a chunk at a time) is judged in the memory of one chunk; :func:`critique` then feeds every such critic in
      one pass over the chunks. The built-in critics do; a critic without it reads the whole arrays
      (``trajectory.frames`` of a compact trajectory builds them: 1.5 kB a sample).
    """

    name: str
    description: str
    Params: type[BaseModel]

    def check(self, execution: "Execution", params: Any) -> Verdict: ...


class CriticParams(BaseModel):
    """Base for critics' ``Params``: frozen, unknown fields are rejected (typos are caught), and a number must be
    finite (a NaN threshold compares False with everything and would pass every check)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    @field_validator("*", mode="before")
    @classmethod
    def _a_number_is_a_number(cls, value: Any, info: ValidationInfo) -> Any:
        """A number field takes a number: pydantic's lax mode would read ``true`` as 1 m/s and ``"0.5"`` as 0.5
        without a word (a params file's mistake silently becomes a threshold)."""
        field = cls.model_fields.get(info.field_name or "")
        if field is not None and field.annotation in (float, int) and isinstance(value, (bool, str)):
            raise ValueError("Input should be a valid number, not true/false or text")
        return value


#: Most names one list parameter holds (frames, proximity pairs): a robot has tens of frames and a scene a few hundred
#: pairs; 10,000 frame names made a 30-s program's per-sample arrays take 5 GB.
MAX_PARAM_NAMES = 1_000
#: Longest name in a parameter, characters (frame and pair names are identifiers).
MAX_PARAM_NAME_CHARS = 200


def _distinct(names: tuple[str, ...]) -> tuple[str, ...]:
    """``names`` if none repeats: a repeated name would be checked (and cost) once per repeat."""
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise ValueError(f"names {name[:60]!r} more than once")
        seen.add(name)
    return names


#: A name in a critic's parameters (a frame, a proximity pair): 1 to :data:`MAX_PARAM_NAME_CHARS` characters.
ParamName = Annotated[str, StringConstraints(min_length=1, max_length=MAX_PARAM_NAME_CHARS)]
#: A list of distinct :data:`ParamName` values, at most :data:`MAX_PARAM_NAMES` of them.
ParamNames = Annotated[tuple[ParamName, ...], Field(max_length=MAX_PARAM_NAMES), AfterValidator(_distinct)]


ParamsArg = Union[Mapping[str, Any], BaseModel, None]


def _unknown(what: str, name: str, available: Iterable[str]) -> str:
    names = sorted(available)
    return f"{what} {name!r}{did_you_mean(name, names)} (installed critics: {', '.join(names) or 'none'})"


def resolve_params(critic: Critic, given: ParamsArg) -> BaseModel:
    """The critic's ``Params`` from a dict of overrides, a Params instance, or None (defaults).

    Raises :class:`CriticError` naming the critic and the offending field.
    """
    cls = critic.Params
    if given is None:
        return cls()
    if isinstance(given, cls):
        return given
    if isinstance(given, BaseModel):
        raise CriticError(
            f"params for critic {critic.name!r} must be a dict or {cls.__name__} of that critic, got {type(given).__name__}"
        )
    if not isinstance(given, Mapping):
        raise CriticError(f"params for critic {critic.name!r} must be a mapping of field names to values, got {type(given).__name__}")
    try:
        return cls.model_validate(dict(given))
    except ValidationError as exc:
        err = exc.errors()[0]
        field = ".".join(str(p) for p in err["loc"]) or "params"
        fields = list(cls.model_fields)
        if err["type"] == "extra_forbidden":
            hint = did_you_mean(err["loc"][0], fields)
            message = f"unknown parameter {field!r}{hint} (its parameters: {', '.join(fields)})"
        else:
            msg = err["msg"]
            if msg.startswith("Value error, "):
                msg = msg[len("Value error, ") :]
            shown = f" (got {_clipped(err['input'])})" if "input" in err and not isinstance(err["input"], dict) else ""
            message = f"{field}: {msg}{shown}"
        raise CriticError(f"invalid params for critic {critic.name!r}: {message}") from None


def _clipped(value: Any, max_chars: int = 80) -> str:
    """``repr(value)`` cut to ``max_chars`` characters (an invalid value may be a list of 10,000 names)."""
    if isinstance(value, (list, tuple)) and len(value) > 8:
        return f"a list of {len(value):,} items"
    text = repr(value)
    return text if len(text) <= max_chars else f"{text[:max_chars]}... ({len(text):,} characters)"


def _select(critics: Any, available: dict[str, Any]) -> list[Any]:
    if critics is None:
        return list(available.values())
    if isinstance(critics, str):
        critics = [c.strip() for c in critics.split(",") if c.strip()]
    selected: list[Any] = []
    seen: set[str] = set()
    for item in critics:
        if isinstance(item, str):
            if item not in available:
                raise CriticError(_unknown("unknown critic", item, available))
            item = available[item]
        else:
            validate_critic(item)  # an ad-hoc critic object, checked like a registered one
        if item.name in seen:
            continue
        seen.add(item.name)
        selected.append(item)
    if not selected:
        raise CriticError(f"no critics selected (installed critics: {', '.join(sorted(available)) or 'none'})")
    return selected


def select_critics(
    critics: Iterable[str | Critic] | str | None = None,
    params: Mapping[str, ParamsArg] | None = None,
) -> list[tuple[Critic, BaseModel]]:
    """Resolve a critic selection and its parameters without running anything.

    Returns ``[(critic, params), ...]`` in run order. Raises :class:`CriticError`
    for unknown critic names (with a did-you-mean), unknown or invalid parameters
    (naming the critic and the field), or params given for a critic that is not
    installed. :func:`critique` calls this first; a CLI can call it before a
    slow simulation to fail fast.
    """
    available = get_critics()
    selected = _select(critics, available)
    params = dict(params or {})
    selected_names = {c.name for c in selected}
    for name in params:
        if not isinstance(name, str) or (name not in available and name not in selected_names):
            raise CriticError(_unknown("params given for unknown critic", str(name)[:MAX_PARAM_NAME_CHARS], available))
    return [(critic, resolve_params(critic, params.get(critic.name))) for critic in selected]


def critique(
    run: "Execution | Trajectory",
    scene: "Scene | None" = None,
    critics: Iterable[str | Critic] | str | None = None,
    params: Mapping[str, ParamsArg] | None = None,
    *,
    goals: "Iterable[str | Goal] | str | Goal | None" = None,
    robot: Any = None,
) -> Report:
    """Run critics on a run and collect their verdicts in a :class:`Report`.

    ``run``: the :class:`~robocritics.execution.Execution` that :func:`robocritics.simulate` (or a loader of
    motion from another tool) returns, or a bare :class:`~robocritics.trajectory.Trajectory` with the ``scene``
    it moves in (and, optionally, the ``robot``): it is judged as a run with no plan whose scene does not change.
    ``scene`` given with an Execution replaces the scene it was simulated in.
    ``critics``: names (or a comma-separated string, or critic objects, validated like registered ones) to run,
    in that order; default every installed critic (:func:`get_critics`) except the on-demand ones the run does
    not ask for (a critic with ``requested(execution)``, such as ``task_outcome`` when there are no goals).
    An on-demand critic that the run asks for runs whatever ``critics`` says.
    ``params``: ``{critic_name: {field: value} | ParamsInstance}`` overriding thresholds.
    Unknown critic names, unknown or invalid parameters raise :class:`CriticError` naming the critic and the
    field; so does a critic that fails or returns something other than a :class:`Verdict`.
    ``goals``: task goals (``"green_apple in white_box"`` or :class:`~robocritics.goals.Goal`) added to the run's
    own; a bad goal raises :class:`~robocritics.errors.GoalError`. Goals are checked on the final scene, which
    only an Execution has.
    """
    from dataclasses import replace

    # a copy: the arrays the critics derive from the run (robocritics.critic.derived) live as long as this call
    execution = replace(as_execution(run, scene, goals=goals, robot=robot))
    selected = select_critics(_requested_selection(critics, execution), params)
    # the critics that reduce over chunks (:mod:`robocritics.critic.chunked`) share one pass over the run's chunks
    reductions = {
        i: _guarded(critic, lambda: critic.reduction(execution, p))
        for i, (critic, p) in enumerate(selected)
        if callable(getattr(critic, "reduction", None)) and takes_execution(critic)
    }
    if reductions:
        for chunk, window in execution.chunks():
            for i, reduction in reductions.items():
                _guarded(selected[i][0], lambda: reduction.add(chunk, window))
    verdicts: list[Verdict] = []
    used: dict[str, dict[str, Any]] = {}
    for i, (critic, p) in enumerate(selected):
        if i in reductions:
            verdict = _checked(critic, _guarded(critic, reductions[i].verdict))
        else:
            verdict = _run_critic(critic, execution, p)
        verdicts.append(verdict)
        used[critic.name] = p.model_dump(mode="json")
    trajectory = execution.trajectory
    return Report(
        verdicts=verdicts,
        trajectory_hash=trajectory.content_hash(),
        samples=len(trajectory),
        duration_s=trajectory.duration_s,
        params=used,
        source=None if execution.source in ("program", "trajectory") else execution.source,
    )


def as_execution(
    run: "Execution | Trajectory",
    scene: "Scene | None" = None,
    *,
    goals: "Iterable[str | Goal] | str | Goal | None" = None,
    robot: Any = None,
) -> "Execution":
    """The :class:`~robocritics.execution.Execution` a critic reads, from an Execution or a bare Trajectory.

    Raises :class:`CriticError` for anything else, for a Trajectory without its scene, and for goals on a bare
    Trajectory (goals are checked on the final scene, which only an Execution has).
    """
    from dataclasses import replace

    from ..execution import Execution
    from ..goals import parse_goals
    from ..trajectory import Trajectory

    if isinstance(run, Execution):
        execution = run if scene is None else replace(run, scene=scene)
        if robot is not None:
            execution = replace(execution, robot=robot)
        if goals:
            added = [g for g in parse_goals(goals, execution.scene) if g not in execution.goals]
            execution = replace(execution, goals=tuple(execution.goals) + tuple(added))
        return execution
    if not isinstance(run, Trajectory):
        raise CriticError(f"critique() judges a Trajectory or an Execution, got {type(run).__name__}")
    if goals:
        raise CriticError(
            "critique(..., goals=...) checks goals on the final scene, which only an Execution has: "
            "pass the Execution that simulate() returned, not its trajectory"
        )
    if scene is None:
        raise CriticError("critique(trajectory) needs the scene the trajectory moves in: critique(trajectory, scene)")
    return Execution(
        trajectory=run, plan=None, events=[], final_scene=scene, scene=scene, robot=robot, source="trajectory"
    )


def _requested_selection(critics: Any, execution: "Execution") -> Any:
    """The selection with the on-demand critics (those with ``requested(execution)``) the run asks for added,
    and, for the default selection, those it does not ask for left out."""
    available = get_critics()
    if critics is None:
        return [c for c in available.values() if _asked(c, execution) is not False]
    if isinstance(critics, str):
        critics = [c.strip() for c in critics.split(",") if c.strip()]
    critics = list(critics)
    named = {c if isinstance(c, str) else getattr(c, "name", None) for c in critics}
    return critics + [c for name, c in available.items() if name not in named and _asked(c, execution)]


def _asked(critic: Any, execution: "Execution") -> "bool | None":
    """``requested(execution)`` of an on-demand critic; None for a critic that always runs by default."""
    requested = getattr(critic, "requested", None)
    if requested is None:
        return None
    try:
        return bool(requested(execution))
    except Exception as exc:  # a plugin's bug: say which critic
        raise CriticError(f"critic {critic.name!r} failed in requested(): {type(exc).__name__}: {exc}") from exc


def _run_critic(critic: Any, execution: "Execution", params: BaseModel) -> Verdict:
    """One critic's verdict on the run, through whichever contract its ``check`` follows."""
    if takes_execution(critic):
        verdict = _guarded(critic, lambda: critic.check(execution, params))
    else:
        verdict = _guarded(critic, lambda: critic.check(execution.trajectory, execution.scene, params))
    return _checked(critic, verdict)


def _guarded(critic: Any, call: Any) -> Any:
    """``call()`` of a critic's code, its failure a :class:`CriticError` naming the critic."""
    try:
        return call()
    except CriticError as exc:
        raise CriticError(f"critic {critic.name!r}: {exc}") from exc
    except RoboCriticsError as exc:
        raise CriticError(f"critic {critic.name!r} cannot judge this trajectory: {exc}") from exc
    except Exception as exc:  # a plugin's bug: say which critic
        raise CriticError(f"critic {critic.name!r} failed: {type(exc).__name__}: {exc}") from exc


def _checked(critic: Any, verdict: Any) -> Verdict:
    if not isinstance(verdict, Verdict):
        raise CriticError(f"critic {critic.name!r} returned {type(verdict).__name__}, not a Verdict")
    if verdict.critic != critic.name:
        raise CriticError(f"critic {critic.name!r} returned a verdict labelled {verdict.critic!r}")
    return verdict


RUNTIME = "runtime"
"""Critic name of the verdict of a program that does not run (:func:`robocritics.pipeline.check`)."""

_RUNTIME_HINTS = {
    "ProgramError": "fix the program at the line named: the sandbox rejected it or it failed while running",
    "MotionBudgetError": "shorten the motion: fewer or faster moves, shorter waits, fewer loop iterations",
    "PlanningError": "change the motion at the line named so it can be planned: a reachable target, a hover "
    "height the arm reaches, a speed of at least 1 %",
}


def runtime_report(error: "RoboCriticsError") -> Report:
    """The report of a program that did not run: one ERROR verdict of critic ``runtime`` (score 0).

    ``error`` is the :class:`~robocritics.errors.ProgramError` or :class:`~robocritics.errors.PlanningError`
    it raised; the verdict's message is its text, ``evidence.lines`` its line (when known), ``details`` its type.
    """
    line = int(getattr(error, "line", 0) or 0)
    kind = type(error).__name__
    hint = next((h for name, h in _RUNTIME_HINTS.items() if name in [c.__name__ for c in type(error).__mro__]), "")
    verdict = Verdict(
        critic=RUNTIME,
        flag=Flag.ERROR,
        message=f"the program does not run: {kind}: {error}",
        hint=hint,
        evidence=Evidence(lines=[line] if line > 0 else []),
        details={"error": kind, "line": line, "text": str(error), "reason": str(getattr(error, "reason", error))},
    )
    return Report(verdicts=[verdict], trajectory_hash="", samples=0, duration_s=0.0, params={})
