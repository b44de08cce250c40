"""The plugin manager: loads every ``robocritics`` entry point and collects the critics.

There is one :data:`pm` (``pluggy.PluginManager("robocritics")``) with the
hookspecs of :mod:`robocritics.critic.hookspecs`. :func:`load_plugins` walks the
``robocritics`` entry-point group itself (rather than pluggy's
``load_setuptools_entrypoints``) so that a plugin that fails to import is
reported **by name**, with a :class:`PluginWarning` and an entry in
:data:`plugin_errors`, and skipped; the other plugins still load. The built-in
critics come in through robocritics' own entry points, like any third-party
package's.

:func:`get_critics` calls each plugin's ``register_critics`` hook and returns
the critics by name; :func:`critic_sources` tells which distribution provides
each one.

:func:`register` adds a critic object to the same plugin manager from a
notebook or script, without a package: it is validated at once (a
:class:`~robocritics.errors.CriticError` says what is missing) and from then on
listed by :func:`get_critics` and run by ``critique()`` like an installed one.
"""

from __future__ import annotations

import inspect
import re
import warnings
import weakref
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Any

import pluggy
from pydantic import BaseModel

from . import hookspecs
from ..errors import CriticError

__all__ = [
    "pm",
    "PluginError",
    "PluginWarning",
    "plugin_errors",
    "load_plugins",
    "get_critics",
    "critic_sources",
    "critic_distributions",
    "validate_critic",
    "takes_execution",
    "register",
    "unregister",
    "ENTRY_POINT_GROUP",
    "BUILTIN_CRITICS",
]

ENTRY_POINT_GROUP = "robocritics"
#: The paper's five critics, in the order the paper lists them (and the order they run in).
BUILTIN_CRITICS = ("space_usage", "collision", "joint_speed", "end_effector_pose", "pinch_point")

pm = pluggy.PluginManager("robocritics")
pm.add_hookspecs(hookspecs)


class PluginWarning(UserWarning):
    """A plugin could not be loaded or registered a bad critic; it was skipped."""


@dataclass(frozen=True)
class PluginError:
    """One plugin (entry point) or critic that was skipped, and why."""

    name: str  # entry-point name (or critic name for a rejected critic)
    value: str  # entry-point value, e.g. "robocritics_cycle_time"
    distribution: str  # "name version" of the package that declared it
    error: str  # "ImportError: ..."

    def __str__(self) -> str:
        return f"{self.name} ({self.distribution or 'unknown package'}): {self.error}"


#: Plugins and critics skipped, in the order they failed: entry points that failed to
#: import or register (for the life of the process) and, from the latest
#: :func:`get_critics`, plugins whose hook failed and critics that were rejected.
plugin_errors: list[PluginError] = []
_import_errors: list[PluginError] = []
_warned: set[PluginError] = set()

_plugin_dist: dict[str, tuple[str, str]] = {}  # plugin name -> (distribution name, version)
_loaded = False
_cache_key: frozenset[Any] | None = None
_critics: dict[str, Any] = {}
_sources: dict[str, tuple[str, str]] = {}

_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_.\-]*$")


def _warn(err: PluginError) -> None:
    if err in _warned:
        return
    _warned.add(err)
    message = f"robocritics plugin {err.name!r} skipped: {err.error}" + (
        f" (from {err.distribution})" if err.distribution else ""
    )
    import logging  # here: only a skipped plugin logs, and loading logging is ~2 ms of every cold check

    logging.getLogger(__name__).warning(message)
    warnings.warn(message, PluginWarning, stacklevel=4)


def _report(err: PluginError) -> None:
    """An entry point that could not be imported or registered."""
    if err not in _import_errors:
        _import_errors.append(err)
        plugin_errors.append(err)
    _warn(err)


def load_plugins() -> None:
    """Import and register every entry point of the ``robocritics`` group (once per process)."""
    global _loaded
    if _loaded:
        return
    _loaded = True
    eps = list(entry_points(group=ENTRY_POINT_GROUP))
    # robocritics' own critics first (in the paper's order), then third parties alphabetically.
    order = {name: i for i, name in enumerate(BUILTIN_CRITICS)}
    eps.sort(key=lambda ep: (_dist_of(ep)[0] != "robocritics", order.get(ep.name, len(order)), ep.name))
    for ep in eps:
        dist = _dist_of(ep)
        dist_label = " ".join(p for p in dist if p)
        if pm.has_plugin(ep.name) or pm.is_blocked(ep.name):
            continue
        try:
            plugin = ep.load()
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - a broken plugin never crashes a run
            _report(PluginError(ep.name, ep.value, dist_label, f"{type(exc).__name__}: {exc}"))
            continue
        try:
            pm.register(plugin, name=ep.name)
        except Exception as exc:  # noqa: BLE001 - pluggy.PluginValidationError, or the same module twice
            _report(PluginError(ep.name, ep.value, dist_label, f"{type(exc).__name__}: {exc}"))
            continue
        _plugin_dist[ep.name] = dist


_dist_cache: dict[int, tuple[Any, tuple[str, str]]] = {}  # id(distribution) -> (it, (name, version))


def _dist_of(ep) -> tuple[str, str]:
    """``(name, version)`` of the distribution that declared ``ep`` (``("", "")`` if unknown).

    Read once per distribution: every ``dist.name`` or ``dist.version`` parses its whole METADATA file (with
    the package's long description) again, and the entry points of one package share one distribution.
    """
    dist = getattr(ep, "dist", None)
    if dist is None:
        return ("", "")
    cached = _dist_cache.get(id(dist))
    if cached is not None and cached[0] is dist:
        return cached[1]
    try:
        metadata = dist.metadata  # what dist.name and dist.version read
        info = (metadata["Name"] or "", metadata["Version"] or "")
    except Exception:  # noqa: BLE001 - malformed metadata
        info = ("", "")
    _dist_cache[id(dist)] = (dist, info)  # holding dist keeps its id from being reused
    return info


def validate_critic(critic: Any) -> None:
    """Raise :class:`CriticError` saying what ``critic`` lacks to follow the Critic protocol.

    A critic is an object (not a class) with a ``name`` (letters, digits, ``_ . -``), a
    ``description`` string, a pydantic ``Params`` model class whose fields all have defaults,
    and a ``check(execution, params)`` method (or the older ``check(trajectory, scene, params)``, see
    :func:`takes_execution`). Registered critics and critic objects
    passed to ``critique(critics=[...])`` are checked alike.
    """
    if isinstance(critic, type):
        raise CriticError(f"{critic.__name__} is a class; pass an instance: {critic.__name__}()")
    name = getattr(critic, "name", None)
    if not isinstance(name, str) or not _NAME.match(name):
        raise CriticError(f"critic {critic!r} needs a `name` (letters, digits, _ . -), got {name!r}")
    missing = [attr for attr in ("description", "Params", "check") if not hasattr(critic, attr)]
    if missing:
        raise CriticError(
            f"critic {name!r} has no {', '.join(f'`{m}`' for m in missing)} "
            "(a critic needs `name`, `description`, `Params` and `check`)"
        )
    if not isinstance(critic.description, str):
        raise CriticError(f"critic {name!r}: `description` must be a string, got {type(critic.description).__name__}")
    params = critic.Params
    if not (isinstance(params, type) and issubclass(params, BaseModel)):
        raise CriticError(
            f"critic {name!r}: `Params` must be a pydantic model class (e.g. a CriticParams subclass), got {params!r}"
        )
    try:
        params()
    except Exception as exc:  # noqa: BLE001
        raise CriticError(f"critic {name!r}: every field of Params needs a default ({exc})") from None
    if not callable(critic.check):
        raise CriticError(f"critic {name!r}: `check` must be a method check(execution, params)")
    takes_execution(critic)  # a check of neither contract is refused at registration


def takes_execution(critic: Any) -> bool:
    """Whether ``critic.check`` is the run contract ``check(execution, params)`` (True) or the older
    ``check(trajectory, scene, params)`` (False), told apart by the number of positional parameters.

    Raises :class:`CriticError` for a ``check`` that takes neither two nor three (a ``*args`` check is the new
    contract).
    """
    check = critic.check
    key = getattr(check, "__func__", check)
    try:
        return _arity_cache[key]
    except (KeyError, TypeError):
        pass
    try:
        params = inspect.signature(check).parameters.values()
    except (TypeError, ValueError):  # a builtin without a signature: assume the run contract
        return True
    positional = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) and p.default is p.empty]
    if any(p.kind is p.VAR_POSITIONAL for p in params) or len(positional) == 2:
        result = True
    elif len(positional) == 3:
        result = False
    else:
        raise CriticError(
            f"critic {critic.name!r}: `check` takes {len(positional)} parameters; a critic's check is "
            "check(execution, params) (or the older check(trajectory, scene, params))"
        )
    try:
        _arity_cache[key] = result
    except TypeError:  # an unhashable callable: not cached
        pass
    return result


_arity_cache: "weakref.WeakKeyDictionary[Any, bool]" = weakref.WeakKeyDictionary()


def _collect() -> None:
    global _cache_key, _critics, _sources
    load_plugins()
    key = frozenset(pm.get_plugins())  # the plugins themselves (not ids, which a replaced plugin may reuse)
    if key == _cache_key:
        return
    critics: dict[str, Any] = {}
    sources: dict[str, tuple[str, str]] = {}
    errors: list[PluginError] = []

    def reject(err: PluginError) -> None:
        if err not in errors:
            errors.append(err)
        _warn(err)

    # get_hookimpls() lists implementations in registration order.
    for impl in pm.hook.register_critics.get_hookimpls():
        plugin_name = pm.get_name(impl.plugin) or repr(impl.plugin)
        dist = _plugin_dist.get(plugin_name, ("", ""))
        dist_label = " ".join(p for p in dist if p)

        def register(critic: Any, _plugin: str = plugin_name, _dist: tuple[str, str] = dist, _label: str = dist_label) -> None:
            try:
                validate_critic(critic)
            except CriticError as exc:
                reject(PluginError(_plugin, _plugin, _label, f"CriticError: {exc}"))
                return
            if critic.name in critics:
                other = " ".join(p for p in sources[critic.name] if p) or "another plugin"
                reject(
                    PluginError(
                        critic.name, _plugin, _label, f"CriticError: a critic named {critic.name!r} is already provided by {other}"
                    )
                )
                return
            critics[critic.name] = critic
            sources[critic.name] = _dist

        try:
            impl.function(**{arg: register for arg in impl.argnames})
        except Exception as exc:  # noqa: BLE001 - a plugin's hook failing skips only that plugin
            reject(PluginError(plugin_name, plugin_name, dist_label, f"{type(exc).__name__}: {exc}"))
    _critics, _sources, _cache_key = critics, sources, key
    plugin_errors[:] = _import_errors + errors


def get_critics() -> dict[str, Any]:
    """Every installed critic by name (built-ins first, then plugins alphabetically)."""
    _collect()
    return dict(_critics)


def critic_sources() -> dict[str, str]:
    """Name of the distribution (package) that provides each critic ('' if registered by hand)."""
    _collect()
    return {name: dist[0] for name, dist in _sources.items()}


def critic_distributions() -> dict[str, tuple[str, str]]:
    """``(distribution name, version)`` providing each critic."""
    _collect()
    return dict(_sources)


_REGISTERED_PREFIX = "registered:"


def register(critic: Any) -> Any:
    """Add ``critic`` to the plugin manager, as a package's entry point would; returns ``critic``.

    For notebooks and scripts: the critic is validated at once (:class:`CriticError` saying what
    is missing), then :func:`get_critics` lists it (its package is ``""``) and
    ``critique()`` runs it by default and by name. Registering a critic of the same name again
    replaces the earlier one registered this way (re-running a notebook cell); a name that an
    installed package provides is refused. :func:`unregister` removes it.
    """
    validate_critic(critic)
    load_plugins()
    installed = get_critics()
    if critic.name in installed and not pm.has_plugin(_REGISTERED_PREFIX + critic.name):
        other = " ".join(p for p in _sources[critic.name] if p) or "another plugin"
        raise CriticError(f"a critic named {critic.name!r} is already provided by {other}; choose another name")
    unregister(critic.name)

    class _Plugin:
        @hookspecs.hookimpl
        def register_critics(self, register):  # type: ignore[no-untyped-def]
            register(critic)

    pm.register(_Plugin(), name=_REGISTERED_PREFIX + critic.name)
    return critic


def unregister(name: str) -> None:
    """Remove the critic ``name`` added by :func:`register` (nothing happens if there is none)."""
    plugin = pm.get_plugin(_REGISTERED_PREFIX + name)
    if plugin is not None:
        pm.unregister(plugin)
