"""``reward(programs, scene, goal=...)``: one float in [0, 1] per program, for RL fine-tuning.

The formula, per program::

    reward = 0.0                      if the program could not be evaluated (any error row)
           = 0.0                      if goals were given and the task_outcome critic did not give OK
           = score / 10               otherwise

where ``score`` is the 0-10 program quality index of the five built-in motion critics
(:attr:`robocritics.report.Report.score`: OK 2, Warning 1, Error 0 points each). With goals, a program
that moves well but leaves the objects in the wrong place earns nothing: the motion quality only counts
once the task is done.
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
    A program that is not a string earns 0.0.
    """
    from .evaluate import evaluate

    goals = None if goal is None else ([goal] if isinstance(goal, str) else list(goal))
    if isinstance(critics, str):
        critics = [c.strip() for c in critics.split(",") if c.strip()]
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
