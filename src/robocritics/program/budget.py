"""The limits of one run of an untrusted program: how much work, memory, output and time it may use."""

from __future__ import annotations

import time
from dataclasses import dataclass, fields
from typing import Callable

from ..errors import ProgramError

__all__ = ["Budget", "BudgetError"]


@dataclass(frozen=True)
class Budget:
    """Limits for one program run. Exceeding any of them raises :class:`BudgetError`.

    Defaults are generous for robot programs (a pick-and-place task is a few
    hundred steps) and small enough that a hostile program stops within a
    fraction of a second. Every limit but ``max_seconds`` counts work or sizes,
    so it stops a program at the same line on any machine; ``max_seconds`` is
    the backstop, read from ``clock`` (inject a simulated clock to test it
    deterministically).
    """

    max_steps: int = 100_000
    """Executed statements + loop iterations + comprehension elements + function calls."""
    max_work: int = 500_000
    """Work units: one per evaluated expression node or step, plus the work builtin operations do (comparing,
    hashing, sorting, copying, searching, printing) at one unit per ~32 elements or ~512 characters they touch."""
    max_skill_calls: int = 2_000
    """Recorded skill calls."""
    max_call_depth: int = 50
    """Nested user-function calls (recursion depth)."""
    max_seconds: float = 0.5
    """Time the run may take on ``clock``, s."""
    max_len: int = 10_000
    """Elements of one list/tuple/dict/set, or of any sequence materialised from an iterable (e.g. ``list(range(n))``)."""
    max_str_len: int = 100_000
    """Characters of one string."""
    max_alloc_bytes: int = 50_000_000
    """Bytes of all the values the program creates over the whole run (numbers, strings, containers, functions,
    call scopes), each counted when it is made and never given back."""
    max_int_bits: int = 4_096
    """Bit length of any integer (``2**4096`` is ~1234 digits)."""
    max_nodes: int = 200_000
    """Nested elements one comparison, hash or sort may walk (shared sub-lists count each time they are reached)."""
    max_source_chars: int = 100_000
    """Length of the program source."""
    max_nesting: int = 100
    """Depth of the syntax tree (nested expressions/blocks), and of nested data a comparison, hash or print walks."""
    max_output_chars: int = 100_000
    """Total characters of ``print`` output."""
    clock: Callable[[], float] = time.perf_counter
    """Monotonic time in seconds that ``max_seconds`` is measured on: read at the start and every few hundred
    work units (and before every long builtin operation)."""

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "clock":
                if not callable(value):
                    raise ValueError(f"Budget.clock must be a callable returning seconds, got {value!r}")
            elif not isinstance(value, (int, float)) or isinstance(value, bool) or not value > 0:
                raise ValueError(f"Budget.{f.name} must be a positive number, got {value!r}")


class BudgetError(ProgramError):
    """A program hit a :class:`Budget` limit. ``limit`` names the Budget field, e.g. ``"max_work"``."""

    def __init__(self, message: str, line: int = 0, col: int = 0, limit: str = ""):
        super().__init__(message, line, col)
        self.limit = limit

    def __reduce__(self) -> tuple:
        return (type(self), (self.reason, self.line, self.col, self.limit))
