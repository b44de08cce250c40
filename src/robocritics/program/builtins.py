"""The builtins and wrapped ``math`` functions of robot programs, each bounded and priced before it runs.

The names are those of :data:`robocritics.program.language.SAFE_BUILTINS`; the
interpreter asks :class:`Builtins` for ``b_<name>`` (and ``m_<name>`` for the ``math``
functions whose C versions iterate). Each one takes its inputs through the
bounded helpers of :class:`~robocritics.program.operations.Operations`
(``items``, ``sorted_list``, ``set_of``, ``to_str``...), so no builtin runs C
code over more than ``max_len`` elements, and each pays for its work and its
result before returning.
"""

from __future__ import annotations

import ast
import math
from typing import Any

from . import skills as _skills
from .budget import Budget
from .meter import MAKE_OPS, Meter
from .operations import Operations
from .values import NOVALUE, signature, tname

__all__ = ["Builtins", "MATH_WRAPPED"]

_MAX_ROUND_DIGITS = 400
"""Largest ``abs(ndigits)`` of round(): more digits than a float has (308 + 17) change nothing but cost big-int work."""
_MAX_INT_TEXT_CHARS = 4_300
"""Longest string int() parses (Python's own default limit): 4096 bits are ~1234 digits, and parsing is quadratic."""
MATH_WRAPPED = ("fsum", "prod", "dist")
"""math functions whose C versions would iterate without limits: :class:`Builtins` implements them (``m_<name>``)."""
_NUMBERS = frozenset({int, float, bool, complex})
_DICT_VIEWS = (type({}.keys()), type({}.values()), type({}.items()))
_REVERSIBLE = (list, tuple, str, range, dict, *_DICT_VIEWS)
_SIZED = (*_REVERSIBLE, set)


class Builtins:
    """The program's builtin functions, paid to ``meter`` through the value operations ``ops``.

    The interpreter sets ``call_node`` to the node of the call being made (and back when it returns): the
    builtins take the program's arguments only, so that is where they find the place their errors point to.
    """

    __slots__ = ("meter", "b", "ops", "call_node")

    def __init__(self, meter: Meter, budget: Budget, ops: Operations):
        self.meter = meter
        self.b = budget
        self.ops = ops
        self.call_node: Any = None

    def function(self, name: str) -> Any:
        """The builtin ``name`` of SAFE_BUILTINS, bound to this run."""
        return getattr(self, "b_" + name)

    def math_function(self, name: str) -> Any:
        """The math function ``name`` of MATH_WRAPPED, bound to this run."""
        return getattr(self, "m_" + name)

    def b_range(self, *args):
        if not 1 <= len(args) <= 3:
            raise TypeError(f"range expected 1 to 3 arguments, got {len(args)}")
        for a in args:
            if type(a) not in (int, bool):
                raise TypeError(f"range() needs whole numbers, got {tname(a)}; convert with int(...) or round(...)")
        return self.ops.made(range(*args))

    def b_len(self, obj):
        if type(obj) not in _SIZED:
            raise TypeError(f"object of type '{tname(obj)}' has no len()")
        try:
            return len(obj)
        except OverflowError:
            raise OverflowError("the range is too long to measure") from None

    def b_min(self, *args, key=None, default=NOVALUE):
        return self._min_or_max(min, "min", args, key, default)

    def b_max(self, *args, key=None, default=NOVALUE):
        return self._min_or_max(max, "max", args, key, default)

    def _min_or_max(self, fn: Any, name: str, args: tuple, key: Any, default: Any) -> Any:
        if not args:
            raise TypeError(f"{name} expected at least 1 argument, got 0")
        if default is not NOVALUE and len(args) != 1:
            raise TypeError(f"Cannot specify a default for {name}() with multiple positional arguments")
        items = self.ops.items(args[0], self.call_node, f"the argument of {name}()") if len(args) == 1 else args
        return self.ops.extreme(fn, items, key, default, self.call_node)

    def b_abs(self, x):
        return self.ops.new_value(abs(x), self.call_node)

    def b_round(self, number, ndigits=None):
        if ndigits is None:
            return self.ops.new_value(round(number), self.call_node)
        if type(ndigits) not in (int, bool):
            raise TypeError(f"round() ndigits must be a whole number, not {tname(ndigits)}")
        if abs(ndigits) > _MAX_ROUND_DIGITS:
            raise ValueError(f"round() ndigits must be between -{_MAX_ROUND_DIGITS} and {_MAX_ROUND_DIGITS}")
        if type(number) is int and ndigits < 0:
            self.ops.charge_int_text(number)  # divides by a power of ten: as costly as writing it in decimal
        return self.ops.new_value(round(number, ndigits), self.call_node)

    def b_enumerate(self, iterable, start=0):
        if type(start) not in (int, bool):
            raise TypeError(f"enumerate() start must be a whole number, not {tname(start)}")
        return self.ops.made(enumerate(self.ops.iterate(iterable, self.call_node), start))

    def b_zip(self, *iterables):
        return self.ops.made(zip(*[self.ops.iterate(it, self.call_node) for it in iterables]))

    def b_sum(self, iterable, start=0):
        node = self.call_node
        items = self.ops.items(iterable, node, "the argument of sum()")
        kinds = set(map(type, items)) | {type(start)}
        if not kinds <= _NUMBERS:
            wrong = next(x for x in (start, *items) if type(x) not in _NUMBERS)
            raise TypeError(f"sum() adds numbers only, got {tname(wrong)}")
        widest = self.b.max_int_bits if int in kinds else 0  # big integers add digit by digit
        self.meter.spend_ops(len(items) * (1 + widest // 64))
        return self.ops.new_value(sum(items, start), node)

    def b_sorted(self, iterable, key=None, reverse=False):
        items = self.ops.items(iterable, self.call_node, "the argument of sorted()")
        return self.ops.sorted_list(items, key, reverse, self.call_node)

    def b_reversed(self, seq):
        if type(seq) not in _REVERSIBLE:
            raise TypeError(f"'{tname(seq)}' object is not reversible")
        return self.ops.made(reversed(seq))

    def b_list(self, iterable=()):
        items = self.ops.items(iterable, self.call_node, "the argument of list()")
        self.meter.spend_ops(MAKE_OPS * len(items) if type(items) is range else len(items))
        return self.ops.made(list(items))

    def b_tuple(self, iterable=()):
        items = self.ops.items(iterable, self.call_node, "the argument of tuple()")
        self.meter.spend_ops(MAKE_OPS * len(items) if type(items) is range else len(items))
        return self.ops.made(tuple(items))

    def b_set(self, iterable=()):
        node = self.call_node
        return self.ops.set_of(self.ops.items(iterable, node, "the argument of set()"), node)

    def b_dict(self, iterable=(), **kwargs):
        node = self.call_node
        out = self.ops.dict_of(self.ops.pairs(iterable, node), node)
        for k, v in kwargs.items():
            self.ops.dict_store(out, k, v, node)
        return out

    def b_float(self, x=0.0):
        if type(x) not in (int, float, bool, str):
            raise TypeError(f"float() argument must be a number or a string, not {tname(x)}")
        if type(x) is str:
            self.meter.spend_chars(len(x))
        return self.ops.made(float(x))

    def b_int(self, x=0, base=NOVALUE):
        if type(x) not in (int, float, bool, str):
            raise TypeError(f"int() argument must be a number or a string, not {tname(x)}")
        if type(x) is str:
            if len(x) > _MAX_INT_TEXT_CHARS:
                raise self.ops.int_error(self.call_node)
            self.meter.spend_chars(len(x) * len(x) // 64)  # decimal parsing is quadratic
        return self.ops.new_value(int(x) if base is NOVALUE else int(x, base), self.call_node)

    def b_str(self, x=""):
        return self.ops.to_str(x, self.call_node)

    def b_repr(self, x):
        return self.ops.to_str(x, self.call_node, use_repr=True)

    def b_bool(self, x=False):
        return bool(x)

    def b_any(self, iterable):
        items = self.ops.items(iterable, self.call_node, "the argument of any()")
        self.meter.spend_ops(len(items))
        return any(items)

    def b_all(self, iterable):
        items = self.ops.items(iterable, self.call_node, "the argument of all()")
        self.meter.spend_ops(len(items))
        return all(items)

    def b_print(self, *values, sep=" ", end="\n"):
        node = self.call_node
        if sep is None:
            sep = " "
        if type(sep) is not str or (end is not None and type(end) is not str):
            raise TypeError("print() sep and end must be strings")
        parts = [self.ops.to_str(v, node) for v in values]
        self.ops.check_str(sum(len(p) for p in parts) + len(sep) * max(len(parts) - 1, 0), node)
        text = sep.join(parts)
        if end not in (None, "\n"):
            text += end
        self.meter.spend_chars(len(text))
        _skills.print(text)

    # ---- math functions whose C versions would iterate without limits ---------------------------

    def m_fsum(self, iterable):
        items = self.ops.items(iterable, self.call_node, "the argument of fsum()")
        self.meter.spend_ops(len(items))
        return self.ops.made(math.fsum(items))

    def m_prod(self, iterable, start=1):
        node = self.call_node
        result = start
        for x in self.ops.items(iterable, node, "the argument of prod()"):
            result = self.ops.binop(ast.Mult, result, x, node)
        return result

    def m_dist(self, p, q):
        node = self.call_node
        p, q = self.ops.items(p, node, "p"), self.ops.items(q, node, "q")
        self.meter.spend_ops(len(p) + len(q))
        return self.ops.made(math.dist(tuple(p), tuple(q)))



# Compute every signature at import time so that running a program never imports anything.
for _name in dir(Builtins):
    if _name.startswith(("b_", "m_")):
        signature(getattr(Builtins, _name), method=True)
