"""The one hook specification of robocritics plugins.

A plugin is a module (or any object) registered under the ``robocritics``
entry-point group, with a function marked ``@hookimpl`` named
``register_critics``::

    # pyproject.toml of a plugin package
    [project.entry-points.robocritics]
    cycle_time = "robocritics_cycle_time"

    # robocritics_cycle_time.py
    from robocritics import hookimpl

    @hookimpl
    def register_critics(register):
        register(CycleTimeCritic())

The built-in critics are registered in exactly this way, through robocritics'
own entry points. ``hookimpl`` is defined here and imported as
``robocritics.hookimpl``, its one public path.
"""

from __future__ import annotations

import pluggy

__all__ = ["hookspec", "hookimpl", "register_critics", "robocritics_repairs", "register_llm_providers"]

hookspec = pluggy.HookspecMarker("robocritics")
hookimpl = pluggy.HookimplMarker("robocritics")


@hookspec
def register_critics(register):  # type: ignore[no-untyped-def]
    """Register this plugin's critics: call ``register(critic)`` once for each.

    ``critic`` follows the :class:`robocritics.critic.Critic` protocol: a
    ``name``, a ``description``, a pydantic ``Params`` model whose fields all
    have defaults, and a pure ``check(execution, params) -> Verdict`` (or the older
    ``check(trajectory, scene, params)``).
    """


@hookspec
def register_llm_providers(register):  # type: ignore[no-untyped-def]
    """Register this plugin's language-model providers: call ``register(name, factory)`` once for each.

    ``factory(**options)`` returns a :class:`robocritics.llm.protocol.ChatModel` (and, if the provider can
    embed, an :class:`~robocritics.llm.protocol.EmbeddingModel`); :func:`robocritics.llm.providers.provider`
    finds it by ``name``. robocritics registers its OpenAI-compatible provider this way, as simonw/llm
    registers its own OpenAI models through its ``register_models`` hook.
    """


@hookspec
def robocritics_repairs(verdict, execution, program):  # type: ignore[no-untyped-def]
    """Candidate repairs for one flagged ``verdict``: a list of :class:`robocritics.repair.Edit`.

    ``execution`` is the :class:`~robocritics.execution.Execution` the verdict judged
    (its ``plan`` maps skill calls to program lines), or for the ``runtime`` critic's
    verdict (a program that does not run) a :class:`robocritics.repair.NotRun` (its
    ``scene`` and ``robot``, no trajectory); ``program`` is the source text.
    Return ``[]`` for verdicts of other critics. Candidates are re-simulated by
    :func:`robocritics.repair.repair` and kept only when they remove the flag
    without adding another or breaking a goal.
    """
