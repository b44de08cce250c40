"""The static check of a robot program: parse it and reject everything outside the allowed subset.

Nothing of the program runs here. The check walks the syntax tree once,
iteratively (so deeply nested source cannot exhaust the stack), collects up to
:data:`_MAX_COLLECTED_PROBLEMS` problems, and raises one :class:`ProgramError`
naming the first, with the others listed. Names quoted from the source are
cut to :data:`~robocritics.program.render.VALUE_CHARS` characters, so a
100 000-character identifier gives a short message.
"""

from __future__ import annotations

import ast
from typing import Any

from ..errors import ProgramError
from .budget import Budget, BudgetError
from .language import MATH_NAMES
from .render import bounded_repr, clip
from .skills import SKILLS, _close_names

__all__ = ["parse_program", "Source", "quote"]

_MAX_COLLECTED_PROBLEMS = 20
"""The static check stops collecting after this many problems: more only slow down rejecting a hostile program."""
_MAX_LISTED_PROBLEMS = 9
"""Further problems listed under the first one: enough to fix several in one revision, short enough to read."""
_MAX_PROBLEM_CHARS = 300
"""Each listed problem is cut to this many characters."""

MODULE_ALIASES = {"math": "math", "lib": "lib", "robot_lib": "lib", "robocritics": "lib", "skills": "lib"}
_MODULE_HINTS = {
    "time": "to pause use wait(seconds)",
    "numpy": "use math and plain lists",
    "random": "robot programs must be deterministic",
    "os": "programs cannot touch the computer, only the robot",
    "sys": "programs cannot touch the computer, only the robot",
    "subprocess": "programs cannot touch the computer, only the robot",
}

FORBIDDEN_NAMES = {
    name: f"'{name}' is not available in robot programs"
    for name in (
        "eval exec compile open getattr setattr delattr hasattr globals locals vars type object super dir help "
        "input breakpoint exit quit memoryview bytearray bytes classmethod staticmethod property id iter next "
        "callable issubclass isinstance format frozenset map filter aiter anext importlib builtins"
    ).split()
}
FORBIDDEN_NAMES["isinstance"] = "'isinstance' is not available in robot programs; compare values directly"
FORBIDDEN_NAMES["format"] = "'format' is not available; use an f-string such as f\"{x:.2f}\""
FORBIDDEN_NAMES["map"] = "'map' is not available; use a list comprehension [f(x) for x in items]"
FORBIDDEN_NAMES["filter"] = "'filter' is not available; use a list comprehension [x for x in items if ...]"
FORBIDDEN_NAMES["getattr"] = "'getattr' is not available; read fields directly, e.g. green_apple.colour"
FORBIDDEN_NAMES["hasattr"] = "'hasattr' is not available; check obj.attributes, e.g. 'colour' in apple.attributes"

_REJECTED = {
    ast.ClassDef: "class definitions are not allowed; use functions, lists and dicts",
    ast.Try: "try/except is not allowed; check conditions with if instead",
    ast.Raise: "raise is not allowed; use if/else to handle special cases",
    ast.With: "'with' is not allowed in robot programs",
    ast.AsyncWith: "async code is not allowed",
    ast.AsyncFunctionDef: "async code is not allowed",
    ast.AsyncFor: "async code is not allowed",
    ast.Await: "async code is not allowed",
    ast.Yield: "generators (yield) are not allowed; build and return a list instead",
    ast.YieldFrom: "generators (yield) are not allowed; build and return a list instead",
    ast.Global: "'global' is not allowed; pass values as arguments and return results",
    ast.Nonlocal: "'nonlocal' is not allowed; pass values as arguments and return results",
    ast.NamedExpr: "the ':=' operator is not allowed; assign on a separate line",
    ast.MatMult: "the '@' operator is not supported",
}
if hasattr(ast, "TryStar"):
    _REJECTED[ast.TryStar] = _REJECTED[ast.Try]
if hasattr(ast, "Match"):
    _REJECTED[ast.Match] = "match statements are not allowed; use if/elif"

ALLOWED_NODES = {
    ast.Module, ast.Expr, ast.Assign, ast.AugAssign, ast.AnnAssign, ast.If, ast.For, ast.While, ast.Break,
    ast.Continue, ast.Pass, ast.FunctionDef, ast.Return, ast.Import, ast.ImportFrom, ast.alias, ast.Assert,
    ast.Delete, ast.BoolOp, ast.BinOp, ast.UnaryOp, ast.Lambda, ast.IfExp, ast.Dict, ast.Set, ast.ListComp,
    ast.SetComp, ast.DictComp, ast.GeneratorExp, ast.Compare, ast.Call, ast.keyword, ast.FormattedValue,
    ast.JoinedStr, ast.Constant, ast.Attribute, ast.Subscript, ast.Starred, ast.Name, ast.List, ast.Tuple,
    ast.Slice, ast.Load, ast.Store, ast.Del, ast.arguments, ast.arg, ast.comprehension,
    ast.And, ast.Or, ast.Add, ast.Sub, ast.Mult, ast.Div, ast.FloorDiv, ast.Mod, ast.Pow, ast.LShift,
    ast.RShift, ast.BitOr, ast.BitXor, ast.BitAnd, ast.UAdd, ast.USub, ast.Not, ast.Invert, ast.Eq,
    ast.NotEq, ast.Lt, ast.LtE, ast.Gt, ast.GtE, ast.Is, ast.IsNot, ast.In, ast.NotIn,
}  # fmt: skip


MATH_ALL = frozenset(MATH_NAMES)


def quote(name: str) -> str:
    """``repr(name)`` of a name from the program's source, cut for a message."""
    return bounded_repr(name)


def parse_program(source: str, budget: Budget | None = None) -> ast.Module:
    """Parse ``source`` and reject anything outside the allowed subset; return the syntax tree.

    Raises :class:`ProgramError` with the line and column of the first problem
    (further problems are listed in the message).
    """
    b = budget or Budget()
    if not isinstance(source, str):
        raise ProgramError(f"the program must be Python source text (str), got {type(source).__name__}")
    if len(source) > b.max_source_chars:
        raise BudgetError(
            f"the program is {len(source)} characters long; the limit is {b.max_source_chars}. Use loops and helper "
            "functions instead of repeating code",
            limit="max_source_chars",
        )
    try:
        tree = ast.parse(source, mode="exec")
    except SyntaxError as exc:
        raise ProgramError(f"syntax error: {exc.msg}", exc.lineno or 0, exc.offset or 0) from None
    except (RecursionError, MemoryError):
        raise BudgetError(
            "the program nests too deeply for the parser; split long expressions into several statements",
            limit="max_nesting",
        ) from None
    except ValueError as exc:  # e.g. null bytes
        raise ProgramError(f"the program cannot be parsed: {exc}") from None
    _Checker(source, b).check(tree)
    return tree


class Source:
    """Converts AST byte offsets into 1-based character columns."""

    def __init__(self, source: str):
        self.lines = source.splitlines()

    def col(self, line: int, offset: int | None) -> int:
        if offset is None or line <= 0:
            return 0
        if 0 < line <= len(self.lines):
            text = self.lines[line - 1]
            if not text.isascii():
                return len(text.encode("utf-8")[:offset].decode("utf-8", errors="replace")) + 1
        return offset + 1


class _Checker:
    def __init__(self, source: str, budget: Budget):
        self.src = Source(source)
        self.budget = budget
        self.problems: list[tuple[int, int, str, str]] = []
        """(line, column, message, the Budget field of a limit problem or "")"""

    def add(self, node: Any, where: tuple[int, int], message: str, attr: str | None = None, limit: str = "") -> None:
        """Record a problem at ``node`` (or at ``where``, the line and byte offset of its nearest located parent)."""
        line = getattr(node, "lineno", None)
        if line is None:
            line, offset = where
            col = self.src.col(line, offset) if line else 0
        elif attr is not None and getattr(node, "end_lineno", None) is not None:
            line = node.end_lineno
            col = self.src.col(line, node.end_col_offset - len(attr.encode("utf-8")))
        else:
            col = self.src.col(line, node.col_offset)
        self.problems.append((line, col, clip(message, _MAX_PROBLEM_CHARS), limit))

    def check(self, tree: ast.Module) -> None:
        max_depth = self.budget.max_nesting
        # (node, depth, in_loop, in_func, parent, where)
        stack: list[tuple[Any, int, bool, bool, Any, tuple[int, int]]] = [(tree, 0, False, False, None, (0, 0))]
        while stack and len(self.problems) < _MAX_COLLECTED_PROBLEMS:
            node, depth, in_loop, in_func, parent, where = stack.pop()
            if hasattr(node, "lineno"):
                where = (node.lineno, node.col_offset)  # columns are computed only for problems
            if depth > max_depth:
                self.add(
                    node,
                    where,
                    f"the program nests more than {max_depth} levels deep; split long or deeply nested "
                    "expressions into several statements",
                    limit="max_nesting",
                )
                continue
            t = type(node)
            if t in _REJECTED:
                self.add(node, where, _REJECTED[t])
                continue
            if t not in ALLOWED_NODES:
                self.add(node, where, f"{t.__name__} is not allowed in robot programs")
                continue
            self._node(node, t, in_loop, in_func, parent, where)
            children: list[tuple[Any, int, bool, bool, Any, tuple[int, int]]] = []
            for fname, value in ast.iter_fields(node):
                c_loop, c_func = in_loop, in_func
                if t in (ast.FunctionDef, ast.Lambda) and fname == "body":
                    c_loop, c_func = False, True
                elif t in (ast.For, ast.While) and fname == "body":
                    c_loop = True
                items = value if isinstance(value, list) else [value]
                for item in items:
                    if isinstance(item, ast.AST):
                        children.append((item, depth + 1, c_loop, c_func, node, where))
            stack.extend(reversed(children))
        if self.problems:
            self.problems.sort(key=lambda p: (p[0], p[1]))
            line, col, message, limit = self.problems[0]
            rest = self.problems[1:]
            if rest:
                message += "\nOther problems:" + "".join(
                    f"\n  line {ln}, column {c}: {m}" for ln, c, m, _ in rest[:_MAX_LISTED_PROBLEMS]
                )
                if len(rest) > _MAX_LISTED_PROBLEMS:
                    message += f"\n  ... and {len(rest) - _MAX_LISTED_PROBLEMS} more"
            if limit:
                raise BudgetError(clip(message), line, col, limit=limit)
            raise ProgramError(clip(message), line, col)

    def _node(self, node: Any, t: type, in_loop: bool, in_func: bool, parent: Any, where: tuple[int, int]) -> None:
        add = self.add
        if t is ast.Name:
            if node.id.startswith("_"):
                add(node, where, f"name {quote(node.id)} is not allowed: names starting with '_' are reserved")
            elif node.id in FORBIDDEN_NAMES:
                add(node, where, FORBIDDEN_NAMES[node.id] + "; the program can only use the skill API and math")
        elif t is ast.Attribute:
            if node.attr.startswith("_"):
                add(
                    node,
                    where,
                    f"attribute {quote(node.attr)} is not allowed: names starting with '_' reach Python internals; "
                    "programs can only use the skill API (lib.move_to, ...), math and object fields",
                    attr=node.attr,
                )
            elif not isinstance(node.ctx, ast.Load):
                verb = "assign to" if isinstance(node.ctx, ast.Store) else "delete"
                add(
                    node,
                    where,
                    f"cannot {verb} attribute {quote(node.attr)}: scene objects, lib and math are read-only; "
                    "use your own variables (and skills to move things)",
                    attr=node.attr,
                )
        elif t is ast.FunctionDef:
            if node.name.startswith("_"):
                add(node, where, f"function name {quote(node.name)} is not allowed: names starting with '_' are reserved")
            if node.name in FORBIDDEN_NAMES:
                add(node, where, f"cannot define a function named {quote(node.name)}; choose another name")
            if node.decorator_list:
                add(node.decorator_list[0], where, "decorators are not allowed")
        elif t is ast.arguments:
            if node.posonlyargs:
                add(node.posonlyargs[0], where, "positional-only parameters ('/') are not allowed")
            if node.vararg is not None:
                add(node.vararg, where, "'*args' parameters are not allowed; pass a list instead")
            if node.kwarg is not None:
                add(node.kwarg, where, "'**kwargs' parameters are not allowed; use named parameters with defaults")
        elif t is ast.arg:
            if node.arg.startswith("_"):
                add(node, where, f"parameter name {quote(node.arg)} is not allowed: names starting with '_' are reserved")
        elif t is ast.keyword:
            if node.arg is None:
                add(node, where, "'**' unpacking in calls is not allowed; pass keyword arguments by name")
            elif node.arg.startswith("_"):
                add(node, where, f"keyword {quote(node.arg)} is not allowed: names starting with '_' are reserved")
        elif t is ast.Import:
            for alias in node.names:
                self._module(alias, alias.name, where)
                if alias.asname and alias.asname.startswith("_"):
                    add(alias, where, f"name {quote(alias.asname)} is not allowed: names starting with '_' are reserved")
        elif t is ast.ImportFrom:
            module = node.module or ""
            if node.level:
                add(node, where, "relative imports are not allowed; use 'import math' or 'import lib'")
                return
            if not self._module(node, module, where):
                return
            members = MATH_ALL if MODULE_ALIASES[module] == "math" else frozenset(SKILLS)
            for alias in node.names:
                if alias.name == "*":
                    add(node, where, f"'from {module} import *' is not allowed; import the names you need")
                elif alias.name not in members:
                    hint = _close_names(alias.name, members)
                    add(
                        alias,
                        where,
                        f"cannot import {quote(alias.name)} from {module}{hint or '.'} "
                        f"{module} provides: {', '.join(sorted(members))}",
                    )
                if alias.asname and alias.asname.startswith("_"):
                    add(alias, where, f"name {quote(alias.asname)} is not allowed: names starting with '_' are reserved")
        elif t is ast.Constant:
            v = node.value
            if isinstance(v, bytes):
                add(node, where, "bytes literals are not allowed; use str")
            elif type(v) is int and v.bit_length() > self.budget.max_int_bits:
                add(node, where, f"integer literal too large (more than {self.budget.max_int_bits} bits)")
        elif t is ast.Starred:
            if not isinstance(parent, (ast.Call, ast.List, ast.Tuple, ast.Set)):
                add(node, where, "'*' unpacking is only allowed in calls, list/tuple/set displays and assignments")
        elif t is ast.Dict:
            if any(k is None for k in node.keys):
                add(node, where, "'**' unpacking in dict displays is not allowed; use d.update(other)")
        elif t is ast.comprehension:
            if node.is_async:
                add(node.target, where, "async comprehensions are not allowed")
        elif t is ast.Break or t is ast.Continue:
            if not in_loop:
                add(node, where, f"'{t.__name__.lower()}' outside a loop")
        elif t is ast.Return:
            if not in_func:
                add(node, where, "'return' outside a function; a program simply ends at its last line")
        elif t is ast.Delete:
            for target in node.targets:
                if not isinstance(target, (ast.Name, ast.Subscript, ast.Tuple, ast.List, ast.Attribute)):
                    add(target, where, "only names and items can be deleted")

    def _module(self, node: Any, name: str, where: tuple[int, int]) -> bool:
        if name in MODULE_ALIASES:
            return True
        top = name.split(".")[0]
        hint = _MODULE_HINTS.get(top)
        self.add(
            node,
            where,
            f"import of {quote(name)} is not allowed; the program can only use the skill API (lib.move_to, ...) and math"
            + (f" ({hint})" if hint else "")
            + "; available modules: math, lib",
        )
        return False


