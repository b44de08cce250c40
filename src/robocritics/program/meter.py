"""The cost model of a program run: what each thing a program makes Python do costs, and the meter that pays.

Three counters cover everything a program can make the interpreter do:

* **steps**: statements, loop iterations, comprehension elements and calls
  (``Budget.max_steps``);
* **work units** (``Budget.max_work``): one per evaluated expression node or
  step, plus, *before* any builtin operation runs, its worst case in elements
  it may touch: copying, searching and concatenating cost their lengths; a
  comparison, hash or sort costs the weight of the values it walks (see
  :meth:`Meter.weigh`); printing costs the characters written. Operations in
  C cannot be interrupted, so each is priced from the sizes of its inputs and
  refused when the budget cannot pay, never stopped half way;
* **bytes** (``Budget.max_alloc_bytes``): every value the program creates, by
  ``sys.getsizeof`` when made, plus the slots a container grows by.

The clock (``Budget.max_seconds``) is read every :data:`CLOCK_EVERY_UNITS` work
units, so time is checked inside long expressions and before long builtin work.
"""

from __future__ import annotations

import math
from typing import Any

from .budget import Budget

__all__ = ["Meter", "LimitReached", "OPS_PER_UNIT", "MAKE_OPS", "CHARS_PER_UNIT", "CLOCK_EVERY_UNITS", "SLOT_BYTES"]

OPS_PER_UNIT = 32
"""Element operations in C (compare two numbers, hash or copy one element) per work unit: a work unit is about
the time the interpreter takes for one expression node, and C does about this many element operations in it."""
MAKE_OPS = 4
"""Element operations of making one new element in C (an int of a range, a tuple of zip, a hashed set slot)."""
CHARS_PER_UNIT = 512
"""Characters C copies, searches or writes per work unit (memcpy-like loops run at about a character a ns)."""
WALK_OPS_PER_ELEMENT = 2
"""Element operations one element of a weighed value costs (the walk looks at each element's type in C)."""
WALK_OPS_PER_CONTAINER = OPS_PER_UNIT
"""Element operations each container met by the walk costs: one step of the walk in Python."""
CLOCK_EVERY_UNITS = 256
"""Work units between two readings of the clock (a few hundred microseconds of interpretation)."""
SLOT_BYTES = 9
"""Bytes one more element of a list takes (an 8-byte pointer plus over-allocation)."""
_STR_CHARS_PER_NODE = 64
"""A string weighs one node per this many characters (comparing or hashing it walks them all)."""

_DICT_VIEWS = (type({}.keys()), type({}.values()), type({}.items()))
_CONTAINERS = frozenset({list, tuple, dict, set, frozenset, *_DICT_VIEWS})


class LimitReached(Exception):
    """A Budget limit was passed; the interpreter turns it into a BudgetError at the line being run."""

    def __init__(self, limit: str, message: str):
        super().__init__(message)
        self.limit = limit
        self.message = message


def scalar_weight(value: Any) -> int:
    """Nodes a comparison or hash of a value that is not a container walks (integers are at most
    ``max_int_bits`` wide, a few hundred bytes compared in one step)."""
    if type(value) is str:
        return 1 + len(value) // _STR_CHARS_PER_NODE
    return 1


class Meter:
    """The counters of one run against its :class:`Budget`; raises :class:`LimitReached` when one is passed.

    The interpreter's hot path increments ``work`` itself and calls :meth:`check`
    when it reaches ``alarm``; everything else pays through :meth:`spend`,
    :meth:`spend_ops`, :meth:`spend_chars` and :meth:`allocate`.
    """

    __slots__ = (
        "budget", "max_work", "max_steps", "max_memory", "steps", "work", "memory", "alarm", "deadline", "clock"
    )  # fmt: skip

    def __init__(self, budget: Budget):
        self.budget = budget
        self.max_work = budget.max_work
        self.max_steps = budget.max_steps
        self.max_memory = budget.max_alloc_bytes
        self.steps = 0
        self.work = 0
        self.memory = 0
        self.clock = budget.clock
        self.deadline = math.inf
        self.alarm = 0
        """The work count at which :meth:`check` runs next."""

    def start(self) -> None:
        """Start the clock; call once, right before the program's first statement."""
        self.deadline = self.clock() + self.budget.max_seconds
        self.alarm = min(self.work + CLOCK_EVERY_UNITS, self.max_work + 1)

    # ---- work --------------------------------------------------------------------------------

    def check(self) -> None:
        """Refuse to go on past the work budget or the deadline; schedule the next check."""
        if self.work > self.max_work:
            raise self.out_of_work()
        if self.clock() > self.deadline:
            raise LimitReached(
                "max_seconds",
                f"the program ran longer than {self.budget.max_seconds:g} s; does a loop never end or do too "
                "much work?",
            )
        self.alarm = min(self.work + CLOCK_EVERY_UNITS, self.max_work + 1)

    def spend(self, units: int) -> None:
        """Pay ``units`` of work before doing it; :class:`LimitReached` (and nothing done) if they do not fit."""
        work = self.work + units
        if work > self.max_work:
            raise self.out_of_work()
        self.work = work
        if work >= self.alarm:
            self.check()

    def spend_ops(self, ops: int) -> None:
        """Pay for ``ops`` element operations of builtin (C) work."""
        self.spend(1 + ops // OPS_PER_UNIT)

    def spend_chars(self, chars: int) -> None:
        """Pay for copying, searching or writing ``chars`` characters."""
        self.spend(1 + chars // CHARS_PER_UNIT)

    def step(self) -> None:
        """Count one step (a statement, loop iteration, comprehension element or call) and its work."""
        self.steps += 1
        if self.steps > self.max_steps:
            raise LimitReached(
                "max_steps",
                f"the program ran more than {self.max_steps} steps (statements, loop iterations and calls); "
                "does a loop never end? A robot task needs far fewer steps",
            )
        self.work += 1
        if self.work >= self.alarm:
            self.check()

    def out_of_work(self) -> LimitReached:
        return LimitReached(
            "max_work",
            f"the program did more than {self.max_work} units of work (expressions evaluated and elements "
            "compared, copied, sorted or printed); keep loops short and data small",
        )

    # ---- memory ------------------------------------------------------------------------------

    def allocate(self, nbytes: int) -> None:
        """Count ``nbytes`` of new values; :class:`LimitReached` past the memory budget."""
        memory = self.memory + nbytes
        if memory > self.max_memory:
            raise LimitReached(
                "max_alloc_bytes",
                f"the program created more than {self.budget.max_alloc_bytes // 1_000_000} MB of values in "
                "total; keep lists, strings and numbers small",
            )
        self.memory = memory

    # ---- weights -----------------------------------------------------------------------------

    def weigh(self, value: Any, cap: int | None = None) -> int:
        """How many nodes an operation that walks ``value`` (compare, hash, sort) may visit; pays for the walk.

        Every element counts one node and a string one more per 64 characters;
        shared sub-values count every time they are reached, as the C code
        walks them. The walk stops as soon as the weight passes ``cap``
        (default ``max_nodes``) and returns that partial weight, above ``cap``.
        Data nested deeper than ``max_nesting`` raises :class:`LimitReached`:
        C would recurse that deep. The walk never does more work than the budget
        has left (it stops with ``max_work``).
        """
        if type(value) not in _CONTAINERS:
            return scalar_weight(value)
        cap = self.budget.max_nodes if cap is None else cap
        max_depth = self.budget.max_nesting
        affordable_ops = (self.max_work - self.work) * OPS_PER_UNIT
        weight = 0
        visited = 0
        containers = 0
        stack: list[tuple[Any, int]] = [(value, 0)]
        while stack and weight <= cap:
            v, depth = stack.pop()
            if depth >= max_depth:
                self.spend_ops(WALK_OPS_PER_ELEMENT * visited + WALK_OPS_PER_CONTAINER * containers)
                raise self.too_deep()
            if WALK_OPS_PER_ELEMENT * visited + WALK_OPS_PER_CONTAINER * containers > affordable_ops:
                raise self.out_of_work()
            elements: Any = [*v.keys(), *v.values()] if type(v) is dict else v
            containers += 1
            visited += len(elements)
            weight += 1 + len(elements)
            kinds = set(map(type, elements))
            if str in kinds:
                weight += sum(len(x) for x in elements if type(x) is str) // _STR_CHARS_PER_NODE
            if not kinds.isdisjoint(_CONTAINERS):
                stack.extend((x, depth + 1) for x in elements if type(x) in _CONTAINERS)
        self.spend_ops(WALK_OPS_PER_ELEMENT * visited + WALK_OPS_PER_CONTAINER * containers)
        return weight

    def weigh_bounded(self, value: Any) -> int:
        """:meth:`weigh`, refusing values heavier than ``max_nodes``."""
        weight = self.weigh(value)
        if weight > self.budget.max_nodes:
            raise self.too_large()
        return weight

    def too_deep(self) -> LimitReached:
        depth = self.budget.max_nesting
        return LimitReached(
            "max_nesting",
            f"this value is nested more than {depth} levels deep (lists inside lists, or a list that contains "
            "itself); keep data structures flat",
        )

    def too_large(self) -> LimitReached:
        return LimitReached(
            "max_nodes",
            f"this value is too large to compare, hash or print (more than {self.budget.max_nodes} nested "
            "elements; lists that share or contain themselves count every time); keep data structures small",
        )
