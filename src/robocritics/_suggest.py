"""The one did-you-mean of robocritics: the closest valid names to a mistyped one, for error messages."""

from __future__ import annotations

import difflib  # at import, not in a program's error path: a sandboxed run must import nothing

from typing import Iterable

__all__ = ["did_you_mean"]


def did_you_mean(name: object, choices: Iterable[object], n: int = 1) -> str:
    """``"; did you mean 'x'?"`` (``"'x' or 'y'"`` for ``n > 1``) naming the choices closest to ``name``.

    ``""`` when none is close (difflib's similarity ratio below 0.6), so callers append it to a message
    unconditionally: ``f"unknown critic {name!r}{did_you_mean(name, names)}"``.
    """
    close = difflib.get_close_matches(str(name), [str(c) for c in choices], n=n)
    if not close:
        return ""
    return "; did you mean " + " or ".join(repr(c) for c in close) + "?"
