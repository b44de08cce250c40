"""Language-model providers, registered as plugins through the ``register_llm_providers`` hook.

:func:`providers` lists them by name, :func:`provider` returns one's factory. The built-in
``openai-compatible`` provider (:class:`~robocritics.llm.providers.openai_compatible.OpenAICompatible`) is
this module's own ``register_llm_providers`` hook, registered on the plugin manager the first time providers are
asked for, as simonw/llm registers its default OpenAI plugin (so a ``robocritics check``, which loads the critic
plugins, loads no LLM code); a third-party package registers its provider through a ``robocritics`` entry point::

    # pyproject.toml:  [project.entry-points.robocritics]  my_llm = "my_llm"
    from robocritics import hookimpl

    @hookimpl
    def register_llm_providers(register):
        register("my-llm", MyChatModel)
"""

from __future__ import annotations

from typing import Any, Callable

from ...critic.hookspecs import hookimpl
from ...errors import LLMError

__all__ = ["providers", "provider", "DEFAULT_PROVIDER"]

#: The provider the command line uses (``--base-url``/``--model`` describe an OpenAI-compatible server).
DEFAULT_PROVIDER = "openai-compatible"
#: The plugin name of this module's own hook.
_BUILTIN = "robocritics.llm.providers"


def providers() -> dict[str, Callable[..., Any]]:
    """Every registered provider: ``{name: factory}`` (a plugin that fails to import is reported and skipped)."""
    import sys

    from ...critic.plugins import load_plugins, pm

    load_plugins()
    if not pm.has_plugin(_BUILTIN):
        pm.register(sys.modules[__name__], name=_BUILTIN)
    found: dict[str, Callable[..., Any]] = {}

    def register(name: str, factory: Callable[..., Any]) -> None:
        if not isinstance(name, str) or not name or not callable(factory):
            raise LLMError(f"register_llm_providers: register(name, factory) needs a name and a callable, got {name!r}")
        found.setdefault(name, factory)  # the first registration of a name wins (robocritics' own come first)

    impls = pm.hook.register_llm_providers.get_hookimpls()
    impls.sort(key=lambda impl: impl.plugin_name != _BUILTIN)  # robocritics' own first, then in registration order
    for impl in impls:
        impl.function(register=register)
    return found


def provider(name: str = DEFAULT_PROVIDER) -> Callable[..., Any]:
    """The factory of provider ``name``; :class:`LLMError` naming the registered ones when there is none."""
    found = providers()
    if name not in found:
        raise LLMError(f"no language-model provider {name!r} (registered: {', '.join(sorted(found)) or 'none'})")
    return found[name]


def _openai_compatible(**options: Any) -> Any:
    from .openai_compatible import OpenAICompatible

    return OpenAICompatible(**options)


@hookimpl
def register_llm_providers(register):  # type: ignore[no-untyped-def]
    """robocritics' own provider, registered as any plugin registers one."""
    register(DEFAULT_PROVIDER, _openai_compatible)
