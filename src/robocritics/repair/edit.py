"""Program edits a repair proposes: statements inserted around a line, numbers replaced on a line.

Edits work on the source text at :mod:`ast` positions, so the rest of the
program (comments, blank lines, formatting) survives unchanged.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass, field

from ..errors import ProgramError

__all__ = ["Edit", "Insert", "ScaleNumbers", "apply_edits"]


def _statement_at(tree: ast.Module, line: int) -> ast.stmt:
    """The innermost simple statement that starts on ``line`` (1-based)."""
    best = None
    for node in ast.walk(tree):
        if isinstance(node, ast.stmt) and node.lineno == line and not hasattr(node, "body"):
            best = node
    if best is None:
        raise ProgramError(f"no statement starts on line {line} to edit", line=line)
    return best


@dataclass(frozen=True)
class Insert:
    """Insert ``before`` statements above line ``line`` and ``after`` statements below it, at its indentation."""

    line: int
    before: tuple[str, ...] = ()
    after: tuple[str, ...] = ()

    def apply(self, lines: list[str], tree: ast.Module) -> None:
        stmt = _statement_at(tree, self.line)
        indent = " " * stmt.col_offset
        end = stmt.end_lineno or stmt.lineno
        lines[end:end] = [indent + s + "\n" for s in self.after]
        lines[stmt.lineno - 1 : stmt.lineno - 1] = [indent + s + "\n" for s in self.before]


@dataclass(frozen=True)
class ScaleNumbers:
    """Multiply the positive float literals of the statement on ``line`` by ``factor`` (e.g. hover heights, m)."""

    line: int
    factor: float

    def apply(self, lines: list[str], tree: ast.Module) -> None:
        stmt = _statement_at(tree, self.line)
        consts = [
            n
            for n in ast.walk(stmt)
            if isinstance(n, ast.Constant) and type(n.value) is float and n.value > 0 and n.lineno == n.end_lineno
        ]
        for n in sorted(consts, key=lambda n: (n.lineno, n.col_offset), reverse=True):
            text = lines[n.lineno - 1]
            new = f"{round(n.value * self.factor, 4):g}"
            lines[n.lineno - 1] = text[: n.col_offset] + new + text[n.end_col_offset :]


@dataclass
class Edit:
    """One repair candidate from one critic: program operations plus what they change and why.

    ``ops`` are applied together; ``line`` is the program line the change is about.
    """

    critic: str
    line: int
    what: str
    why: str
    ops: list = field(default_factory=list)


def apply_edits(source: str, ops: list) -> str:
    """``source`` with ``ops`` applied.

    In-line replacements go first (they move no line), then insertions bottom-most
    line first, so every position read from the one parse stays valid.
    """
    tree = ast.parse(source)
    lines = source.splitlines(keepends=True)
    if lines and not lines[-1].endswith("\n"):
        lines[-1] += "\n"
    for op in sorted(ops, key=lambda o: (isinstance(o, Insert), -o.line)):
        op.apply(lines, tree)
    return "".join(lines)
