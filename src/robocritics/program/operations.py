"""What the program's operators, comparisons and containers do to its values, each priced before it runs.

:class:`Operations` is given what it needs by the interpreter that owns it: the run's
``meter`` (:class:`~robocritics.program.meter.Meter`), the Budget, the ``keys``
(:class:`~robocritics.program.keys.KeyGuard`), ``where`` (errors at a node) and
``call`` (the interpreter's call of a program function, for sort keys). The rules, one per kind of work C would do:

* sizes are checked *before* anything is built (``[0] * 10**9``, ``'a' * 10**10``,
  ``2 ** 10 ** 10``, ``1 << 10**9``, huge joins and replaces);
* every new value is charged its bytes (:meth:`Operations.made`, :meth:`Operations.new_value`);
* a comparison walks both values in step, so it costs at most the lighter one
  (:meth:`Operations.charge_compare`), and every set or dict it meets on the way costs at
  most :data:`~robocritics.program.keys.MAX_KEYS_PER_HASH` comparisons per element;
* every key entering a dict or set goes through ``keys.admit`` and every lookup
  through ``keys.lookup``; operands of set operations that are not sets become
  sets through :meth:`Operations.set_of` first, so no C code ever hashes an unchecked key;
* a sort of ``n`` values does at most ``n log2 n + n`` comparisons, each costing
  at most the second heaviest value (:meth:`Operations.charge_sort`); key functions are
  called by the interpreter, one metered call per element, never from C.
"""

from __future__ import annotations

import ast
import math
import operator
import sys
from itertools import islice
from operator import itemgetter
from typing import Any, Callable

from ..errors import ProgramError
from .budget import Budget
from .keys import MAX_KEYS_PER_HASH, KeyGuard
from .messages import Where
from .meter import MAKE_OPS, SLOT_BYTES, Meter, scalar_weight
from .render import TooDeep, bounded_repr, render
from .skills import ObjectView, close_names
from .values import NOVALUE, check_callable, tname

__all__ = ["Operations"]

SET_SLOT_BYTES = 40
"""Bytes one more set element takes (a 16-byte entry at a fill of at most 60 %, rounded up)."""
_DICT_SLOT_BYTES = 50
"""Bytes one more dict entry takes (a 24-byte entry plus its index slot, at a fill of at most 2/3)."""
_PAIR_BYTES = 64
"""Bytes of one (key, value) tuple made while iterating items()."""
_MADE_ELEMENT_BYTES = 32
"""Bytes per element of what an iterator makes: a new int of a range (28), a slot of a new tuple (8, plus 48 per
tuple of a few elements)."""
_SEARCH_WINDOW_CHARS = 100
"""Substring search in C compares at most this many needle characters per haystack position (longer needles
switch to a linear-time algorithm)."""
_INT_OP_BITS = 64
"""Integer arithmetic costs one element operation per pair of this many bits of its operands (schoolbook)."""
_SMALL_INT = 2**64
"""Integers smaller than this in size cost one work unit per operation and a fixed size in bytes."""
_NUMBER_BYTES = 32
"""Bytes of a float (24) or of an integer smaller than ``_SMALL_INT`` (28 to 36), rounded up."""
_INT_TEXT_BITS = 128
"""Writing an integer in decimal costs one element operation per pair of this many bits (quadratic)."""
_FLOAT_DIGIT_CHARS = 16
"""A float formatted with a spec is paid this many characters per character written: exact decimal expansion
(``f"{1e-300:.1000e}"``) takes ~40 us for 1000 digits, far more than copying them."""
_MAX_KEYS_SHOWN = 20
"""Keys listed in a KeyError message."""
_SUGGESTED_KEYS = 1_000
"""A mistyped dict key is compared with at most this many of the dict's string keys."""
_MAX_FORMAT_WIDTH = 1_000
"""Largest width or precision in an f-string format spec: a wider field is only padding, built in C uncounted."""

_BINOPS: dict[type, Callable[[Any, Any], Any]] = {
    ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
    ast.FloorDiv: operator.floordiv, ast.Mod: operator.mod, ast.Pow: operator.pow,
    ast.LShift: operator.lshift, ast.RShift: operator.rshift, ast.BitOr: operator.or_,
    ast.BitXor: operator.xor, ast.BitAnd: operator.and_,
}  # fmt: skip
_IBINOPS: dict[type, Callable[[Any, Any], Any]] = {
    ast.Add: operator.iadd, ast.Sub: operator.isub, ast.Mult: operator.imul, ast.Div: operator.itruediv,
    ast.FloorDiv: operator.ifloordiv, ast.Mod: operator.imod, ast.Pow: operator.ipow,
    ast.LShift: operator.ilshift, ast.RShift: operator.irshift, ast.BitOr: operator.ior,
    ast.BitXor: operator.ixor, ast.BitAnd: operator.iand,
}  # fmt: skip
_CMPOPS: dict[type, Callable[[Any, Any], Any]] = {
    ast.Eq: operator.eq, ast.NotEq: operator.ne, ast.Lt: operator.lt, ast.LtE: operator.le,
    ast.Gt: operator.gt, ast.GtE: operator.ge,
}  # fmt: skip
_UNARY: dict[type, Callable[[Any], Any]] = {
    ast.UAdd: operator.pos, ast.USub: operator.neg, ast.Not: operator.not_, ast.Invert: operator.invert,
}
_SET_OPS = (ast.BitOr, ast.BitAnd, ast.Sub, ast.BitXor)

_NoneType = type(None)
SCALARS = frozenset({int, float, bool, complex, str, _NoneType, type(Ellipsis)})
_INTS = (int, bool)
_NUMBERS = (int, float, bool, complex)
_NUMBERS_AND_NONE = frozenset({int, float, bool, complex, type(None)})
_SEQS = (list, tuple, str)
KEYS_VIEW, VALUES_VIEW, ITEMS_VIEW = type({}.keys()), type({}.values()), type({}.items())
DICT_VIEWS = (KEYS_VIEW, VALUES_VIEW, ITEMS_VIEW)
_VIEWS = (KEYS_VIEW, ITEMS_VIEW)
_SET_LIKE = (set, *_VIEWS)
SIZED = frozenset({list, tuple, str, dict, set, range, *DICT_VIEWS})
CONTAINERS = frozenset({list, tuple, dict, set, *DICT_VIEWS})
ITERATORS = frozenset(
    {
        enumerate,
        zip,
        reversed,
        type(iter([])),
        type(iter(())),
        type(iter("")),
        type(iter(range(1))),
        type(iter(range(2**70))),  # ranges past a C long iterate with their own type
        type(iter({})),
        type(iter({}.values())),
        type(iter({}.items())),
        type(iter(set())),
        type(reversed([])),
        type(reversed(range(1))),
        type(reversed({})),
        type(reversed({}.values())),
        type(reversed({}.items())),
    }
)
ITERABLE = SIZED | ITERATORS
TUPLE_ITERATORS = frozenset({enumerate, zip, type(iter({}.items())), type(reversed({}.items()))})
"""Iterators that make a new tuple for every element (zip's tuples are as wide as its arguments are many)."""


def not_iterable(value: Any) -> TypeError:
    hint = ""
    if type(value) is ObjectView:
        hint = f"; to loop over scene objects use 'for obj in objects', for coordinates use {value._id}.position"
    elif type(value) is int:
        hint = "; to count use range(n)"
    return TypeError(f"'{tname(value)}' object is not iterable{hint}")


def produced_size(item: Any, cap: int) -> int:
    """Elements of ``item`` and of the tuples nested in it (what an iterator of tuples made), up to past ``cap``."""
    if type(item) is not tuple:
        return 1
    size = 0
    stack = [item]
    while stack and size <= cap:
        t = stack.pop()
        size += 1 + len(t)
        stack.extend(e for e in t if type(e) is tuple)
    return size


def search_chars(haystack: str, needle: str) -> int:
    """Characters C may compare looking for ``needle`` in ``haystack`` (worst case)."""
    return len(haystack) * min(max(len(needle), 1), _SEARCH_WINDOW_CHARS)


class Operations:
    """Operators, comparisons, containers and text of program values (see the module docstring)."""

    __slots__ = ("meter", "b", "keys", "where", "call")

    def __init__(self, meter: Meter, budget: Budget, keys: KeyGuard, where: Where, call: Callable[..., Any]):
        self.meter = meter
        self.b = budget
        self.keys = keys
        """Every key entering a dict or set of the run (replaced by the interpreter when the run ends)."""
        self.where = where
        self.call = call
        """``call(function, args, kwargs, node)``: the interpreter calls a key function of a sort."""

    # ---- sizes and memory ------------------------------------------------------------------------

    def made(self, value: Any) -> Any:
        """Charge the bytes of a value the program just created; return it."""
        self.meter.allocate(sys.getsizeof(value))
        return value

    def new_value(self, value: Any, node: Any) -> Any:
        """Check a new value against the size limits, charge its bytes and return it."""
        t = type(value)
        if t is float or (t is int and -_SMALL_INT < value < _SMALL_INT):  # the common case, without calls
            meter = self.meter
            meter.memory += _NUMBER_BYTES
            if meter.memory > meter.max_memory:
                meter.allocate(0)  # raises
            return value
        if t is int:
            if value.bit_length() > self.b.max_int_bits:
                raise self.int_error(node)
        elif t is str:
            if len(value) > self.b.max_str_len:
                self.check_str(len(value), node)
        elif t is list or t is tuple or t is set or t is dict:
            if len(value) > self.b.max_len:
                self.check_len(len(value), node)
        self.meter.allocate(sys.getsizeof(value))
        return value

    def check_len(self, n: int, node: Any, what: str = "a list") -> None:
        self.grow(0, n, node, what)

    def grow(self, current: int, add: int, node: Any, what: str = "a list") -> None:
        """Refuse to grow a container of ``current`` elements by ``add`` past ``max_len``."""
        if current + add > self.b.max_len:
            limit = self.b.max_len
            raise self.where.limit(f"{what} would have {current + add} elements; the limit is {limit}", node, "max_len")

    def check_str(self, n: int, node: Any) -> None:
        if n > self.b.max_str_len:
            raise self.where.limit(
                f"a string would have {n} characters; the limit is {self.b.max_str_len}", node, "max_str_len"
            )

    def int_error(self, node: Any) -> Exception:
        return self.where.limit(
            f"integer too large (more than {self.b.max_int_bits} bits); robot programs need small numbers",
            node,
            "max_int_bits",
        )

    # ---- iteration ---------------------------------------------------------------------------------

    def items(self, value: Any, node: Any, what: str = "the sequence") -> Any:
        """``value`` as a sized iterable of at most ``max_len`` elements (refusing huge ranges and endless
        iterators); iterators are run into a list, which is charged."""
        t = type(value)
        if t in SIZED:
            try:
                n = len(value)
            except OverflowError:
                message = f"{what} is far too long (more than {self.b.max_len} elements)"
                raise self.where.limit(message, node, "max_len") from None
            if n > self.b.max_len:
                message = f"{what} would have {n} elements; the limit is {self.b.max_len}"
                raise self.where.limit(message, node, "max_len")
            if t is ITEMS_VIEW:
                self.meter.allocate(_PAIR_BYTES * n)  # the (key, value) tuples the consumer will make
            elif t is range:
                self.meter.allocate(_MADE_ELEMENT_BYTES * n)  # the ints the consumer will make
            return value
        if t in ITERATORS:
            return self.run_iterator(value, node, what)
        raise not_iterable(value)

    def run_iterator(self, iterator: Any, node: Any, what: str) -> list:
        """The elements of an iterator as a new list of at most ``max_len``; the tuples zip(), enumerate() and
        items() make are counted one by one, so together they hold at most ``max_nodes`` elements."""
        limit = self.b.max_len
        if type(iterator) not in TUPLE_ITERATORS:  # each element costs O(1) to make
            out = list(islice(iterator, limit + 1))
            made = len(out)
        else:
            out = []
            made = 0
            max_nodes = self.b.max_nodes
            for item in iterator:
                out.append(item)
                made += produced_size(item, max_nodes)
                if made > max_nodes or len(out) > limit:
                    break
            if made > max_nodes and len(out) <= limit:
                raise self.meter.too_large()
        if len(out) > limit:
            raise self.where.limit(f"{what} has more than {limit} elements; the limit is {limit}", node, "max_len")
        self.meter.spend_ops(MAKE_OPS * made)
        self.meter.allocate(_MADE_ELEMENT_BYTES * made)
        return self.made(out)

    def iterate(self, value: Any, node: Any) -> Any:
        if type(value) in ITERABLE:
            return iter(value)
        raise not_iterable(value)

    # ---- comparisons -------------------------------------------------------------------------------

    def charge_compare(self, a: Any, b: Any) -> None:
        """Pay for comparing two containers: C walks them in step, so at most the lighter one is walked."""
        if type(a) not in CONTAINERS or type(b) not in CONTAINERS:
            return  # a container and a scalar compare in one step
        max_nodes = self.b.max_nodes
        weight_a = self.meter.weigh(a)
        weight_b = self.meter.weigh(b, cap=min(weight_a, max_nodes))
        weight = min(weight_a, weight_b)
        if weight > max_nodes:
            raise self.meter.too_large()
        self.meter.spend_ops((1 + MAX_KEYS_PER_HASH) * weight)

    def compare(self, op: type, a: Any, b: Any, node: Any) -> Any:
        if op is ast.Is:
            return a is b
        if op is ast.IsNot:
            return a is not b
        if op is ast.In:
            return self.contains(b, a, node)
        if op is ast.NotIn:
            return not self.contains(b, a, node)
        if type(a) is str and type(b) is str:
            self.meter.spend_chars(min(len(a), len(b)))
        else:
            self.charge_compare(a, b)
        return _CMPOPS[op](a, b)

    def contains(self, container: Any, x: Any, node: Any) -> bool:
        """``x in container``, priced by what C will walk."""
        t = type(container)
        if t is range:
            if type(x) not in _INTS:  # Python scans the range element by element
                n = len(self.items(container, node, "a range searched for a non-integer"))
                self.meter.spend_ops(n)
        elif t is str:
            if type(x) is str:
                self.meter.spend_chars(search_chars(container, x))
        elif t is dict or t is set or t is KEYS_VIEW:
            self.keys.lookup(x)
        elif t is ITEMS_VIEW:
            if type(x) is tuple and len(x) == 2:  # Python looks the key up, then compares the values
                self.keys.lookup(x[0])
                value_weight = min(self.meter.weigh(x[1]), self.b.max_nodes)
                self.meter.spend_ops((1 + MAX_KEYS_PER_HASH) * value_weight)
        elif t is list or t is tuple or t is VALUES_VIEW:
            self.charge_contains(container, x)
        elif t in ITERATORS:
            container = self.items(container, node, "the searched sequence")
            self.charge_contains(container, x)
        else:
            raise TypeError(f"argument of type '{tname(container)}' is not a container")
        return x in container

    def charge_contains(self, seq: Any, x: Any) -> None:
        """Pay for comparing ``x`` with every element of ``seq``: each comparison costs at most the lighter side,
        so at most ``len(seq)`` times ``x``'s weight and at most the weight of ``seq``."""
        n = len(seq)
        max_nodes = self.b.max_nodes
        weight_x = self.meter.weigh(x)
        ops = n * weight_x
        if weight_x > 1:  # the elements may be lighter than x: weigh them, as far as that can lower the price
            too_heavy = weight_x > max_nodes  # x was not walked to the end: the elements must be
            weight_seq = self.meter.weigh(seq, cap=max_nodes if too_heavy else ops)
            if too_heavy and weight_seq > max_nodes:
                raise self.meter.too_large()
            ops = min(ops, weight_seq)
        self.meter.spend_ops((1 + MAX_KEYS_PER_HASH) * ops + n)

    def index_of(self, seq: Any, x: Any, start: Any, stop: Any, what: str) -> int:
        """``seq.index(x, start, stop)`` without the C message that quotes ``x`` in full."""
        self.charge_contains(seq, x)
        for i in range(*slice(start, stop).indices(len(seq))):
            element = seq[i]
            if element is x or element == x:
                return i
        raise ValueError(f"{bounded_repr(x)} is not in {what}")

    # ---- items: subscripts ----------------------------------------------------------------------------

    def getitem(self, obj: Any, key: Any, node: Any) -> Any:
        t = type(obj)
        if t is dict:
            self.keys.lookup(key)
            try:
                return obj[key]
            except KeyError:
                raise self.key_error(obj, key, node) from None
        if t is list or t is tuple or t is str or t is range:
            if type(key) is slice:
                result = obj[key]
                if t is not range:
                    self.meter.spend_ops(len(result))
                return self.made(result)
            try:
                return obj[key]
            except IndexError:
                if type(key) is int:
                    raise self.where.error(
                        f"IndexError: index {bounded_repr(key)} is out of range for a {t.__name__} of length "
                        f"{len(obj)}",
                        node,
                    ) from None
                raise
        hint = ""
        if t is ObjectView:
            hint = f"; use fields such as {obj._id}.position or {obj._id}.attributes['colour']"
        raise TypeError(f"'{tname(obj)}' object is not subscriptable{hint}")

    def key_error(self, d: dict, key: Any, node: Any) -> ProgramError:
        hint = close_names(key, islice((k for k in d if type(k) is str), _SUGGESTED_KEYS)) if type(key) is str else ""
        shown = ", ".join(bounded_repr(k) for k in islice(d, _MAX_KEYS_SHOWN))
        more = f" and {len(d) - _MAX_KEYS_SHOWN} more" if len(d) > _MAX_KEYS_SHOWN else ""
        return self.where.error(
            f"KeyError: key {bounded_repr(key)} is not in the dict{hint or '.'} Keys: {shown or '(none)'}{more}", node
        )

    def setitem(self, obj: Any, key: Any, value: Any, node: Any) -> None:
        t = type(obj)
        if t is dict:
            self.dict_store(obj, key, value, node)
        elif t is list:
            if type(key) is slice:
                items = list(self.items(value, node, "the assigned sequence"))
                before = len(obj)
                self.grow(before, len(items), node)
                self.meter.spend_ops(before + len(items))
                obj[key] = items
                self.meter.allocate(SLOT_BYTES * max(len(obj) - before, 0))
            else:
                try:
                    obj[key] = value
                except IndexError:
                    if type(key) is int:
                        raise self.where.error(
                            f"IndexError: index {bounded_repr(key)} is out of range for a list of length {len(obj)}",
                            node,
                        ) from None
                    raise
        else:
            hint = "; scene objects are read-only" if t is ObjectView else ""
            if t is tuple or t is str:
                hint = f"; a {t.__name__} cannot be changed, build a new one or use a list"
            raise TypeError(f"'{tname(obj)}' object does not support item assignment{hint}")

    def delitem(self, obj: Any, key: Any, node: Any) -> None:
        t = type(obj)
        if t is dict:
            self.keys.lookup(key)
        elif t is list:
            self.meter.spend_ops(len(obj))
        else:
            raise TypeError(f"'{tname(obj)}' object does not support item deletion")
        del obj[key]

    # ---- keys: dicts and sets ------------------------------------------------------------------------

    def set_of(self, items: Any, node: Any) -> set:
        """A new set of ``items`` (a sized iterable from :meth:`_items`), every element admitted."""
        self.keys.admit_all(items)
        return self.made(set(items))

    def dict_of(self, pairs: Any, node: Any) -> dict:
        """A new dict of ``(key, value)`` pairs (a list or a dict's items), every key admitted."""
        self.keys.admit_all(list(map(itemgetter(0), pairs)))
        out = dict(pairs)
        self.check_len(len(out), node, "a dict")
        return self.made(out)

    def set_store(self, s: set, x: Any, node: Any) -> None:
        """``s.add(x)``: admitted, within ``max_len``, its slot charged."""
        self.keys.admit(x)
        if x not in s:
            self.grow(len(s), 1, node, "a set")
            self.meter.allocate(SET_SLOT_BYTES)
            s.add(x)

    def dict_store(self, d: dict, key: Any, value: Any, node: Any) -> None:
        """``d[key] = value``: the key admitted, within ``max_len``, its slot charged."""
        self.keys.admit(key)
        if key not in d:
            self.grow(len(d), 1, node, "a dict")
            self.meter.allocate(_DICT_SLOT_BYTES)
        d[key] = value

    def pairs(self, value: Any, node: Any) -> Any:
        """The ``(key, value)`` pairs of a dict or of an iterable of pairs (keys not yet admitted)."""
        if type(value) is dict:
            return value.items()
        items = self.items(value, node, "the key/value pairs")
        out = []
        for i, pair in enumerate(items):
            if type(pair) not in (tuple, list, str) or len(pair) != 2:
                length = len(pair) if type(pair) in (tuple, list, str) else None
                got = f"has length {length}" if length is not None else f"is a {tname(pair)}"
                raise ValueError(f"dict element #{i} {got}; each element must be a (key, value) pair")
            out.append((pair[0], pair[1]))
        self.meter.spend_ops(len(out))
        return out

    def as_set(self, value: Any, node: Any) -> Any:
        """A set or dict view as is (their elements were admitted), an items view or any other iterable as a
        new set of admitted elements."""
        t = type(value)
        if t is set or t is KEYS_VIEW:
            return value
        return self.set_of(self.items(value, node, "the other operand"), node)

    def charge_set_operation(self, *operands: Any) -> None:
        """Pay for a set operation between sets of admitted elements: every element is hashed or probed once,
        comparing with at most MAX_KEYS_PER_HASH stored keys."""
        self.meter.spend_ops((1 + MAX_KEYS_PER_HASH) * self.total_weight(operands))

    def total_weight(self, values: Any) -> int:
        """The summed weight of ``values``; refused past ``max_nodes`` (the walk stops there)."""
        max_nodes = self.b.max_nodes
        total = 0
        for v in values:
            total += self.meter.weigh(v, cap=max_nodes - total) if type(v) in CONTAINERS else scalar_weight(v)
            if total > max_nodes:
                raise self.meter.too_large()
        return total

    def set_binop(self, op: type, a: Any, b: Any, node: Any, inplace: bool) -> Any:
        """``a | b``, ``a & b``, ``a - b``, ``a ^ b`` of sets and dict views, and ``|`` of dicts.

        As in Python, a dict view combines with any iterable and the result is a
        new set; a set combines only with sets and views.
        """
        if type(a) is dict:
            return self.dict_merge(a, b, node, inplace) if op is ast.BitOr else _BINOPS[op](a, b)
        if type(a) in _VIEWS or type(b) in _VIEWS:
            left, right = self.as_set(a, node), self.as_set(b, node)
            inplace = False
        elif type(a) is set and type(b) is set:
            left, right = a, b
        else:
            return _BINOPS[op](a, b)  # a TypeError, as in Python
        self.charge_set_operation(left, right)
        if not inplace:
            return self.new_value(_BINOPS[op](left, right), node)
        before = len(a)
        _IBINOPS[op](a, right)
        if len(a) > self.b.max_len:
            self.check_len(len(a), node, "a set")
        self.meter.allocate(SET_SLOT_BYTES * max(len(a) - before, 0))
        return a

    def dict_merge(self, a: dict, b: Any, node: Any, inplace: bool) -> dict:
        """``a | b`` of two dicts; ``a |= b`` takes any pairs, like ``a.update(b)``."""
        if inplace:
            self.dict_update(a, b, {}, node)
            return a
        if type(b) is not dict:
            return a | b  # a TypeError, as in Python
        self.charge_set_operation(a, b)
        return self.new_value(a | b, node)

    def dict_update(self, d: dict, other: Any, kwargs: dict, node: Any) -> None:
        """``d.update(other, **kwargs)`` (and ``d |= other``), every new key admitted and charged."""
        for k, v in (*self.pairs(other, node), *kwargs.items()):
            self.dict_store(d, k, v, node)

    # ---- operators -----------------------------------------------------------------------------------

    def binop(self, op: type, a: Any, b: Any, node: Any, inplace: bool = False) -> Any:
        ta, tb = type(a), type(b)
        if ta in _INTS and tb in _INTS:
            if op is ast.Pow or op is ast.LShift or not (-_SMALL_INT < a < _SMALL_INT and -_SMALL_INT < b < _SMALL_INT):
                self.charge_int_operation(op, a, b, node)
        elif op in _SET_OPS and (ta in _SET_LIKE or tb in _SET_LIKE or ta is dict):
            return self.set_binop(op, a, b, node, inplace)
        elif op is ast.Add:
            if ta in _SEQS and ta is tb:
                if ta is str:
                    self.check_str(len(a) + len(b), node)
                    self.meter.spend_chars(len(a) + len(b))
                else:
                    self.grow(len(a), len(b), node)
                    self.meter.spend_ops(len(a) + len(b))
            elif inplace and ta is list:
                b = self.items(b, node, "the extension")
                self.grow(len(a), len(b), node)
                self.meter.spend_ops(len(b))
        elif op is ast.Mult:
            if (ta in _SEQS and tb in _INTS) or (tb in _SEQS and ta in _INTS):
                seq, n = (a, b) if ta in _SEQS else (b, a)
                total = len(seq) * max(int(n), 0)
                if type(seq) is str:
                    self.check_str(total, node)
                    self.meter.spend_chars(total)
                else:
                    self.check_len(total, node)
                    self.meter.spend_ops(total)
        elif op is ast.Mod and ta is str:
            raise self.where.error("'%' string formatting is not available; use an f-string such as f\"{x:.2f}\"", node)
        if inplace and ta is list:
            before = len(a)
            result = _IBINOPS[op](a, b)
            self.meter.allocate(SLOT_BYTES * (len(a) - before))
            return result
        fn = _IBINOPS[op] if inplace else _BINOPS[op]
        return self.new_value(fn(a, b), node)

    def charge_int_operation(self, op: type, a: int, b: int, node: Any) -> None:
        """Refuse integer results wider than ``max_int_bits`` before computing them; pay for big-int work."""
        max_bits = self.b.max_int_bits
        bits_a, bits_b = a.bit_length(), b.bit_length()
        if op is ast.Mult:
            if bits_a + bits_b > max_bits + 1:
                raise self.int_error(node)
        elif op is ast.Pow:
            if b > 0 and abs(a) > 1 and (abs(a).bit_length() - 1) * b >= max_bits:
                raise self.where.limit(
                    f"integer too large: {bounded_repr(a)} ** {bounded_repr(b)} has more than {max_bits} bits; "
                    "robot programs need small numbers",
                    node,
                    "max_int_bits",
                )
            bits_b = max_bits if b > 0 else 0
        elif op is ast.LShift:
            if a != 0 and b > 0 and bits_a + b > max_bits:
                raise self.int_error(node)
            bits_b = 0
        elif op is ast.RShift:
            bits_b = 0
        self.meter.spend_ops((1 + bits_a // _INT_OP_BITS) * (1 + bits_b // _INT_OP_BITS))

    def unaryop(self, op: type, value: Any, node: Any) -> Any:
        result = _UNARY[op](value)
        if type(result) is int:
            return self.new_value(result, node)
        return result

    # ---- text ------------------------------------------------------------------------------------------

    def to_str(self, value: Any, node: Any, use_repr: bool = False) -> str:
        """``str(value)`` (``repr`` with ``use_repr``), refused past ``max_str_len`` and paid per character."""
        t = type(value)
        if t is str and not use_repr:
            return value
        if t in CONTAINERS:
            text = self.render_container(value, node)
        else:
            if t is int:
                self.charge_int_text(value)
            text = repr(value) if use_repr or t is not str else value
            self.check_str(len(text), node)
        self.meter.spend_chars(len(text))
        return self.made(text)

    def charge_int_text(self, value: int) -> None:
        """Pay for writing an integer in decimal: Python's conversion is quadratic in its length."""
        self.meter.spend_ops((1 + value.bit_length() // _INT_TEXT_BITS) ** 2)

    def render_container(self, value: Any, node: Any) -> str:
        """``repr`` of a container, written by a walk that can do no more work than the budget has left."""
        max_chars = self.b.max_str_len
        affordable = self.meter.max_work - self.meter.work  # every piece written costs a unit
        try:
            text, complete, steps = render(value, min(max_chars, affordable), self.b.max_nesting)
        except TooDeep:
            raise self.meter.too_deep() from None
        self.meter.spend(steps)
        if not complete:
            if affordable < max_chars:  # cut short by the work budget, not by the length limit
                raise self.meter.out_of_work()
            raise self.where.limit(
                f"printing this value would produce more than {max_chars} characters; the limit is {max_chars}",
                node,
                "max_str_len",
            )
        return text

    def format_field(self, value: Any, spec: str, node: Any) -> str:
        """``format(value, spec)`` of an f-string field, with widths and precisions bounded."""
        self.meter.spend_chars(len(spec))
        number = ""
        for ch in spec:  # every run of digits is a width or a precision
            if ch.isdigit():
                number += ch
                if len(number) > len(str(_MAX_FORMAT_WIDTH)) or int(number) > _MAX_FORMAT_WIDTH:
                    raise self.where.error(
                        f"format spec {bounded_repr(spec)} asks for a width or precision above {_MAX_FORMAT_WIDTH}",
                        node,
                    )
            else:
                number = ""
        if type(value) not in SCALARS and type(value) is not ObjectView:
            raise TypeError(f"format spec {bounded_repr(spec)} only applies to numbers and strings, not {tname(value)}")
        if type(value) is str:
            self.meter.spend_chars(len(value))
        elif type(value) is int:
            self.charge_int_text(value)
        text = format(value, spec)
        if type(value) is float or type(value) is complex:  # exact decimal digits: ~1 us per 30 digits written
            self.meter.spend_chars(_FLOAT_DIGIT_CHARS * len(text))
        return self.made(text)

    # ---- sorting -------------------------------------------------------------------------------------------

    def sort_keys(self, items: Any, key: Any, node: Any) -> list:
        """The sort keys of ``items``: the items, or ``key(item)`` called by the interpreter for each."""
        if key is None:
            return list(items)
        check_callable(key, "key")
        return [self.call(key, [x], {}, node) for x in items]

    def charge_sort(self, keys: list, comparisons: int) -> None:
        """Pay for ``comparisons`` comparisons among ``keys``: each costs at most the second heaviest key
        (the lighter of the two compared)."""
        kinds = set(map(type, keys))
        if kinds <= _NUMBERS_AND_NONE:
            per_comparison = 2
        elif kinds == {str}:
            per_comparison = 2 + (sorted(map(len, keys))[-2] if len(keys) > 1 else 0) // 64
        else:  # containers: their comparisons may meet sets or dicts, each element a lookup
            per_comparison = 1 + (1 + MAX_KEYS_PER_HASH) * self.second_weight(keys)
        self.meter.spend_ops(comparisons * per_comparison)

    def second_weight(self, values: list) -> int:
        """The second largest weight of ``values``; refused when they weigh more than ``max_nodes`` together."""
        max_nodes = self.b.max_nodes
        weights = []
        total = 0
        for v in values:
            w = self.meter.weigh(v, cap=max_nodes - total) if type(v) in CONTAINERS else scalar_weight(v)
            total += w
            if total > max_nodes:
                raise self.meter.too_large()
            weights.append(w)
        return sorted(weights)[-2] if len(weights) > 1 else 0

    def sorted_list(self, items: Any, key: Any, reverse: Any, node: Any) -> list:
        """``sorted(items, key=key, reverse=reverse)``; key calls metered, comparisons paid before sorting."""
        items = list(items)
        n = len(items)
        keys = self.sort_keys(items, key, node)
        self.charge_sort(keys, n * max(math.ceil(math.log2(n)), 1) + n if n else 0)
        if key is None:
            return self.made(sorted(items, reverse=bool(reverse)))
        order = sorted(range(n), key=keys.__getitem__, reverse=bool(reverse))
        return self.made([items[i] for i in order])

    def extreme(self, fn: Callable, items: Any, key: Any, default: Any, node: Any) -> Any:
        """``min`` or ``max`` of a sized sequence (``default`` if empty and given), comparisons paid first."""
        keys = self.sort_keys(items, key, node)
        self.charge_sort(keys, len(keys))
        kw = {} if default is NOVALUE else {"default": default}
        if not keys:
            return fn((), **kw)
        if key is None:
            return fn(keys)
        return items[fn(range(len(keys)), key=keys.__getitem__)]

