"""The methods of a program's own values (:data:`~robocritics.program.language.SAFE_METHODS`), each priced.

One function per type; within it, methods are grouped by the work they do, which
is paid before the method runs: growing a list costs its slots, searching
costs the comparisons (:meth:`Operations.charge_contains`), text methods cost the
characters they touch, set methods treat every non-set argument as a new set
of admitted elements (:meth:`Operations.set_of`), dict methods admit every new key.
"""

from __future__ import annotations

import sys
from typing import Any

from .meter import MAKE_OPS, SLOT_BYTES, Meter
from .operations import SET_SLOT_BYTES, Operations, search_chars

__all__ = ["Methods"]

_STR_LINEAR = frozenset("upper lower strip lstrip rstrip title capitalize isdigit isalpha startswith endswith".split())
"""str methods whose work is one pass over the string."""
_STR_SEARCH = frozenset("find count index".split())
_STR_STRIP = frozenset("strip lstrip rstrip".split())
"""str methods that, given ``chars``, search it once for every character they strip."""
_SET_WITH_OTHERS = frozenset("union intersection difference issubset issuperset update".split())
_STR_BYTES = 49
"""Bytes of an empty string object (its characters come on top)."""


class Methods:
    """Method calls on program values, paid to ``meter`` through the value operations ``ops``."""

    __slots__ = ("meter", "ops")

    def __init__(self, meter: Meter, ops: Operations):
        self.meter = meter
        self.ops = ops

    def call(self, obj: Any, name: str, args: Any, kwargs: dict, node: Any) -> Any:
        """Call method ``name`` (already checked against the whitelist) of ``obj``, at the calling ``node``."""
        handler = _HANDLERS[type(obj)]
        return handler(self, obj, name, tuple(args), kwargs, node)

    def _list_method(self, obj: list, name: str, args: tuple, kwargs: dict, node: Any) -> Any:
        meter = self.meter
        if name == "append" or name == "insert":
            self.ops.grow(len(obj), 1, node)
            meter.spend_ops(len(obj) if name == "insert" else 1)
            meter.allocate(SLOT_BYTES)
        elif name == "extend" and len(args) == 1:
            items = self.ops.items(args[0], node, "the extension")
            self.ops.grow(len(obj), len(items), node)
            meter.spend_ops(len(items))
            meter.allocate(SLOT_BYTES * len(items))
            args = (items,)
        elif name == "index" and 1 <= len(args) <= 3 and not kwargs:
            start = args[1] if len(args) > 1 else None
            stop = args[2] if len(args) > 2 else None
            return self.ops.index_of(obj, args[0], start, stop, "list")
        elif (name == "count" or name == "remove") and args:
            self.ops.charge_contains(obj, args[0])
        elif name == "sort":
            return self._sort_in_place(obj, args, kwargs, node)
        elif name == "copy":
            meter.spend_ops(len(obj))
            return self.ops.made(obj.copy())
        else:  # pop, reverse, clear: one pass at most
            meter.spend_ops(len(obj))
        return getattr(obj, name)(*args, **kwargs)

    def _sort_in_place(self, obj: list, args: tuple, kwargs: dict, node: Any) -> None:
        """``list.sort``: like Python, the list looks empty to the key function and must not change."""
        if args:
            raise TypeError(f"sort() takes no positional arguments ({len(args)} given)")
        unknown = set(kwargs) - {"key", "reverse"}
        if unknown:
            raise TypeError(f"sort() got an unexpected keyword argument {sorted(unknown)[0]!r}")
        items = obj[:]
        obj.clear()
        try:
            result = self.ops.sorted_list(items, kwargs.get("key"), kwargs.get("reverse", False), node)
        except BaseException:
            obj[:] = items
            raise
        modified = bool(obj)
        obj[:] = items if modified else result
        if modified:
            raise ValueError("list modified during sort")

    def _tuple_method(self, obj: tuple, name: str, args: tuple, kwargs: dict, node: Any) -> Any:
        if args:
            self.ops.charge_contains(obj, args[0])
        return getattr(obj, name)(*args, **kwargs)

    def _dict_method(self, obj: dict, name: str, args: tuple, kwargs: dict, node: Any) -> Any:
        if name in ("get", "pop") and args:
            self.ops.keys.lookup(args[0])
        elif name == "setdefault" and args:
            self.ops.keys.lookup(args[0])
            if args[0] not in obj:
                self.ops.dict_store(obj, args[0], args[1] if len(args) > 1 else None, node)
        elif name == "update":
            if len(args) > 1:
                raise TypeError(f"update expected at most 1 argument, got {len(args)}")
            self.ops.dict_update(obj, args[0] if args else (), kwargs, node)
            return None
        elif name == "copy":
            self.meter.spend_ops(len(obj))
            return self.ops.made(obj.copy())
        elif name in ("keys", "values", "items"):
            return self.ops.made(getattr(obj, name)(*args, **kwargs))
        else:  # clear
            self.meter.spend_ops(len(obj))
        return getattr(obj, name)(*args, **kwargs)

    def _set_method(self, obj: set, name: str, args: tuple, kwargs: dict, node: Any) -> Any:
        if name == "add" and len(args) == 1:
            self.ops.set_store(obj, args[0], node)
            return None
        if name in ("discard", "remove") and args:
            self.ops.keys.lookup(args[0])
        elif name in _SET_WITH_OTHERS:
            others = tuple(self.ops.as_set(a, node) if type(a) is not set else a for a in args)
            self.ops.charge_set_operation(obj, *others)
            if name == "update":
                before = len(obj)
                self.ops.grow(before, sum(len(o) for o in others), node, "a set")
                obj.update(*others)
                self.meter.allocate(SET_SLOT_BYTES * (len(obj) - before))
                return None
            result = getattr(obj, name)(*others, **kwargs)
            return result if type(result) is bool else self.ops.new_value(result, node)
        elif name == "copy":
            self.meter.spend_ops(len(obj))
            return self.ops.made(obj.copy())
        elif name == "clear":
            self.meter.spend_ops(len(obj))
        return getattr(obj, name)(*args, **kwargs)

    def _str_method(self, obj: str, name: str, args: tuple, kwargs: dict, node: Any) -> Any:
        meter = self.meter
        if name in _STR_STRIP and args and type(args[0]) is str:
            # C looks every stripped character up in ``chars`` one by one (no fast search for wide strings)
            meter.spend_chars(len(obj) * max(len(args[0]), 1) + len(args[0]))
        elif name in _STR_LINEAR:
            meter.spend_chars(len(obj) + sum(len(a) for a in args if type(a) is str))
            if name in ("startswith", "endswith") and args and type(args[0]) is tuple:
                meter.spend_chars(sum(len(a) for a in args[0] if type(a) is str) + len(args[0]) * 64)
        elif name in _STR_SEARCH:
            needle = args[0] if args and type(args[0]) is str else ""
            meter.spend_chars(search_chars(obj, needle))
        elif name == "join" and len(args) == 1:
            items = self.ops.items(args[0], node, "the joined sequence")
            meter.spend_ops(MAKE_OPS * len(items))
            if set(map(type, items)) <= {str}:  # otherwise join raises its TypeError before building anything
                total = sum(map(len, items)) + len(obj) * max(len(items) - 1, 0)
                self.ops.check_str(total, node)
                meter.spend_chars(total)
            args = (items,)
        elif name == "replace" and len(args) >= 2 and type(args[0]) is str and type(args[1]) is str:
            old, new = args[0], args[1]
            meter.spend_chars(search_chars(obj, old))
            n = obj.count(old) if old else len(obj) + 1
            if len(args) >= 3 and type(args[2]) is int and args[2] >= 0:
                n = min(n, args[2])
            self.ops.check_str(len(obj) + n * (len(new) - len(old)), node)
            meter.spend_chars(len(obj) + n * len(new))
        elif name == "split":
            sep = args[0] if args and type(args[0]) is str else kwargs.get("sep")
            meter.spend_chars(search_chars(obj, sep) if type(sep) is str else len(obj))
            parts = obj.split(*args, **kwargs)
            self.ops.check_len(len(parts), node)
            meter.spend_ops(MAKE_OPS * len(parts))
            meter.allocate(sys.getsizeof(obj) + _STR_BYTES * len(parts))  # the parts hold at most obj's characters
            return self.ops.made(parts)
        result = getattr(obj, name)(*args, **kwargs)
        return self.ops.new_value(result, node) if type(result) is str else result


_HANDLERS = {
    list: Methods._list_method,
    tuple: Methods._tuple_method,
    dict: Methods._dict_method,
    set: Methods._set_method,
    str: Methods._str_method,
}
"""The method handler of each type in SAFE_METHODS."""
