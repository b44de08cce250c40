"""The limits of one run of an untrusted program: how much work, memory, output and time it may use."""

from __future__ import annotations

import time
from dataclasses import dataclass, fields
from typing import Callable

__all__ = ["Budget"]


@dataclass(frozen=True)
class Budget:
    """Limits for one program run. Exceeding any of them raises :class:`ProgramError`.

    Defaults are generous for robot programs (a pick-and-place task is a few
    hundred steps) and small enough that a hostile program stops within a
    fraction of a second. Every limit but ``max_seconds`` counts work, so it
    stops a program at the same line on any machine; ``max_seconds`` is the
    backstop for work the counts miss, read from ``clock`` (inject a simulated
    clock to test it deterministically).
    """

    max_steps: int = 100_000
    """Executed statements + loop iterations + comprehension elements + function calls."""
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
    max_alloc: int = 2_000_000
    """Elements plus characters the program may create over the whole run."""
    max_int_bits: int = 4_096
    """Bit length of any integer (``2**4096`` is ~1234 digits)."""
    max_nodes: int = 200_000
    """Nested elements one comparison, hash or str() may walk (counts shared sub-lists each time)."""
    max_source_chars: int = 100_000
    """Length of the program source."""
    max_nesting: int = 100
    """Depth of the syntax tree (nested expressions/blocks)."""
    max_output_chars: int = 100_000
    """Total characters of ``print`` output."""
    clock: Callable[[], float] = time.perf_counter
    """Monotonic time in seconds that ``max_seconds`` is measured on: read once at the start and at every step."""

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "clock":
                if not callable(value):
                    raise ValueError(f"Budget.clock must be a callable returning seconds, got {value!r}")
            elif not isinstance(value, (int, float)) or isinstance(value, bool) or not value > 0:
                raise ValueError(f"Budget.{f.name} must be a positive number, got {value!r}")
