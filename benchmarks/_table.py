"""The report the loopback benchmarks print: a header naming the machine, a two-column table, the command line."""

from __future__ import annotations

import os
import platform
import sys


def print_table(script: str, what: str, rows: list[tuple[str, str]], argv: list[str] | None, rule: int = 40) -> None:
    """Print ``script — what, Python …, load average …``, ``rows`` between two rules ``rule`` dashes wider
    than the first column, and ``reproduce: .venv/bin/python benchmarks/<script>.py <argv>``."""
    w = max(len(a) for a, _ in rows)
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(
        f"{script} — {what}, Python {platform.python_version()}, "
        f"{platform.machine()}, {os.cpu_count()} CPUs, load average {load}"
    )
    print("-" * (w + rule))
    for a, b in rows:
        print(f"{a:<{w}}  {b}")
    print("-" * (w + rule))
    cmd = " ".join([f"benchmarks/{script}.py", *(sys.argv[1:] if argv is None else argv)])
    print(f"reproduce: .venv/bin/python {cmd}")
