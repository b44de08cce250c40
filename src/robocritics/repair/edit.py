"""Program edits a repair proposes: statements inserted around a line, numbers replaced on a line.

Edits work on the source text at :mod:`ast` positions, so the rest of the
program (comments, blank lines, formatting) survives unchanged.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass, field

from ..errors import ProgramError

__all__ = ["Edit", "Insert", "InsertText", "ReplaceSpan", "ScaleNumbers", "MoveBlock", "ReplaceText", "apply_edits", "paragraphs"]


def _statement_at(tree: ast.Module, line: int) -> ast.stmt:
    """The innermost simple statement that starts on ``line`` (1-based), else the compound one (``for``...)."""
    best = compound = None
    for node in ast.walk(tree):
        if isinstance(node, ast.stmt) and node.lineno == line:
            if not hasattr(node, "body"):
                best = node
            elif compound is None:  # a loop or def header: its outermost statement
                compound = node
    best = best or compound
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
class ReplaceText:
    """Replace ``old`` by ``new`` in the text of line ``line`` (every occurrence; the line count is unchanged)."""

    line: int
    old: str
    new: str
    inline = True

    def apply(self, lines: list[str], tree: ast.Module) -> None:
        lines[self.line - 1] = lines[self.line - 1].replace(self.old, self.new)


@dataclass(frozen=True)
class ReplaceSpan:
    """Replace columns ``col..end_col`` of line ``line`` (:mod:`ast` columns: UTF-8 bytes) by ``text``, e.g. one argument."""

    line: int
    col: int
    end_col: int
    text: str
    inline = True

    def apply(self, lines: list[str], tree: ast.Module) -> None:
        raw = lines[self.line - 1].encode()
        lines[self.line - 1] = (raw[: self.col] + self.text.encode() + raw[self.end_col :]).decode()


def InsertText(line: int, col: int, text: str) -> ReplaceSpan:  # noqa: N802 - used as the edit type it builds
    """Insert ``text`` into line ``line`` before column ``col`` (an :mod:`ast` column: UTF-8 bytes from the line
    start): the empty span ``col..col`` replaced."""
    return ReplaceSpan(line, col, col, text)


@dataclass(frozen=True)
class ScaleNumbers:
    """Multiply the positive float literals of the statement on ``line`` by ``factor`` (e.g. hover heights, m)."""

    line: int
    factor: float
    inline = True

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


def paragraphs(source: str) -> list[tuple[int, int]]:
    """The top-level statement groups separated by blank lines, as ``(first, last)`` lines (1-based)."""
    tree = ast.parse(source)
    text = source.splitlines()
    groups: list[list[int]] = []
    for stmt in tree.body:
        first, last = stmt.lineno, stmt.end_lineno or stmt.lineno
        if groups and not any(not line.strip() for line in text[groups[-1][1] : first - 1]):
            groups[-1][1] = last
        else:
            groups.append([first, last])
    return [(a, b) for a, b in groups]


@dataclass(frozen=True)
class MoveBlock:
    """Move the top-level lines ``first..last`` (a paragraph, with a blank line after it) above line ``line``."""

    line: int
    first: int
    last: int

    def apply(self, lines: list[str], tree: ast.Module) -> None:
        block = lines[self.first - 1 : self.last]
        if not block[-1].strip() == "":
            block = [*block, "\n"]
        del lines[self.first - 1 : self.last]
        if 0 < self.first - 1 < len(lines) and not lines[self.first - 2].strip() and not lines[self.first - 1].strip():
            del lines[self.first - 1]  # the blank line that separated the moved paragraph
        while len(lines) > 1 and not lines[-1].strip():
            del lines[-1]  # the program still ends at its last statement
        lines[self.line - 1 : self.line - 1] = block


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

    In-line replacements go first (they move no line; right-most first within a line),
    then insertions bottom-most line first, so every position read from the one parse
    stays valid.
    """
    tree = ast.parse(source)
    lines = source.splitlines(keepends=True)
    if lines and not lines[-1].endswith("\n"):
        lines[-1] += "\n"
    for op in sorted(ops, key=lambda o: (not getattr(o, "inline", False), -o.line, -getattr(o, "col", 0))):
        op.apply(lines, tree)
    return "".join(lines)
