"""Lazily imported package attributes (PEP 562), for ``robocritics`` and ``robocritics.llm``."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from importlib import import_module
from typing import Any

from ._suggest import did_you_mean


def lazy_exports(
    package: str,
    exports: Mapping[str, str],
    namespace: dict[str, Any],
    moved: Mapping[str, str] | None = None,
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """A module ``__getattr__`` and ``__dir__`` for ``package``.

    ``exports`` maps each public name to the module that defines it; the module
    is imported on first access and the value cached in ``namespace`` (the
    package's ``globals()``). ``__dir__`` lists the package's ``__all__``.
    ``moved`` maps names no longer exported here to the module to import them
    from; asking for one raises an ``AttributeError`` that says where it went.
    """
    moved = dict(moved or {})

    def __getattr__(name: str) -> Any:
        module = exports.get(name)
        if module is None:
            if name in moved:
                raise AttributeError(f"{package}.{name} moved: use `from {moved[name]} import {name}`")
            hint = did_you_mean(name, namespace.get("__all__", exports)) if not name.startswith("__") else ""
            raise AttributeError(f"module {package!r} has no attribute {name!r}{hint}")
        value = getattr(import_module(module), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(namespace["__all__"])

    return __getattr__, __dir__
