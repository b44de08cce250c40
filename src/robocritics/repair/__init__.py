"""Critic-native repairs: program edits derived from the critics' own evidence, verified by simulation.

``repair(program, scene)`` simulates the program, asks every critic that flags
an Error or a Warning for candidate edits (the ``robocritics_repairs`` hook, see
:mod:`robocritics.critic.hookspecs`; the built-in critics' repairs are in
:mod:`robocritics.repair.builtin`, registered the same way as a plugin's),
re-simulates each candidate and keeps the best one that makes progress on that
flag without worsening any verdict, or that has fewer Errors (or as many and a
higher score) without costing a task goal; when no single edit helps, two are
tried together (see :mod:`robocritics.repair.search`). A program that does not
run is judged by the ``runtime`` critic's Error and repaired the same way. It
iterates until nothing is flagged or nothing helps, within a bound of
:data:`~robocritics.repair.search.MAX_SIMULATIONS` re-simulations; no LLM is
involved. The result is the best program found, with its changes (critic, line,
what, why, cycle-time cost) and what is left.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Iterable

from .._lazy import lazy_exports

__all__ = ["repair", "Repair", "Change", "NotRun", "Edit", "Insert", "ScaleNumbers", "MoveBlock", "apply_edits",
           "paragraphs", "MAX_ROUNDS", "MAX_SIMULATIONS"]  # fmt: skip

# Imported on first use: `import robocritics` re-exports repair() and must stay cheap (no numpy, no pydantic).
_EXPORTS = {
    **{name: "robocritics.repair.search" for name in ("Repair", "Change", "NotRun", "MAX_ROUNDS", "MAX_SIMULATIONS")},
    **{name: "robocritics.repair.edit" for name in ("Edit", "Insert", "ScaleNumbers", "MoveBlock", "apply_edits",
                                                   "paragraphs")},  # fmt: skip
}

if TYPE_CHECKING:  # pragma: no cover
    from ..scene import Scene
    from .edit import Edit, Insert, MoveBlock, ScaleNumbers, apply_edits, paragraphs
    from .search import MAX_ROUNDS, MAX_SIMULATIONS, Change, NotRun, Repair


def repair(
    program: str,
    scene: Scene | str,
    *,
    goal: str | Iterable[Any] | None = None,
    critics: Iterable[str] | str | None = None,
    robot: Any = None,
    params: Any = None,
) -> Repair:
    """Repair ``program`` in ``scene`` with the critics' own edits until nothing is flagged or nothing helps.

    ``goal``: task goals (``"green_apple in white_box"``, a list of them, or
    :class:`~robocritics.goals.Goal`) that every kept edit must still meet;
    ``critics``: the critics to run (default: all installed); ``robot``: a
    :class:`~robocritics.Robot` (default UR3e); ``params``: threshold overrides as
    for :func:`~robocritics.critique`. A bad goal raises :class:`~robocritics.errors.GoalError`.
    A program that does not run (sandbox or planning error) is judged by the ``runtime``
    critic's Error, which has its own repair (e.g. the nearest reachable height for an
    unreachable target); if it still does not run, the result's ``execution`` is None.
    """
    from .search import search

    return search(program, scene, goal, critics, robot, params)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
