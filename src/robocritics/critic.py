"""The critic SDK: the :class:`Critic` protocol, :func:`critique`, and what critics return.

A critic reads a whole :class:`~robocritics.trajectory.Trajectory` (the
paper's s_1..s_T) and the :class:`~robocritics.scene.Scene` and returns one
:class:`Verdict`: a :class:`Flag` (OK / WARNING / ERROR, scoring 2 / 1 / 0), a
message saying what is wrong, a hint saying how to fix it, the measured value
against its threshold, and evidence (time window, samples, links, objects,
program lines and skills).

Critics are plugins: each is registered through the ``robocritics``
entry-point group by a ``register_critics(register)`` hook (see
:mod:`robocritics.hookspecs`), the built-in ones exactly like third-party ones.
:func:`get_critics` lists the installed critics; :func:`critique` runs them.

Writing a critic::

    from pydantic import Field
    from robocritics.critic import CriticParams, Flag, Verdict, hookimpl, make_evidence

    class CycleTime:
        name = "cycle_time"
        description = "Trajectory duration against a target cycle time."

        class Params(CriticParams):
            target_s: float = Field(30.0, gt=0, description="target cycle time, s (task-specific)")

        def check(self, trajectory, scene, params):
            ...
            return Verdict(critic=self.name, flag=Flag.OK, message="...")

    @hookimpl
    def register_critics(register):
        register(CycleTime())
"""

from __future__ import annotations

import difflib
from typing import TYPE_CHECKING, Any, Iterable, Mapping, Protocol, Union, runtime_checkable

from pydantic import BaseModel, ConfigDict, ValidationError

from .errors import CriticError, RoboCriticsError
from .hookspecs import hookimpl, hookspec
from .plugins import critic_distributions, critic_sources, get_critics, plugin_errors
from .report import ALL_PASSED, BUILTIN_CRITICS, Report, signal_svg
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
    from .scene import Scene
    from .trajectory import Trajectory

__all__ = [
    "Critic",
    "CriticParams",
    "Flag",
    "Evidence",
    "Signal",
    "Verdict",
    "Report",
    "critique",
    "select_critics",
    "get_critics",
    "critic_sources",
    "critic_distributions",
    "plugin_errors",
    "resolve_params",
    "hookimpl",
    "hookspec",
    "BUILTIN_CRITICS",
    "ALL_PASSED",
    "MAX_SIGNAL_POINTS",
    "make_evidence",
    "make_signal",
    "threshold_verdict",
    "format_lines",
    "format_skills",
    "during",
    "fmt_value",
    "fmt_length",
    "runs",
    "signal_svg",
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
    * ``check(trajectory, scene, params) -> Verdict``: pure (no I/O, no global
      state, deterministic), vectorised over samples.
    """

    name: str
    description: str
    Params: type[BaseModel]

    def check(self, trajectory: "Trajectory", scene: "Scene", params: Any) -> Verdict: ...


class CriticParams(BaseModel):
    """Base for critics' ``Params``: frozen, and unknown fields are rejected (typos are caught)."""

    model_config = ConfigDict(frozen=True, extra="forbid")


ParamsArg = Union[Mapping[str, Any], BaseModel, None]


def _did_you_mean(name: str, names: Iterable[str], what: str = "critic") -> str:
    names = sorted(names)
    close = difflib.get_close_matches(name, names, n=1, cutoff=0.5)
    hint = f"did you mean {close[0]!r}? " if close else ""
    return f"; {hint}installed {what}s: {', '.join(names) if names else '(none)'}"


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
            close = difflib.get_close_matches(str(err["loc"][0]), fields, n=1, cutoff=0.5)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            message = f"unknown parameter {field!r}{hint}; its parameters are {', '.join(fields)}"
        else:
            msg = err["msg"]
            if msg.startswith("Value error, "):
                msg = msg[len("Value error, ") :]
            message = f"{field}: {msg}" + (f" (got {err['input']!r})" if "input" in err and not isinstance(err["input"], dict) else "")
        raise CriticError(f"invalid params for critic {critic.name!r}: {message}") from None


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
                raise CriticError(f"unknown critic {item!r}{_did_you_mean(item, available)}")
            item = available[item]
        elif not callable(getattr(item, "check", None)) or not isinstance(getattr(item, "name", None), str):
            raise CriticError(f"{item!r} is neither a critic name nor a critic (needs `name`, `Params`, `check`)")
        if item.name in seen:
            continue
        seen.add(item.name)
        selected.append(item)
    if not selected:
        raise CriticError("no critics selected" + _did_you_mean("", available))
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
            raise CriticError(f"params given for unknown critic {name!r}{_did_you_mean(str(name), available)}")
    return [(critic, resolve_params(critic, params.get(critic.name))) for critic in selected]


def critique(
    trajectory: "Trajectory",
    scene: "Scene",
    critics: Iterable[str | Critic] | str | None = None,
    params: Mapping[str, ParamsArg] | None = None,
) -> Report:
    """Run critics on a trajectory in a scene and collect their verdicts in a :class:`Report`.

    ``critics``: names (or a comma-separated string, or critic objects) to run,
    in that order; default every installed critic (:func:`get_critics`: the five
    built-ins plus any plugin's). ``params``: ``{critic_name: {field: value} |
    ParamsInstance}`` overriding thresholds. Unknown critic names, unknown or
    invalid parameters raise :class:`CriticError` naming the critic and the
    field; so does a critic that fails or returns something other than a
    :class:`Verdict`.
    """
    verdicts: list[Verdict] = []
    used: dict[str, dict[str, Any]] = {}
    for critic, p in select_critics(critics, params):
        try:
            verdict = critic.check(trajectory, scene, p)
        except CriticError as exc:
            raise CriticError(f"critic {critic.name!r}: {exc}") from exc
        except RoboCriticsError as exc:
            raise CriticError(f"critic {critic.name!r} cannot judge this trajectory: {exc}") from exc
        except Exception as exc:  # a plugin's bug: say which critic
            raise CriticError(f"critic {critic.name!r} failed: {type(exc).__name__}: {exc}") from exc
        if not isinstance(verdict, Verdict):
            raise CriticError(f"critic {critic.name!r} returned {type(verdict).__name__}, not a Verdict")
        if verdict.critic != critic.name:
            raise CriticError(f"critic {critic.name!r} returned a verdict labelled {verdict.critic!r}")
        verdicts.append(verdict)
        used[critic.name] = p.model_dump(mode="json")
    return Report(
        verdicts=verdicts,
        trajectory_hash=trajectory.content_hash(),
        samples=len(trajectory),
        duration_s=trajectory.duration_s,
        params=used,
    )
