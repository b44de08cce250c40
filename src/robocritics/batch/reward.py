"""``reward(programs, scene, goal=...)``: one float in [0, 1] per program, for RL fine-tuning.

The formula, per program::

    reward = 0.0                      if the program could not be evaluated (any error row)
           = 0.0                      if goals were given and the task_outcome critic did not give OK
           = score / 10               otherwise

where ``score`` is the 0-10 program quality index of the five built-in motion critics
(:attr:`robocritics.critic.report.Report.score`: OK 2, Warning 1, Error 0 points each). With goals, a program
that moves well but leaves the objects in the wrong place earns nothing: the motion quality only counts
once the task is done.

A bad ``scene``, ``goal``, ``critics`` or ``params`` is the caller's mistake, the same for every program: it
raises (:class:`~robocritics.batch.RowError` for a wrong type, :class:`~robocritics.errors.SceneError`,
:class:`~robocritics.errors.GoalError`, :class:`~robocritics.errors.CriticError`) before any program runs,
instead of silently scoring every program 0 (a trainer would learn nothing and not know why).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

__all__ = ["reward", "reward_of"]

_TASK_OUTCOME = "task_outcome"


def reward_of(row: Mapping[str, Any], gated: bool) -> float:
    """The reward of one output row (see the module docstring); ``gated``: goals were given."""
    if row.get("error") is not None or row.get("score") is None:
        return 0.0
    if gated and row.get("flags", {}).get(_TASK_OUTCOME) != "OK":
        return 0.0
    return float(row["score"]) / 10.0


def _check_inputs(scene: Any, goals: list | None, critics: Any, params: Any) -> None:
    """Raise the error every row would get for a bad scene, goal, critic or parameter (see the module docstring)."""
    from ..critic import select_critics
    from ..goals import parse_goals
    from .rows import SceneCache, check_row

    # the batch's row checks (types of scene, goal, critics, params): a RowError naming the field
    check_row({"id": 0, "scene": scene, "program": "", "goal": goals, "critics": critics, "params": params})
    loaded = SceneCache(1).get(scene.strip() if isinstance(scene, str) else dict(scene))
    parse_goals(goals, loaded)
    select_critics(critics, params)


def reward(
    programs: Sequence[str],
    scene: str | Mapping[str, Any],
    goal: str | Iterable[str] | None = None,
    *,
    critics: Iterable[str] | str | None = None,
    params: Mapping[str, Mapping[str, Any]] | None = None,
    engine: Any = "local",
    **kwargs: Any,
) -> list[float]:
    """One reward per program, in the order given (the formula is in this module's docstring).

    ``scene``: a built-in scene name, a scene file path or an inline scene object; ``goal``: a goal string
    (``"green_apple in white_box"``) or several, checked on the final scene; ``critics``/``params`` as in
    :func:`~robocritics.critic.critique`. ``engine``: ``"local"``, ``"ray"``, or an open engine
    (:class:`~robocritics.batch.LocalEngine`, :class:`~robocritics.batch.ray_engine.RayEngine`) reused across
    calls, which a trainer calling this every step should pass (starting workers costs seconds).
    Other keyword arguments go to :func:`~robocritics.batch.evaluate` (``workers``, ``timeout_s``, ...).
    A program that is not a string earns 0.0. ``reward([], ...)`` is ``[]`` (no worker is started).
    """
    from .evaluate import evaluate

    if isinstance(programs, (str, bytes)):  # iterating one would score each character as a program
        raise TypeError("programs must be a sequence of program texts, got one text: pass [program]")
    programs = list(programs)
    goals = None if goal is None else ([goal] if isinstance(goal, str) else list(goal))
    if isinstance(critics, str):
        critics = [c.strip() for c in critics.split(",") if c.strip()]
    _check_inputs(scene, goals, critics, params)
    if not programs:
        return []
    rows = []
    for i, program in enumerate(programs):
        row: dict[str, Any] = {"id": i, "scene": scene, "program": program}
        if goals:
            row["goal"] = goals
        if critics is not None:
            row["critics"] = list(critics)
        if params is not None:
            row["params"] = {k: dict(v) for k, v in params.items()}
        rows.append(row)
    rewards = [0.0] * len(rows)
    for out in evaluate(rows, engine, **kwargs):
        if isinstance(out.get("id"), int):
            rewards[out["id"]] = reward_of(out, gated=bool(goals))
    return rewards
