"""Messages of the interpreter's errors that depend on no run: an attribute a value does not have, the usage of
a builtin or skill, an error said once with the call it happened in.
"""

from __future__ import annotations

from typing import Any

from . import skills as _skills
from .budget import BudgetError
from .check import quote
from .language import SAFE_METHODS
from .skills import _close_names
from .values import _Builtin, _Method, _SandboxFunction, tname
from ..errors import ProgramError

__all__ = ["ALLOWED_METHODS", "attr_message", "called_from", "usage"]

#: The methods a program may call, by the type of its value.
ALLOWED_METHODS: dict[type, frozenset[str]] = {t: frozenset(names) for t, names in SAFE_METHODS.items()}


def attr_message(obj: Any, name: str) -> str:
    t = type(obj)
    if t is str and name in ("format", "format_map"):
        return f"str.{name} is not available; use an f-string such as f\"{{x:.2f}}\""
    if t in (_SandboxFunction, _Builtin, _Method):
        return f"{tname(obj)} {quote(getattr(obj, 'name', ''))} has no attribute {quote(name)}; functions have no fields"
    allowed = ALLOWED_METHODS.get(t)
    if allowed is not None:
        hint = _close_names(name, allowed, 1)
        return (
            f"'{t.__name__}' method {quote(name)} is not available{hint or '.'} "
            f"{t.__name__} methods you can use: {', '.join(sorted(allowed))}"
        )
    return f"'{tname(obj)}' object has no attribute {quote(name)}"


def called_from(exc: ProgramError, fn: _SandboxFunction, line: int) -> ProgramError:
    """``exc`` saying which call of ``fn`` it happened in (said once, by the innermost call)."""
    if getattr(exc, "_in_function", False):
        return exc
    message = f"{exc.reason} (in {quote(fn.name)[1:-1]}(), called from line {line})"
    if isinstance(exc, BudgetError):
        new: ProgramError = BudgetError(message, exc.line, exc.col, limit=exc.limit)
    else:
        new = ProgramError(message, exc.line, exc.col)
    new._in_function = True  # type: ignore[attr-defined]
    return new


def usage(b: _Builtin) -> str:
    """How to call ``b``, for error messages."""
    if b.kind == "skill" or b.name == "print":
        return _skills.usage(b.name)
    return f"{b.name}{b.sig}".replace("=<no value>", "")
