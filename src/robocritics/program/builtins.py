"""The builtins and wrapped ``math`` functions of robot programs, each bounded and priced before it runs.

The names are those of :data:`robocritics.program.language.SAFE_BUILTINS`; the
interpreter finds ``_b_<name>`` (and ``_m_<name>`` for the ``math`` functions
whose C versions iterate) on itself. Each one takes its inputs through the
bounded helpers of :class:`~robocritics.program.operations._Operations`
(``_items``, ``_sorted``, ``_set_of``, ``_to_str``...), so no builtin runs C
code over more than ``max_len`` elements, and each pays for its work and its
result before returning.
"""

from __future__ import annotations

import ast
import math
from typing import Any

from . import skills as _skills
from .meter import MAKE_OPS
from .values import NOVALUE, tname

__all__: list[str] = []

_MAX_ROUND_DIGITS = 400
"""Largest ``abs(ndigits)`` of round(): more digits than a float has (308 + 17) change nothing but cost big-int work."""
_MAX_INT_TEXT_CHARS = 4_300
"""Longest string int() parses (Python's own default limit): 4096 bits are ~1234 digits, and parsing is quadratic."""
_NUMBERS = frozenset({int, float, bool, complex})
_DICT_VIEWS = (type({}.keys()), type({}.values()), type({}.items()))
_REVERSIBLE = (list, tuple, str, range, dict, *_DICT_VIEWS)
_SIZED = (*_REVERSIBLE, set)


class _Builtins:
    """The program's builtin functions (mixed into the interpreter; ``self._call_node`` is the calling node)."""

    def _b_range(self, *args):
        if not 1 <= len(args) <= 3:
            raise TypeError(f"range expected 1 to 3 arguments, got {len(args)}")
        for a in args:
            if type(a) not in (int, bool):
                raise TypeError(f"range() needs whole numbers, got {tname(a)}; convert with int(...) or round(...)")
        return self._made(range(*args))

    def _b_len(self, obj):
        if type(obj) not in _SIZED:
            raise TypeError(f"object of type '{tname(obj)}' has no len()")
        try:
            return len(obj)
        except OverflowError:
            raise OverflowError("the range is too long to measure") from None

    def _b_min(self, *args, key=None, default=NOVALUE):
        return self._min_or_max(min, "min", args, key, default)

    def _b_max(self, *args, key=None, default=NOVALUE):
        return self._min_or_max(max, "max", args, key, default)

    def _min_or_max(self, fn: Any, name: str, args: tuple, key: Any, default: Any) -> Any:
        if not args:
            raise TypeError(f"{name} expected at least 1 argument, got 0")
        if default is not NOVALUE and len(args) != 1:
            raise TypeError(f"Cannot specify a default for {name}() with multiple positional arguments")
        items = self._items(args[0], self._call_node, f"the argument of {name}()") if len(args) == 1 else args
        return self._extreme(fn, items, key, default, self._call_node)

    def _b_abs(self, x):
        return self._new_value(abs(x), self._call_node)

    def _b_round(self, number, ndigits=None):
        if ndigits is None:
            return self._new_value(round(number), self._call_node)
        if type(ndigits) not in (int, bool):
            raise TypeError(f"round() ndigits must be a whole number, not {tname(ndigits)}")
        if abs(ndigits) > _MAX_ROUND_DIGITS:
            raise ValueError(f"round() ndigits must be between -{_MAX_ROUND_DIGITS} and {_MAX_ROUND_DIGITS}")
        if type(number) is int and ndigits < 0:
            self._charge_int_text(number)  # divides by a power of ten: as costly as writing it in decimal
        return self._new_value(round(number, ndigits), self._call_node)

    def _b_enumerate(self, iterable, start=0):
        if type(start) not in (int, bool):
            raise TypeError(f"enumerate() start must be a whole number, not {tname(start)}")
        return self._made(enumerate(self._iter(iterable, self._call_node), start))

    def _b_zip(self, *iterables):
        return self._made(zip(*[self._iter(it, self._call_node) for it in iterables]))

    def _b_sum(self, iterable, start=0):
        node = self._call_node
        items = self._items(iterable, node, "the argument of sum()")
        kinds = set(map(type, items)) | {type(start)}
        if not kinds <= _NUMBERS:
            wrong = next(x for x in (start, *items) if type(x) not in _NUMBERS)
            raise TypeError(f"sum() adds numbers only, got {tname(wrong)}")
        widest = self.b.max_int_bits if int in kinds else 0  # big integers add digit by digit
        self.meter.spend_ops(len(items) * (1 + widest // 64))
        return self._new_value(sum(items, start), node)

    def _b_sorted(self, iterable, key=None, reverse=False):
        items = self._items(iterable, self._call_node, "the argument of sorted()")
        return self._sorted(items, key, reverse, self._call_node)

    def _b_reversed(self, seq):
        if type(seq) not in _REVERSIBLE:
            raise TypeError(f"'{tname(seq)}' object is not reversible")
        return self._made(reversed(seq))

    def _b_list(self, iterable=()):
        items = self._items(iterable, self._call_node, "the argument of list()")
        self.meter.spend_ops(MAKE_OPS * len(items) if type(items) is range else len(items))
        return self._made(list(items))

    def _b_tuple(self, iterable=()):
        items = self._items(iterable, self._call_node, "the argument of tuple()")
        self.meter.spend_ops(MAKE_OPS * len(items) if type(items) is range else len(items))
        return self._made(tuple(items))

    def _b_set(self, iterable=()):
        node = self._call_node
        return self._set_of(self._items(iterable, node, "the argument of set()"), node)

    def _b_dict(self, iterable=(), **kwargs):
        node = self._call_node
        out = self._dict_of(self._pairs(iterable, node), node)
        for k, v in kwargs.items():
            self._dict_store(out, k, v, node)
        return out

    def _b_float(self, x=0.0):
        if type(x) not in (int, float, bool, str):
            raise TypeError(f"float() argument must be a number or a string, not {tname(x)}")
        if type(x) is str:
            self.meter.spend_chars(len(x))
        return self._made(float(x))

    def _b_int(self, x=0, base=NOVALUE):
        if type(x) not in (int, float, bool, str):
            raise TypeError(f"int() argument must be a number or a string, not {tname(x)}")
        if type(x) is str:
            if len(x) > _MAX_INT_TEXT_CHARS:
                raise self._int_error(self._call_node)
            self.meter.spend_chars(len(x) * len(x) // 64)  # decimal parsing is quadratic
        return self._new_value(int(x) if base is NOVALUE else int(x, base), self._call_node)

    def _b_str(self, x=""):
        return self._to_str(x, self._call_node)

    def _b_repr(self, x):
        return self._to_str(x, self._call_node, use_repr=True)

    def _b_bool(self, x=False):
        return bool(x)

    def _b_any(self, iterable):
        items = self._items(iterable, self._call_node, "the argument of any()")
        self.meter.spend_ops(len(items))
        return any(items)

    def _b_all(self, iterable):
        items = self._items(iterable, self._call_node, "the argument of all()")
        self.meter.spend_ops(len(items))
        return all(items)

    def _b_print(self, *values, sep=" ", end="\n"):
        node = self._call_node
        if sep is None:
            sep = " "
        if type(sep) is not str or (end is not None and type(end) is not str):
            raise TypeError("print() sep and end must be strings")
        parts = [self._to_str(v, node) for v in values]
        self._check_str(sum(len(p) for p in parts) + len(sep) * max(len(parts) - 1, 0), node)
        text = sep.join(parts)
        if end not in (None, "\n"):
            text += end
        self.meter.spend_chars(len(text))
        _skills.print(text)

    # ---- math functions whose C versions would iterate without limits ---------------------------

    def _m_fsum(self, iterable):
        items = self._items(iterable, self._call_node, "the argument of fsum()")
        self.meter.spend_ops(len(items))
        return self._made(math.fsum(items))

    def _m_prod(self, iterable, start=1):
        node = self._call_node
        result = start
        for x in self._items(iterable, node, "the argument of prod()"):
            result = self._binop(ast.Mult, result, x, node)
        return result

    def _m_dist(self, p, q):
        node = self._call_node
        p, q = self._items(p, node, "p"), self._items(q, node, "q")
        self.meter.spend_ops(len(p) + len(q))
        return self._made(math.dist(tuple(p), tuple(q)))

