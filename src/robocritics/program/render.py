"""Text of program values whose length and cost are bounded by the caller, never by the value.

A program's values can be large (a 100 000-character string) or exponentially
large when printed (a list that holds the same sub-list many times, at every
level). Python's ``repr`` builds the whole text in C before anything can stop
it, so the sandbox never calls ``repr`` on a container a program made. It uses
:func:`render`, one walk that writes the text piece by piece and stops at a
character limit, in two ways:

* :func:`full_repr` is ``repr`` exactly (``print``, ``str``, f-strings) or
  :class:`TooLong` once the text would pass the limit;
* :func:`bounded_repr` is the first few characters and ``...``: every value
  quoted in an error message goes through it, so no message can grow with
  the data.

Either way the work is proportional to the characters written, at most the
limit: each step of the walk writes at least one character.
"""

from __future__ import annotations

from typing import Any, Iterator

__all__ = ["TooLong", "TooDeep", "render", "full_repr", "bounded_repr", "clip", "MESSAGE_CHARS", "VALUE_CHARS"]

MESSAGE_CHARS = 2_000
"""Longest error message a program can cause: enough for a problem and its hints, short enough to send to an LLM."""
VALUE_CHARS = 60
"""A value or name quoted in an error message is cut to this many characters."""
_QUOTED_INT_BITS = 64
"""Integers wider than this are quoted by their bit length: their digits are noise in a message."""
_QUICK_INT_DIGITS = 40
"""Integers up to this many digits are written in about one step; longer ones cost quadratically more."""
_INT_DIGITS_PER_STEP = 200
"""Writing an integer of ``n`` digits costs about ``(n / this) ** 2`` steps (Python's conversion is quadratic)."""
_QUOTED_DEPTH = 8
"""Containers nested deeper than this are quoted as ``...`` in error messages."""


class TooLong(Exception):
    """The text of a value would have more characters than allowed."""


class TooDeep(Exception):
    """A value is nested deeper than allowed (or contains itself)."""


class _Piece(str):
    """Literal text of a container's brackets and separators (as opposed to an element to render)."""


_COMMA = _Piece(", ")
_COLON = _Piece(": ")


def _joined(items: Any, sep: _Piece = _COMMA) -> Iterator[Any]:
    first = True
    for item in items:
        if not first:
            yield sep
        first = False
        yield item


def _dict_items(d: Any) -> Iterator[Any]:
    first = True
    for k, v in d.items():
        if not first:
            yield _COMMA
        first = False
        yield k
        yield _COLON
        yield v


def _pair(kv: tuple) -> Iterator[Any]:
    yield kv[0]
    yield _COMMA
    yield kv[1]


def _items_view(view: Any) -> Iterator[Any]:
    first = True
    for kv in view:
        if not first:
            yield _COMMA
        first = False
        yield _Piece("(")
        yield from _pair(kv)
        yield _Piece(")")


_KEYS_VIEW = type({}.keys())
_VALUES_VIEW = type({}.values())
_ITEMS_VIEW = type({}.items())


def _opening(value: Any) -> tuple[str, Iterator[Any], str] | None:
    """``(opening text, elements and separators, closing text)`` of a container; ``None`` for anything else."""
    t = type(value)
    if t is list:
        return "[", _joined(value), "]"
    if t is tuple:
        if len(value) == 1:
            return "(", iter((value[0], _Piece(","))), ")"
        return "(", _joined(value), ")"
    if t is dict:
        return "{", _dict_items(value), "}"
    if t is set:
        if not value:
            return "set(", iter(()), ")"
        return "{", _joined(value), "}"
    if t is _KEYS_VIEW:
        return "dict_keys([", _joined(value), "])"
    if t is _VALUES_VIEW:
        return "dict_values([", _joined(value), "])"
    if t is _ITEMS_VIEW:
        return "dict_items([", _items_view(value), "])"
    return None


_RECURSIVE_TEXT = {list: "[...]", tuple: "(...)", dict: "{...}"}
"""What Python writes for a container met again inside itself (views write "...")."""
_END = object()


def _scalar_text(value: Any, short: bool) -> str:
    """``repr`` of a value that is not a container; with ``short``, long strings and integers are abbreviated."""
    if short:
        if type(value) is str and len(value) > VALUE_CHARS:
            return repr(value[:VALUE_CHARS]) + "..."
        if type(value) is int and value.bit_length() > _QUOTED_INT_BITS:
            return f"<{value.bit_length()}-bit integer>"
    return repr(value)


def render(value: Any, limit: int, max_depth: int, short: bool = False) -> tuple[str, bool, int]:
    """Write ``repr(value)`` up to ``limit`` characters; return ``(text, complete, steps)``.

    ``complete`` is False when the text was cut at ``limit``; ``steps`` counts the
    pieces written, each at least one character, so the work is bounded by
    ``limit``. A list or dict that contains itself is written ``[...]`` /
    ``{...}`` as Python does. Containers nested deeper than ``max_depth`` raise
    :class:`TooDeep`, or with ``short`` are written ``...``; ``short`` also
    abbreviates long strings and integers.
    """
    out: list[str] = []
    size = 0
    steps = 0
    open_containers: list[tuple[Iterator[Any], str, int]] = []  # the enclosing ones: (rest, closing, id)
    active: set[int] = set()  # ids of the containers being written
    todo: Iterator[Any] = iter((value,))
    closing, owner = "", 0
    while True:
        item = next(todo, _END)
        if item is _END:
            text = closing
            if not open_containers:
                out.append(text)
                return "".join(out), True, steps
            active.discard(owner)
            todo, closing, owner = open_containers.pop()
        elif type(item) is _Piece:
            text = item
        else:
            opened = _opening(item)
            if opened is None:
                text = _scalar_text(item, short)
                if type(item) is int and len(text) > _QUICK_INT_DIGITS:  # decimal conversion is quadratic
                    steps += (len(text) // _INT_DIGITS_PER_STEP) ** 2
            elif id(item) in active:
                text = _RECURSIVE_TEXT.get(type(item), "...")
            elif len(open_containers) >= max_depth:
                if not short:
                    raise TooDeep(f"nested more than {max_depth} levels deep")
                text = "..."
            else:
                text, elements, tail = opened
                open_containers.append((todo, closing, owner))
                active.add(id(item))
                todo, closing, owner = elements, tail, id(item)
        steps += 1
        out.append(text)
        size += len(text)
        if size > limit:
            return "".join(out)[:limit], False, steps


def full_repr(value: Any, limit: int, max_depth: int) -> tuple[str, int]:
    """``(repr(value), steps)`` exactly as Python writes it; :class:`TooLong` past ``limit`` characters."""
    text, complete, steps = render(value, limit, max_depth)
    if not complete:
        raise TooLong(f"the text would have more than {limit} characters")
    return text, steps


def bounded_repr(value: Any, limit: int = VALUE_CHARS) -> str:
    """``repr(value)`` for an error message: at most ``limit`` characters (plus ``...``), whatever the value."""
    text, complete, _ = render(value, limit, _QUOTED_DEPTH, short=True)
    return text if complete else text + "..."


def clip(text: str, limit: int = MESSAGE_CHARS) -> str:
    """``text`` cut to ``limit`` characters, saying how much was left out."""
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text) - limit} more characters)"
