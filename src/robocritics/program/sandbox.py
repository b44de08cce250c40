"""Static validation and restricted execution of untrusted, LLM-written robot programs.

Design: an AST interpreter
--------------------------
The program is parsed with :mod:`ast`, checked against a whitelist of node
types (:func:`check_program`), and then *interpreted* node by node by
:class:`_Interpreter`. It is never compiled to bytecode and never ``exec``'d,
so the program never touches real builtins, real modules, frames or code
objects. We chose this over "compile after rewriting every attribute access
through a guard" because

* the whole attack surface is the interpreter's own dispatch: a name resolves
  only through the program's scopes and a fixed table of safe builtins, skills,
  ``lib``, ``math`` and the scene objects; an attribute resolves only through an
  explicit table (skill namespace members, ``math`` members, :class:`ObjectView`
  fields, a short list of list/dict/set/str/tuple methods). ``str.format``,
  ``__class__`` and friends are simply not in any table;
* every budget is enforced where work happens: each statement, loop iteration,
  comprehension element and function call is a step (checked against the step
  budget and the wall-clock deadline); sizes are checked *before* allocating
  (``range(10**9)`` materialised, ``[0] * 10**9``, ``"a" * 10**10``,
  ``2 ** 10 ** 10``, ``1 << 10**9``, huge joins/replaces); operations whose C
  implementation walks nested data (``==``, ``<``, ``in``, hashing, ``sorted``,
  ``str``) first weigh the data so shared sub-lists cannot make one operation
  exponential; the total of all elements and characters the program creates is
  capped too;
* runtime errors are caught at the node that raised them, so every error
  carries the line and column of the offending expression.

The price is speed (a few microseconds per node), irrelevant for robot
programs of a few hundred steps. The interpreter recurses in Python for nested
calls and expressions; while a program runs, the recursion limit is raised (if
lower) to the current depth + ``_RECURSION_HEADROOM_FRAMES`` and restored afterwards, and a
``RecursionError`` still becomes a :class:`ProgramError`. Runs are independent
(each has its own interpreter and scopes) and may happen in several threads.

What programs may use
---------------------
Statements: expressions, ``=`` (incl. tuple unpacking and ``*rest``), augmented
assignment, annotated assignment, ``if``/``elif``/``else``, ``for``/``while``
(with ``else``), ``break``, ``continue``, ``pass``, ``def`` (no decorators, no
``*args``/``**kwargs``; keyword-only parameters and defaults are fine; nested
functions see enclosing variables), ``return``, ``assert``, ``del`` of names and
items, ``import math`` / ``from math import ...`` and ``import lib`` (also
``robot_lib``, ``robocritics``, ``skills``: all name the skill namespace).
Expressions: literals, arithmetic, comparisons, boolean operators, conditional
expressions, ``lambda``, list/dict/set comprehensions and generator expressions
(evaluated eagerly to a list), subscripts and slices, f-strings (format specs
like ``{x:.2f}`` work; ``str.format`` and ``%`` formatting do not exist), calls.
Builtins, methods and ``math`` members: exactly those of
:mod:`robocritics.program.language` (``SAFE_BUILTINS``, ``SAFE_METHODS``,
``MATH_NAMES``), the one list shared with the LLM prompt and the docs.

Not available (rejected before running, with the line and a fix hint): other
imports, names or attributes starting with ``_``, ``class``, ``try``,
``raise``, ``with``, ``async``/``await``, ``yield``, ``global``/``nonlocal``,
``match``, ``:=``, ``@``, attribute assignment, ``**`` in calls and dicts,
``eval``/``exec``/``open``/``getattr``/``type``/``globals``/... .
"""

from __future__ import annotations

import ast
import inspect
import math
import operator
import re
import sys
from typing import Any, Callable, Iterator

from ..errors import ProgramError
from ..scene import Scene
from . import skills as _skills
from .budget import Budget
from .language import MATH_NAMES, SAFE_BUILTINS, SAFE_METHODS
from .plan import Plan
from .skills import SKILLS, Namespace, ObjectView, Recorder, _CURRENT, _suggest

__all__ = ["Budget", "run_program", "check_program"]


# --------------------------------------------------------------------------------------
# tables

_RECURSION_HEADROOM_FRAMES = 4_000
"""Python frames a run may add: max_call_depth calls x a few frames per call, each with expressions
nested up to max_nesting deep at a few frames per node, fit with room to spare."""
_MAX_COLLECTED_PROBLEMS = 20
"""The static check stops collecting after this many problems: more only slow down rejecting a hostile program."""
_MAX_LISTED_PROBLEMS = 9
"""Further problems listed under the first one: enough to fix several in one revision, short enough to read."""
_STR_CHARS_PER_NODE = 64
"""Weighing counts a string as one node per this many characters (comparing or hashing it walks them all)."""
_SCALAR_REPR_CHARS = 24
"""Upper estimate of the printed length of a float or other scalar (the longest float repr is 24 characters)."""
_MAX_FORMAT_WIDTH = 1_000
"""Largest width or precision in an f-string format spec: a wider field is only padding, built in C uncounted."""
_MAX_ROUND_DIGITS = 400
"""Largest ``abs(ndigits)`` of round(): more digits than a float has (308 + 17) change nothing but cost big-int work."""
_MAX_KEYS_SHOWN = 20
"""Keys listed in a KeyError message."""
_QUOTED_VALUE_CHARS = 60
"""Values quoted in error messages are cut to this length so the message stays readable."""
_QUOTED_INT_BITS = 64
"""Integers wider than this are quoted in error messages by their bit length, not their digits."""

_MODULE_ALIASES = {"math": "math", "lib": "lib", "robot_lib": "lib", "robocritics": "lib", "skills": "lib"}
_MODULE_HINTS = {
    "time": "to pause use wait(seconds)",
    "numpy": "use math and plain lists",
    "random": "robot programs must be deterministic",
    "os": "programs cannot touch the computer, only the robot",
    "sys": "programs cannot touch the computer, only the robot",
    "subprocess": "programs cannot touch the computer, only the robot",
}

_FORBIDDEN_NAMES = {
    name: f"'{name}' is not available in robot programs"
    for name in (
        "eval exec compile open getattr setattr delattr hasattr globals locals vars type object super dir help "
        "input breakpoint exit quit memoryview bytearray bytes classmethod staticmethod property id iter next "
        "callable issubclass isinstance format frozenset map filter aiter anext importlib builtins"
    ).split()
}
_FORBIDDEN_NAMES["isinstance"] = "'isinstance' is not available in robot programs; compare values directly"
_FORBIDDEN_NAMES["format"] = "'format' is not available; use an f-string such as f\"{x:.2f}\""
_FORBIDDEN_NAMES["map"] = "'map' is not available; use a list comprehension [f(x) for x in items]"
_FORBIDDEN_NAMES["filter"] = "'filter' is not available; use a list comprehension [x for x in items if ...]"
_FORBIDDEN_NAMES["getattr"] = "'getattr' is not available; read fields directly, e.g. green_apple.colour"
_FORBIDDEN_NAMES["hasattr"] = "'hasattr' is not available; check obj.attributes, e.g. 'colour' in apple.attributes"

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

_ALLOWED_NODES = {
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

_METHODS: dict[type, frozenset[str]] = {t: frozenset(names) for t, names in SAFE_METHODS.items()}

# math functions whose C versions would iterate without limits: the interpreter implements them (_m_<name>)
_MATH_WRAPPED = ("fsum", "prod", "dist")
_MATH_ALL = frozenset(MATH_NAMES)

_NoneType = type(None)
_SCALARS = frozenset({int, float, bool, complex, str, _NoneType, type(Ellipsis)})
_SEQS = (list, tuple, str)
_DICT_VIEWS = (type({}.keys()), type({}.values()), type({}.items()))
_SIZED = frozenset({list, tuple, str, dict, set, frozenset, range, *_DICT_VIEWS})
_ITERATORS = frozenset(
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
_ITERABLE = _SIZED | _ITERATORS
_DEEP = frozenset({list, tuple, dict, set, frozenset, str, *_DICT_VIEWS})
_HASH_DEEP = (tuple, frozenset)


# --------------------------------------------------------------------------------------
# static check


def check_program(source: str, budget: Budget | None = None) -> ast.Module:
    """Parse ``source`` and reject anything outside the allowed subset; return the syntax tree.

    Raises :class:`ProgramError` with the line and column of the first problem
    (further problems are listed in the message).
    """
    b = budget or Budget()
    if not isinstance(source, str):
        raise ProgramError(f"the program must be Python source text (str), got {type(source).__name__}")
    if len(source) > b.max_source_chars:
        raise ProgramError(
            f"the program is {len(source)} characters long; the limit is {b.max_source_chars}. Use loops and helper "
            "functions instead of repeating code"
        )
    try:
        tree = ast.parse(source, mode="exec")
    except SyntaxError as exc:
        raise ProgramError(f"syntax error: {exc.msg}", exc.lineno or 0, exc.offset or 0) from None
    except (RecursionError, MemoryError):
        raise ProgramError(
            "the program nests too deeply for the parser; split long expressions into several statements"
        ) from None
    except ValueError as exc:  # e.g. null bytes
        raise ProgramError(f"the program cannot be parsed: {exc}") from None
    _Checker(source, b).check(tree)
    return tree


class _Source:
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
        self.src = _Source(source)
        self.budget = budget
        self.problems: list[tuple[int, int, str]] = []

    def add(self, node: Any, where: tuple[int, int], message: str, attr: str | None = None) -> None:
        line = getattr(node, "lineno", None)
        if line is None:
            line, col = where
        elif attr is not None and getattr(node, "end_lineno", None) is not None:
            line = node.end_lineno
            col = self.src.col(line, node.end_col_offset - len(attr.encode("utf-8")))
        else:
            col = self.src.col(line, node.col_offset)
        self.problems.append((line, col, message))

    def check(self, tree: ast.Module) -> None:
        max_depth = self.budget.max_nesting
        # (node, depth, in_loop, in_func, parent, where)
        stack: list[tuple[Any, int, bool, bool, Any, tuple[int, int]]] = [(tree, 0, False, False, None, (0, 0))]
        while stack and len(self.problems) < _MAX_COLLECTED_PROBLEMS:
            node, depth, in_loop, in_func, parent, where = stack.pop()
            if hasattr(node, "lineno"):
                where = (node.lineno, self.src.col(node.lineno, node.col_offset))
            if depth > max_depth:
                self.add(
                    node,
                    where,
                    f"the program nests more than {max_depth} levels deep; split long or deeply nested "
                    "expressions into several statements",
                )
                continue
            t = type(node)
            if t in _REJECTED:
                self.add(node, where, _REJECTED[t])
                continue
            if t not in _ALLOWED_NODES:
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
            line, col, message = self.problems[0]
            rest = self.problems[1:]
            if rest:
                message += "\nOther problems:" + "".join(
                    f"\n  line {ln}, column {c}: {m}" for ln, c, m in rest[:_MAX_LISTED_PROBLEMS]
                )
                if len(rest) > _MAX_LISTED_PROBLEMS:
                    message += f"\n  ... and {len(rest) - _MAX_LISTED_PROBLEMS} more"
            raise ProgramError(message, line, col)

    def _node(self, node: Any, t: type, in_loop: bool, in_func: bool, parent: Any, where: tuple[int, int]) -> None:
        add = self.add
        if t is ast.Name:
            if node.id.startswith("_"):
                add(node, where, f"name {node.id!r} is not allowed: names starting with '_' are reserved")
            elif node.id in _FORBIDDEN_NAMES:
                add(node, where, _FORBIDDEN_NAMES[node.id] + "; the program can only use the skill API and math")
        elif t is ast.Attribute:
            if node.attr.startswith("_"):
                add(
                    node,
                    where,
                    f"attribute {node.attr!r} is not allowed: names starting with '_' reach Python internals; "
                    "programs can only use the skill API (lib.move_to, ...), math and object fields",
                    attr=node.attr,
                )
            elif not isinstance(node.ctx, ast.Load):
                verb = "assign to" if isinstance(node.ctx, ast.Store) else "delete"
                add(
                    node,
                    where,
                    f"cannot {verb} attribute '{node.attr}': scene objects, lib and math are read-only; "
                    "use your own variables (and skills to move things)",
                    attr=node.attr,
                )
        elif t is ast.FunctionDef:
            if node.name.startswith("_"):
                add(node, where, f"function name {node.name!r} is not allowed: names starting with '_' are reserved")
            if node.name in _FORBIDDEN_NAMES:
                add(node, where, f"cannot define a function named {node.name!r}; choose another name")
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
                add(node, where, f"parameter name {node.arg!r} is not allowed: names starting with '_' are reserved")
        elif t is ast.keyword:
            if node.arg is None:
                add(node, where, "'**' unpacking in calls is not allowed; pass keyword arguments by name")
            elif node.arg.startswith("_"):
                add(node, where, f"keyword {node.arg!r} is not allowed: names starting with '_' are reserved")
        elif t is ast.Import:
            for alias in node.names:
                self._module(alias, alias.name, where)
                if alias.asname and alias.asname.startswith("_"):
                    add(alias, where, f"name {alias.asname!r} is not allowed: names starting with '_' are reserved")
        elif t is ast.ImportFrom:
            module = node.module or ""
            if node.level:
                add(node, where, "relative imports are not allowed; use 'import math' or 'import lib'")
                return
            if not self._module(node, module, where):
                return
            members = _MATH_ALL if _MODULE_ALIASES[module] == "math" else frozenset(SKILLS)
            for alias in node.names:
                if alias.name == "*":
                    add(node, where, f"'from {module} import *' is not allowed; import the names you need")
                elif alias.name not in members:
                    hint = _suggest(alias.name, members)
                    add(
                        alias,
                        where,
                        f"cannot import {alias.name!r} from {module}{hint or '.'} "
                        f"{module} provides: {', '.join(sorted(members))}",
                    )
                if alias.asname and alias.asname.startswith("_"):
                    add(alias, where, f"name {alias.asname!r} is not allowed: names starting with '_' are reserved")
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
        if name in _MODULE_ALIASES:
            return True
        top = name.split(".")[0]
        hint = _MODULE_HINTS.get(top)
        self.add(
            node,
            where,
            f"import of {name!r} is not allowed; the program can only use the skill API (lib.move_to, ...) and math"
            + (f" ({hint})" if hint else "")
            + "; available modules: math, lib",
        )
        return False


# --------------------------------------------------------------------------------------
# runtime values


class _Signal(BaseException):
    """Control flow (break/continue/return); never caught by error conversion."""


class _Break(_Signal):
    pass


class _Continue(_Signal):
    pass


class _Return(_Signal):
    def __init__(self, value: Any):
        self.value = value


class _Scope:
    __slots__ = ("vars", "locals", "parent", "fname")

    def __init__(self, vars: dict, locals: frozenset | None, parent: "_Scope | None", fname: str):
        self.vars = vars
        self.locals = locals  # None for the module scope (everything assigned there is global)
        self.parent = parent
        self.fname = fname


class _SandboxFunction:
    """A function defined by the program (``def`` or ``lambda``)."""

    __slots__ = ("name", "params", "kwonly", "defaults", "closure", "locals", "body", "is_lambda", "interp")

    def __init__(self, name, params, kwonly, defaults, closure, locals_, body, is_lambda, interp):
        self.name = name
        self.params = params
        self.kwonly = kwonly
        self.defaults = defaults
        self.closure = closure
        self.locals = locals_
        self.body = body
        self.is_lambda = is_lambda
        self.interp = interp

    def __call__(self, *args: Any, **kwargs: Any) -> Any:  # called back from sorted(key=...), min, max
        return self.interp._invoke(self, args, kwargs, self.interp._call_node)

    def __repr__(self) -> str:
        return f"<function {self.name}>"


class _Builtin:
    """A builtin, skill or math function as the program sees it."""

    __slots__ = ("name", "fn", "kind", "sig", "interp")

    def __init__(self, name: str, fn: Callable, kind: str, interp: "_Interpreter", bind: bool = True):
        self.name = name
        self.fn = fn
        self.kind = kind
        self.interp = interp
        self.sig = _signature(fn) if bind else None

    @property
    def usage(self) -> str:
        """How to call it, for error messages."""
        if self.kind == "skill" or self.name == "print":
            return _skills.usage(self.name)
        if self.sig is not None:
            return f"{self.name}{self.sig}".replace("=<no value>", "")
        return ""

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return self.interp._call_builtin(self, args, kwargs)

    def __repr__(self) -> str:
        return f"<skill {self.name}>" if self.kind == "skill" else f"<built-in function {self.name}>"


class _Method:
    __slots__ = ("obj", "name", "interp")

    def __init__(self, obj: Any, name: str, interp: "_Interpreter"):
        self.obj = obj
        self.name = name
        self.interp = interp

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return self.interp._call_method(self.obj, self.name, args, kwargs)

    def __repr__(self) -> str:
        return f"<method {type(self.obj).__name__}.{self.name}>"


class _NoValue:
    def __repr__(self) -> str:
        return "<no value>"


_NOVALUE = _NoValue()
_MISSING = object()

_TYPE_NAMES: dict[type, str] = {
    ObjectView: "scene object",
    _SandboxFunction: "function",
    _Builtin: "builtin function",
    _Method: "method",
    Namespace: "module",
}
"""What a program is told the sandbox's own types are called."""
_CLEAN_NAMES = {t.__name__: name for t, name in (*_TYPE_NAMES.items(), (_NoValue, "value"))}
_INTERNAL_NAMES = re.compile(r"\b(" + "|".join(_CLEAN_NAMES) + r")\b")


def _tname(value: Any) -> str:
    return _TYPE_NAMES.get(type(value), type(value).__name__)


def _clean(message: str) -> str:
    return _INTERNAL_NAMES.sub(lambda m: _CLEAN_NAMES[m.group(1)], message)


# --------------------------------------------------------------------------------------
# the interpreter


class _Interpreter:
    def __init__(self, source: str, tree: ast.Module, scene: Scene, budget: Budget):
        self.tree = tree
        self.b = budget
        self.src = _Source(source)
        self.plan = Plan(source=source, calls=[], output=[])
        self.rec = Recorder(scene, self.plan, budget)
        self.steps = 0
        self.depth = 0
        self.alloc = 0
        self.clock = budget.clock
        self.deadline = 0.0
        self.call_lines: list[int] = []
        self.loops: list[Any] = []
        self._call_node: Any = None
        self._locals_cache: dict[int, frozenset] = {}
        self._exec_table = {t: getattr(self, "_exec_" + t.__name__) for t in _STMT_TYPES}
        self._eval_table = {t: getattr(self, "_eval_" + t.__name__) for t in _EXPR_TYPES}

        views = self.rec.views
        lib_members = {name: _Builtin(name, fn, "skill", self) for name, fn in SKILLS.items()}
        math_members: dict[str, Any] = {}
        for name in MATH_NAMES:
            if name in _MATH_WRAPPED:
                math_members[name] = _Builtin(name, getattr(self, "_m_" + name), "math", self)
                continue
            value = getattr(math, name)
            math_members[name] = _Builtin(name, value, "math", self, bind=False) if callable(value) else value
        self.modules = {
            "lib": Namespace("lib", lib_members, "skill"),
            "math": Namespace("math", math_members, "member"),
        }
        base: dict[str, Any] = {
            name: _Builtin(name, getattr(self, "_b_" + name), "builtin", self) for name in SAFE_BUILTINS
        }
        base.update(lib_members)
        base["lib"] = self.modules["lib"]
        base["math"] = self.modules["math"]
        base["objects"] = [v for v in views.values() if v._fields["kind"] == "object"]
        base["containers"] = [v for v in views.values() if v._fields["kind"] == "container"]
        base.update(views)
        self.base = base

    # ---- running ----------------------------------------------------------------------

    def run(self) -> Plan:
        token = _CURRENT.set(self.rec)
        old_limit = sys.getrecursionlimit()
        here = _frame_depth()
        wanted = here + _RECURSION_HEADROOM_FRAMES
        if old_limit < wanted:
            sys.setrecursionlimit(wanted)
        try:
            self.deadline = self.clock() + self.b.max_seconds
            module = _Scope({}, None, None, "<module>")
            self._exec_block(self.tree.body, module)
        except RecursionError:
            raise ProgramError("the program nests too deeply (deep recursion or nested expressions)") from None
        except MemoryError:
            raise ProgramError("the program ran out of memory; keep lists and strings small") from None
        finally:
            if old_limit < wanted:
                sys.setrecursionlimit(old_limit)
            _CURRENT.reset(token)
        return self.plan

    # ---- errors -----------------------------------------------------------------------

    def _pos(self, node: Any) -> tuple[int, int]:
        line = getattr(node, "lineno", 0) or 0
        return line, self.src.col(line, getattr(node, "col_offset", None))

    def _error(self, message: str, node: Any) -> ProgramError:
        line, col = self._pos(node)
        return ProgramError(message, line, col)

    def _attr_error(self, message: str, node: ast.Attribute) -> ProgramError:
        line = node.end_lineno or node.lineno
        col = self.src.col(line, (node.end_col_offset or 0) - len(node.attr.encode("utf-8")))
        return ProgramError(message, line, col)

    def _convert(self, exc: BaseException, node: Any) -> ProgramError:
        if isinstance(exc, RecursionError):
            return self._error(
                "the program nests too deeply (deep recursion or nested expressions); simplify it", node
            )
        if isinstance(exc, MemoryError):
            return self._error("the program ran out of memory; keep lists and strings small", node)
        text = _clean(str(exc))
        return self._error(f"{type(exc).__name__}: {text}" if text else type(exc).__name__, node)

    def _tick(self, node: Any) -> None:
        self.steps += 1
        if self.steps > self.b.max_steps:
            where = self.loops[-1] if self.loops else node
            raise self._error(
                f"the program ran more than {self.b.max_steps} steps (statements, loop iterations and calls); "
                "does a loop never end? A robot task needs far fewer steps",
                where,
            )
        if self.clock() > self.deadline:
            where = self.loops[-1] if self.loops else node
            raise self._error(
                f"the program ran longer than {self.b.max_seconds:g} s; does a loop never end or do too much work?",
                where,
            )

    def _alloc_n(self, n: int, node: Any) -> None:
        self.alloc += n
        if self.alloc > self.b.max_alloc:
            raise self._error(
                f"the program created more than {self.b.max_alloc} list elements and string characters in total; "
                "keep data small",
                node,
            )

    def _check_len(self, n: int, node: Any, what: str = "a list") -> None:
        self._grow(0, n, node, what)

    def _grow(self, current: int, add: int, node: Any, what: str = "a list") -> None:
        if current + add > self.b.max_len:
            raise self._error(f"{what} would have {current + add} elements; the limit is {self.b.max_len}", node)
        self._alloc_n(add, node)

    def _check_str(self, n: int, node: Any) -> None:
        if n > self.b.max_str_len:
            raise self._error(f"a string would have {n} characters; the limit is {self.b.max_str_len}", node)
        self._alloc_n(n, node)

    def _check_int(self, value: int, node: Any) -> None:
        if value.bit_length() > self.b.max_int_bits:
            raise self._error(
                f"integer too large (more than {self.b.max_int_bits} bits); robot programs need small numbers", node
            )

    def _check_result(self, value: Any, node: Any) -> Any:
        t = type(value)
        if t is int:
            if value.bit_length() > self.b.max_int_bits:
                self._check_int(value, node)
        elif t is str:
            if len(value) > self.b.max_str_len:
                self._check_str(len(value), node)
        elif t is list or t is tuple or t is set or t is dict:
            if len(value) > self.b.max_len:
                self._check_len(len(value), node)
        return value

    def _weigh(self, value: Any, node: Any, chars: bool = False) -> int:
        """Walk nested data; refuse it if an operation on it (compare, hash, repr) could do too much work.

        Every occurrence of a shared sub-list counts (that is what the C code walks), and
        nesting deeper than ``max_nesting`` is refused (C recursion). Returns an upper
        estimate of the printed length in characters when ``chars`` is set.
        """
        if type(value) not in _DEEP:
            return 0
        limit = self.b.max_nodes
        max_depth = self.b.max_nesting
        count = 0
        nchars = 0
        stack: list[tuple[Any, int]] = [(value, 0)]
        pop, extend = stack.pop, stack.extend
        while stack:
            v, depth = pop()
            t = type(v)
            if t is str:
                count += 1 + len(v) // _STR_CHARS_PER_NODE
                nchars += len(v) + 2
                continue
            if depth >= max_depth:
                raise self._error(
                    f"this value is nested more than {max_depth} levels deep (lists inside lists, or a list "
                    "that contains itself); keep data structures flat",
                    node,
                )
            elems: Any = [*v.keys(), *v.values()] if t is dict else v
            n = len(elems)
            count += 1 + n
            if count > limit:
                break
            nchars += 2 + 2 * n
            extend([(x, depth + 1) for x in elems if type(x) in _DEEP])
            if chars:
                for x in elems:
                    tx = type(x)
                    if tx is int:
                        nchars += (x.bit_length() * 3) // 10 + 2  # decimal digits: bits x log10(2), rounded up
                    elif tx not in _DEEP:
                        nchars += _SCALAR_REPR_CHARS
        if count > limit:
            raise self._error(
                f"this value is too large to compare, hash or print (more than {limit} nested elements; "
                "lists that share or contain themselves count every time); keep data structures small",
                node,
            )
        return nchars

    # ---- iteration helpers ---------------------------------------------------------------

    def _items(self, value: Any, node: Any, what: str = "the sequence") -> Any:
        """``value`` as a bounded sized iterable (refusing huge ranges and endless iterators)."""
        t = type(value)
        if t in _SIZED:
            try:
                n = len(value)
            except OverflowError:
                raise self._error(f"{what} is far too long (more than {self.b.max_len} elements)", node) from None
            if n > self.b.max_len:
                raise self._error(f"{what} would have {n} elements; the limit is {self.b.max_len}", node)
            if t is _DICT_VIEWS[2]:
                self._alloc_n(2 * n, node)  # the (key, value) tuples the consumer will create
            return value
        if t in _ITERATORS:
            out = []
            limit = self.b.max_len
            for x in value:
                out.append(x)
                if len(out) > limit:
                    raise self._error(f"{what} has more than {limit} elements; the limit is {limit}", node)
            if out and type(out[0]) is tuple:
                self._alloc_n(2 * len(out), node)  # zip/enumerate/items made a new tuple per element
            return out
        raise _not_iterable(value)

    def _iter(self, value: Any, node: Any) -> Any:
        if type(value) in _ITERABLE:
            return iter(value)
        raise _not_iterable(value)

    # ---- statements -------------------------------------------------------------------

    def _exec_block(self, body: list, scope: _Scope) -> None:
        table = self._exec_table
        for stmt in body:
            self._tick(stmt)
            try:
                table[type(stmt)](stmt, scope)
            except (ProgramError, _Signal):
                raise
            except Exception as exc:
                raise self._convert(exc, stmt) from None

    def _exec_Expr(self, node: ast.Expr, scope: _Scope) -> None:
        self._eval(node.value, scope)

    def _exec_Pass(self, node: ast.Pass, scope: _Scope) -> None:
        pass

    def _exec_Break(self, node: ast.Break, scope: _Scope) -> None:
        raise _Break()

    def _exec_Continue(self, node: ast.Continue, scope: _Scope) -> None:
        raise _Continue()

    def _exec_Return(self, node: ast.Return, scope: _Scope) -> None:
        raise _Return(None if node.value is None else self._eval(node.value, scope))

    def _exec_Assign(self, node: ast.Assign, scope: _Scope) -> None:
        value = self._eval(node.value, scope)
        for target in node.targets:
            self._assign(target, value, scope)

    def _exec_AnnAssign(self, node: ast.AnnAssign, scope: _Scope) -> None:
        if node.value is not None:
            self._assign(node.target, self._eval(node.value, scope), scope)

    def _exec_AugAssign(self, node: ast.AugAssign, scope: _Scope) -> None:
        target = node.target
        op = type(node.op)
        if isinstance(target, ast.Name):
            current = self._eval_Name(target, scope)
            value = self._eval(node.value, scope)
            scope.vars[target.id] = self._binop(op, current, value, node, inplace=True)
        elif isinstance(target, ast.Subscript):
            obj = self._eval(target.value, scope)
            key = self._eval(target.slice, scope)
            current = self._getitem(obj, key, target)
            value = self._eval(node.value, scope)
            self._setitem(obj, key, self._binop(op, current, value, node, inplace=True), target)
        else:  # pragma: no cover - rejected statically
            raise self._error("cannot assign to this target", target)

    def _exec_If(self, node: ast.If, scope: _Scope) -> None:
        if self._eval(node.test, scope):
            self._exec_block(node.body, scope)
        elif node.orelse:
            self._exec_block(node.orelse, scope)

    def _exec_While(self, node: ast.While, scope: _Scope) -> None:
        def iterations() -> Iterator[None]:
            while True:
                self._tick(node)
                if not self._eval(node.test, scope):
                    return
                yield

        self._loop(node, scope, iterations())

    def _exec_For(self, node: ast.For, scope: _Scope) -> None:
        iterable = self._eval(node.iter, scope)
        try:
            it = self._iter(iterable, node.iter)
        except TypeError as exc:
            raise self._convert(exc, node.iter) from None

        def iterations() -> Iterator[None]:
            for item in it:
                self._tick(node)
                self._assign(node.target, item, scope)
                yield

        self._loop(node, scope, iterations())

    def _loop(self, node: ast.While | ast.For, scope: _Scope, iterations: Iterator[None]) -> None:
        """Run ``node.body`` once per step of ``iterations`` (which ticks, tests or binds the target),
        then ``node.orelse`` unless the body broke out."""
        self.loops.append(node)
        try:
            for _ in iterations:
                try:
                    self._exec_block(node.body, scope)
                except _Break:
                    return
                except _Continue:
                    pass
        finally:
            self.loops.pop()
        if node.orelse:
            self._exec_block(node.orelse, scope)

    def _exec_FunctionDef(self, node: ast.FunctionDef, scope: _Scope) -> None:
        scope.vars[node.name] = self._make_function(node.name, node.args, node.body, False, node, scope)

    def _exec_Import(self, node: ast.Import, scope: _Scope) -> None:
        for alias in node.names:
            module = self.modules[_MODULE_ALIASES[alias.name]]
            scope.vars[alias.asname or alias.name] = module

    def _exec_ImportFrom(self, node: ast.ImportFrom, scope: _Scope) -> None:
        module = self.modules[_MODULE_ALIASES[node.module or ""]]
        for alias in node.names:
            scope.vars[alias.asname or alias.name] = module._lookup(alias.name)

    def _exec_Assert(self, node: ast.Assert, scope: _Scope) -> None:
        if not self._eval(node.test, scope):
            message = "assertion failed"
            if node.msg is not None:
                message += ": " + self._to_str(self._eval(node.msg, scope), node.msg)
            raise self._error(message, node)

    def _exec_Delete(self, node: ast.Delete, scope: _Scope) -> None:
        for target in node.targets:
            self._delete(target, scope)

    def _delete(self, target: Any, scope: _Scope) -> None:
        if isinstance(target, ast.Name):
            if target.id in scope.vars:
                del scope.vars[target.id]
            else:
                raise self._error(f"NameError: name {target.id!r} is not defined here", target)
        elif isinstance(target, ast.Subscript):
            obj = self._eval(target.value, scope)
            key = self._eval(target.slice, scope)
            if type(obj) not in (list, dict):
                raise self._error(f"TypeError: '{_tname(obj)}' object does not support item deletion", target)
            try:
                del obj[key]
            except Exception as exc:
                raise self._convert(exc, target) from None
        elif isinstance(target, (ast.Tuple, ast.List)):
            for elt in target.elts:
                self._delete(elt, scope)
        else:
            raise self._error("only names and items can be deleted", target)

    # ---- assignment ---------------------------------------------------------------------

    def _assign(self, target: Any, value: Any, scope: _Scope) -> None:
        t = type(target)
        if t is ast.Name:
            scope.vars[target.id] = value
        elif t is ast.Tuple or t is ast.List:
            self._unpack(target, value, scope)
        elif t is ast.Subscript:
            obj = self._eval(target.value, scope)
            key = self._eval(target.slice, scope)
            self._setitem(obj, key, value, target)
        else:
            raise self._error("cannot assign to this expression", target)

    def _unpack(self, target: Any, value: Any, scope: _Scope) -> None:
        elts = target.elts
        starred = [i for i, e in enumerate(elts) if isinstance(e, ast.Starred)]
        try:
            if type(value) in _SIZED and not starred:
                n = len(value)
                if n != len(elts):
                    if n > len(elts):
                        raise ValueError(f"too many values to unpack (expected {len(elts)})")
                    raise ValueError(f"not enough values to unpack (expected {len(elts)}, got {n})")
            items = list(self._items(value, target, "the value to unpack"))
        except (TypeError, ValueError, OverflowError) as exc:
            raise self._convert(exc, target) from None
        if not starred:
            if len(items) != len(elts):
                kind = "too many" if len(items) > len(elts) else "not enough"
                raise self._error(f"ValueError: {kind} values to unpack (expected {len(elts)}, got {len(items)})", target)
            for elt, item in zip(elts, items):
                self._assign(elt, item, scope)
            return
        if len(starred) > 1:
            raise self._error("multiple starred expressions in assignment", target)
        i = starred[0]
        after = len(elts) - i - 1
        if len(items) < len(elts) - 1:
            raise self._error(
                f"ValueError: not enough values to unpack (expected at least {len(elts) - 1}, got {len(items)})",
                target,
            )
        for elt, item in zip(elts[:i], items[:i]):
            self._assign(elt, item, scope)
        rest = items[i : len(items) - after]
        self._alloc_n(len(rest), target)
        self._assign(elts[i].value, rest, scope)
        for elt, item in zip(elts[i + 1 :], items[len(items) - after :]):
            self._assign(elt, item, scope)

    def _getitem(self, obj: Any, key: Any, node: Any) -> Any:
        t = type(obj)
        if t is dict:
            if type(key) in _HASH_DEEP:
                self._weigh(key, node)
            try:
                return obj[key]
            except KeyError:
                keys = [k for k in obj if isinstance(k, str)]
                hint = _suggest(key, keys) if isinstance(key, str) else ""
                shown = ", ".join(repr(k) for k in list(obj)[:_MAX_KEYS_SHOWN])
                raise self._error(
                    f"KeyError: key {_short_repr(key)} is not in the dict{hint or '.'} Keys: {shown or '(none)'}",
                    node,
                ) from None
        if t is list or t is tuple or t is str or t is range:
            if type(key) is slice:
                result = obj[key]
                if t is not range:
                    self._alloc_n(len(result), node)
                return result
            try:
                return obj[key]
            except IndexError:
                if type(key) is int:
                    raise self._error(
                        f"IndexError: index {key} is out of range for a {t.__name__} of length {len(obj)}", node
                    ) from None
                raise
        hint = ""
        if t is ObjectView:
            hint = f"; use fields such as {obj._id}.position or {obj._id}.attributes['colour']"
        raise TypeError(f"'{_tname(obj)}' object is not subscriptable{hint}")

    def _setitem(self, obj: Any, key: Any, value: Any, node: Any) -> None:
        t = type(obj)
        if t is dict:
            if type(key) in _HASH_DEEP:
                self._weigh(key, node)
            if key not in obj:
                self._grow(len(obj), 1, node, "a dict")
            obj[key] = value
        elif t is list:
            if type(key) is slice:
                items = list(self._items(value, node, "the assigned sequence"))
                self._grow(len(obj), len(items), node)
                obj[key] = items
            else:
                try:
                    obj[key] = value
                except IndexError:
                    if type(key) is int:
                        raise self._error(
                            f"IndexError: index {key} is out of range for a list of length {len(obj)}", node
                        ) from None
                    raise
        else:
            hint = "; scene objects are read-only" if t is ObjectView else ""
            if t is tuple or t is str:
                hint = f"; a {t.__name__} cannot be changed, build a new one or use a list"
            raise TypeError(f"'{_tname(obj)}' object does not support item assignment{hint}")

    # ---- functions --------------------------------------------------------------------

    def _make_function(self, name: str, args: ast.arguments, body: Any, is_lambda: bool, node: Any, scope: _Scope):
        params = tuple(a.arg for a in args.args)
        kwonly = tuple(a.arg for a in args.kwonlyargs)
        defaults: dict[str, Any] = {}
        for a, d in zip(args.args[len(args.args) - len(args.defaults) :], args.defaults):
            defaults[a.arg] = self._eval(d, scope)
        for a, d in zip(args.kwonlyargs, args.kw_defaults):
            if d is not None:
                defaults[a.arg] = self._eval(d, scope)
        local_names = self._function_locals(node, args, body, is_lambda)
        return _SandboxFunction(name, params, kwonly, defaults, scope, local_names, body, is_lambda, self)

    def _function_locals(self, node: Any, args: ast.arguments, body: Any, is_lambda: bool) -> frozenset:
        cached = self._locals_cache.get(id(node))
        if cached is not None:
            return cached
        names = {a.arg for a in (*args.args, *args.kwonlyargs)}
        stack: list[Any] = [body] if is_lambda else list(body)
        while stack:
            n = stack.pop()
            if isinstance(n, ast.FunctionDef):
                names.add(n.name)
                stack.extend(n.args.defaults)
                stack.extend(d for d in n.args.kw_defaults if d is not None)
            elif isinstance(n, ast.Lambda):
                stack.extend(n.args.defaults)
                stack.extend(d for d in n.args.kw_defaults if d is not None)
            elif isinstance(n, (ast.ListComp, ast.SetComp, ast.DictComp, ast.GeneratorExp)):
                stack.append(n.generators[0].iter)
            elif isinstance(n, ast.Name):
                if not isinstance(n.ctx, ast.Load):
                    names.add(n.id)
            elif isinstance(n, (ast.Import, ast.ImportFrom)):
                for alias in n.names:
                    names.add(alias.asname or alias.name)
            else:
                stack.extend(ast.iter_child_nodes(n))
        result = frozenset(names)
        self._locals_cache[id(node)] = result
        return result

    def _bind(self, fn: _SandboxFunction, args: Any, kwargs: dict) -> dict[str, Any]:
        params = fn.params
        if len(args) > len(params):
            raise TypeError(
                f"{fn.name}() takes {len(params)} positional argument{'s' if len(params) != 1 else ''} "
                f"but {len(args)} {'were' if len(args) != 1 else 'was'} given"
            )
        values = dict(zip(params, args))
        for key, value in kwargs.items():
            if key in values:
                raise TypeError(f"{fn.name}() got multiple values for argument {key!r}")
            if key not in params and key not in fn.kwonly:
                raise TypeError(
                    f"{fn.name}() got an unexpected keyword argument {key!r}"
                    f"{_suggest(key, (*params, *fn.kwonly), 1)}"
                )
            values[key] = value
        for p in (*params, *fn.kwonly):
            if p not in values:
                if p in fn.defaults:
                    values[p] = fn.defaults[p]
                else:
                    raise TypeError(f"{fn.name}() missing required argument {p!r}")
        return values

    def _invoke(self, fn: _SandboxFunction, args: Any, kwargs: dict, node: Any) -> Any:
        if self.depth >= self.b.max_call_depth:
            raise self._error(
                f"function calls nest more than {self.b.max_call_depth} deep; does a recursive function lack a "
                "base case? Use a loop instead",
                node,
            )
        self._tick(node)
        try:
            values = self._bind(fn, args, kwargs)
        except TypeError as exc:
            raise self._convert(exc, node) from None
        scope = _Scope(values, fn.locals, fn.closure, fn.name)
        line = getattr(node, "lineno", 0) or 0
        self.depth += 1
        self.call_lines.append(line)
        try:
            if fn.is_lambda:
                return self._eval(fn.body, scope)
            try:
                self._exec_block(fn.body, scope)
            except _Return as ret:
                return ret.value
            return None
        except ProgramError as exc:
            if getattr(exc, "_in_function", False):
                raise
            new = ProgramError(f"{exc.reason} (in {fn.name}(), called from line {line})", exc.line, exc.col)
            new._in_function = True  # type: ignore[attr-defined]
            raise new from None
        finally:
            self.depth -= 1
            self.call_lines.pop()

    def _call(self, func: Any, args: Any, kwargs: dict, node: Any) -> Any:
        t = type(func)
        prev = self._call_node
        self._call_node = node
        try:
            if t is _SandboxFunction:
                return self._invoke(func, args, kwargs, node)
            if t is _Builtin:
                return self._call_builtin(func, args, kwargs)
            if t is _Method:
                return self._call_method(func.obj, func.name, args, kwargs)
        finally:
            self._call_node = prev
        hint = ""
        if t is ObjectView:
            hint = f"; {func._id} is a scene object, not a function"
        elif t is Namespace:
            hint = f"; call one of its functions, e.g. {func._name}.{next(iter(func._members))}(...)"
        raise TypeError(f"'{_tname(func)}' object is not callable{hint}")

    def _call_builtin(self, b: _Builtin, args: Any, kwargs: dict) -> Any:
        node = self._call_node
        if b.sig is not None:
            try:
                b.sig.bind(*args, **kwargs)
            except TypeError as exc:
                text = str(exc)
                m = re.search(r"unexpected keyword argument '(\w+)'", text)
                hint = _suggest(m.group(1), b.sig.parameters, 1) if m else ""
                raise self._error(f"{b.name}(): {text}{hint}; usage: {b.usage}", node) from None
        if b.kind == "skill" or b.name == "print":
            line, col = self._pos(node)
            self.rec.where = (line, col, tuple(self.call_lines))
        result = b.fn(*args, **kwargs)
        t = type(result)
        if t is int and result.bit_length() > self.b.max_int_bits:
            self._check_int(result, node)
        return result

    def _call_method(self, obj: Any, name: str, args: Any, kwargs: dict) -> Any:
        node = self._call_node
        t = type(obj)
        method = getattr(obj, name)  # name comes from the _METHODS whitelist
        args = tuple(args)
        if t is list:
            if name in ("append", "insert"):
                self._grow(len(obj), 1, node)
            elif name == "extend" and len(args) == 1:
                items = self._items(args[0], node, "the extension")
                self._grow(len(obj), len(items), node)
                args = (items,)
            elif name in ("index", "count", "remove", "sort"):
                self._weigh(obj, node)
                for a in args:
                    self._weigh(a, node)
            elif name == "copy":
                self._alloc_n(len(obj), node)
        elif t is dict:
            if name in ("get", "pop", "setdefault") and args:
                if type(args[0]) in _HASH_DEEP:
                    self._weigh(args[0], node)
                if name == "setdefault" and args[0] not in obj:
                    self._grow(len(obj), 1, node, "a dict")
            elif name == "update":
                if len(args) > 1:
                    raise TypeError(f"update expected at most 1 argument, got {len(args)}")
                pairs = dict(self._pairs(args[0], node)) if args else {}
                for k, v in kwargs.items():
                    pairs[k] = v
                self._grow(len(obj), len(pairs), node, "a dict")
                obj.update(pairs)
                return None
            elif name in ("copy", "keys", "values", "items"):
                self._alloc_n(len(obj) if name == "copy" else 0, node)
        elif t is set:
            if name in ("add", "discard", "remove") and args:
                if type(args[0]) in _HASH_DEEP:
                    self._weigh(args[0], node)
                if name == "add":
                    self._grow(len(obj), 1, node, "a set")
            elif name in ("union", "intersection", "difference", "issubset", "issuperset", "update"):
                others = []
                for a in args:
                    items = self._items(a, node, "the argument")
                    self._weigh(items, node)
                    others.append(items)
                if name in ("union", "update"):
                    self._grow(len(obj), sum(len(o) for o in others), node, "a set")
                args = tuple(others)
            elif name == "copy":
                self._alloc_n(len(obj), node)
        elif t is str:
            if name == "join" and len(args) == 1:
                items = self._items(args[0], node, "the joined sequence")
                total = sum(len(x) for x in items if type(x) is str) + len(obj) * max(len(items) - 1, 0)
                self._check_str(total, node)
                args = (items,)
            elif name == "replace" and len(args) >= 2 and type(args[0]) is str and type(args[1]) is str:
                old, new = args[0], args[1]
                n = obj.count(old) if old else len(obj) + 1
                if len(args) >= 3 and type(args[2]) is int and args[2] >= 0:
                    n = min(n, args[2])
                self._check_str(len(obj) + n * (len(new) - len(old)), node)
            elif name in ("index", "count", "find", "startswith", "endswith") and args and type(args[0]) is tuple:
                self._weigh(args[0], node)
        elif t is tuple:
            self._weigh(obj, node)
            for a in args:
                self._weigh(a, node)
        if "key" in kwargs and kwargs["key"] is not None:
            _check_callable(kwargs["key"], "key")
        result = method(*args, **kwargs)
        rt = type(result)
        if rt is str:
            self._check_str(len(result), node)
        elif rt is list:
            self._check_len(len(result), node)
        return result

    def _pairs(self, value: Any, node: Any) -> Any:
        if type(value) is dict:
            return value
        items = self._items(value, node, "the key/value pairs")
        out = []
        for i, pair in enumerate(items):
            if type(pair) not in (tuple, list, str) or len(pair) != 2:
                length = len(pair) if type(pair) in (tuple, list, str) else None
                got = f"has length {length}" if length is not None else f"is a {_tname(pair)}"
                raise ValueError(f"dict element #{i} {got}; each element must be a (key, value) pair")
            if type(pair[0]) in _HASH_DEEP:
                self._weigh(pair[0], node)
            out.append((pair[0], pair[1]))
        return out

    # ---- expressions ------------------------------------------------------------------

    def _eval(self, node: Any, scope: _Scope) -> Any:
        try:
            return self._eval_table[type(node)](node, scope)
        except (ProgramError, _Signal):
            raise
        except Exception as exc:
            raise self._convert(exc, node) from None

    def _eval_Constant(self, node: ast.Constant, scope: _Scope) -> Any:
        return node.value

    def _eval_Name(self, node: ast.Name, scope: _Scope) -> Any:
        name = node.id
        s: _Scope | None = scope
        while s is not None:
            value = s.vars.get(name, _MISSING)
            if value is not _MISSING:
                return value
            if s.locals is not None and name in s.locals:
                raise self._error(
                    f"UnboundLocalError: local variable {name!r} is used before it is assigned in {s.fname}()"
                    + (
                        "; assigning to a name anywhere in a function makes it local there: use another name "
                        "or pass the value as an argument"
                        if self._defined_outside(name, s)
                        else ""
                    ),
                    node,
                )
            s = s.parent
        value = self.base.get(name, _MISSING)
        if value is not _MISSING:
            return value
        raise self._error(self._name_message(name, scope), node)

    def _defined_outside(self, name: str, scope: _Scope) -> bool:
        s = scope.parent
        while s is not None:
            if name in s.vars:
                return True
            s = s.parent
        return name in self.base

    def _name_message(self, name: str, scope: _Scope) -> str:
        if name in _MATH_ALL:
            return f"name {name!r} is not defined; did you mean math.{name}? (or write 'from math import {name}')"
        candidates: set[str] = set(self.base)
        s: _Scope | None = scope
        while s is not None:
            candidates.update(s.vars)
            if s.locals:
                candidates.update(s.locals)
            s = s.parent
        text = f"name {name!r} is not defined{_suggest(name, sorted(candidates))}"
        if not text.endswith("?"):
            ids = list(self.rec.views)
            text += f". Skills: {', '.join(SKILLS)}; scene objects: {', '.join(ids) or '(none)'}"
        return text

    def _eval_Attribute(self, node: ast.Attribute, scope: _Scope) -> Any:
        obj = self._eval(node.value, scope)
        name = node.attr
        t = type(obj)
        if t is ObjectView or t is Namespace:
            try:
                return obj._lookup(name)
            except AttributeError as exc:
                raise self._attr_error(str(exc), node) from None
        allowed = _METHODS.get(t)
        if allowed is not None and name in allowed:
            return _Method(obj, name, self)
        raise self._attr_error(_attr_message(obj, name), node)

    def _eval_Subscript(self, node: ast.Subscript, scope: _Scope) -> Any:
        obj = self._eval(node.value, scope)
        key = self._eval(node.slice, scope)
        return self._getitem(obj, key, node)

    def _eval_Slice(self, node: ast.Slice, scope: _Scope) -> Any:
        parts = []
        for part in (node.lower, node.upper, node.step):
            value = None if part is None else self._eval(part, scope)
            if value is not None and type(value) not in (int, bool):
                raise TypeError(f"slice indices must be whole numbers or None, not {_tname(value)}")
            parts.append(value)
        return slice(*parts)

    def _eval_Call(self, node: ast.Call, scope: _Scope) -> Any:
        func = self._eval(node.func, scope)
        args: list[Any] = []
        for a in node.args:
            if type(a) is ast.Starred:
                value = self._eval(a.value, scope)
                try:
                    args.extend(self._items(value, a, "the '*' argument"))
                except TypeError as exc:
                    raise self._convert(exc, a) from None
                if len(args) > self.b.max_len:
                    raise self._error(f"too many arguments (more than {self.b.max_len})", a)
            else:
                args.append(self._eval(a, scope))
        kwargs = {kw.arg: self._eval(kw.value, scope) for kw in node.keywords}
        return self._call(func, args, kwargs, node)

    def _eval_BinOp(self, node: ast.BinOp, scope: _Scope) -> Any:
        left = self._eval(node.left, scope)
        right = self._eval(node.right, scope)
        return self._binop(type(node.op), left, right, node)

    def _binop(self, op: type, a: Any, b: Any, node: Any, inplace: bool = False) -> Any:
        ta, tb = type(a), type(b)
        if op is ast.Add:
            if ta in _SEQS and ta is tb:
                if inplace and ta is list:
                    self._grow(len(a), len(b), node)
                elif ta is str:
                    self._check_str(len(a) + len(b), node)
                else:
                    self._check_len(len(a) + len(b), node)
            elif inplace and ta is list:
                b = self._items(b, node, "the extension")
                self._grow(len(a), len(b), node)
        elif op is ast.Mult:
            if ta in _SEQS and isinstance(b, int) or tb in _SEQS and isinstance(a, int):
                seq, n = (a, b) if ta in _SEQS else (b, a)
                total = len(seq) * max(int(n), 0)
                if type(seq) is str:
                    self._check_str(total, node)
                else:
                    self._check_len(total, node)
            elif ta is int and tb is int and a.bit_length() + b.bit_length() > self.b.max_int_bits + 1:
                self._check_int(1 << (self.b.max_int_bits + 1), node)
        elif op is ast.Pow:
            if isinstance(a, int) and isinstance(b, int) and b > 0 and abs(a) > 1:
                if (abs(a).bit_length() - 1) * b >= self.b.max_int_bits:
                    raise self._error(
                        f"integer too large: {_short_repr(a)} ** {_short_repr(b)} has more than "
                        f"{self.b.max_int_bits} bits; robot programs need small numbers",
                        node,
                    )
        elif op is ast.LShift:
            if isinstance(a, int) and isinstance(b, int) and a != 0 and b > 0:
                if abs(a).bit_length() + b > self.b.max_int_bits:
                    self._check_int(1 << (self.b.max_int_bits + 1), node)
        elif op is ast.Mod:
            if ta is str:
                raise self._error("'%' string formatting is not available; use an f-string such as f\"{x:.2f}\"", node)
        fn = _IBINOPS[op] if inplace else _BINOPS[op]
        result = fn(a, b)
        return self._check_result(result, node)

    def _eval_UnaryOp(self, node: ast.UnaryOp, scope: _Scope) -> Any:
        value = self._eval(node.operand, scope)
        return _UNARY[type(node.op)](value)

    def _eval_BoolOp(self, node: ast.BoolOp, scope: _Scope) -> Any:
        is_and = type(node.op) is ast.And
        value = None
        for v in node.values:
            value = self._eval(v, scope)
            if is_and:
                if not value:
                    return value
            elif value:
                return value
        return value

    def _eval_Compare(self, node: ast.Compare, scope: _Scope) -> Any:
        left = self._eval(node.left, scope)
        result: Any = True
        for op, comp in zip(node.ops, node.comparators):
            right = self._eval(comp, scope)
            result = self._compare(type(op), left, right, node)
            if not result:
                return result
            left = right
        return result

    def _compare(self, op: type, a: Any, b: Any, node: Any) -> Any:
        if op is ast.Is:
            return a is b
        if op is ast.IsNot:
            return a is not b
        if op is ast.In or op is ast.NotIn:
            tb = type(b)
            if tb is range:
                if type(a) is not int and len(b) > self.b.max_len:
                    raise self._error("'in' on a huge range only works for whole numbers", node)
            elif tb is str:
                pass
            elif tb in _SIZED:
                self._weigh(b, node)
                self._weigh(a, node)
            elif tb in _ITERATORS:
                b = self._items(b, node, "the searched sequence")
                self._weigh(b, node)
                self._weigh(a, node)
            else:
                raise TypeError(f"argument of type '{_tname(b)}' is not a container")
            found = a in b
            return found if op is ast.In else not found
        if type(a) not in _SCALARS or type(b) not in _SCALARS:
            self._weigh(a, node)
            self._weigh(b, node)
        return _CMPOPS[op](a, b)

    def _eval_IfExp(self, node: ast.IfExp, scope: _Scope) -> Any:
        return self._eval(node.body if self._eval(node.test, scope) else node.orelse, scope)

    def _elements(self, elts: list, scope: _Scope, node: Any) -> list:
        out: list[Any] = []
        for e in elts:
            if type(e) is ast.Starred:
                value = self._eval(e.value, scope)
                try:
                    out.extend(self._items(value, e, "the '*' expansion"))
                except TypeError as exc:
                    raise self._convert(exc, e) from None
            else:
                out.append(self._eval(e, scope))
        self._check_len(len(out), node)
        return out

    def _eval_List(self, node: ast.List, scope: _Scope) -> Any:
        return self._elements(node.elts, scope, node)

    def _eval_Tuple(self, node: ast.Tuple, scope: _Scope) -> Any:
        return tuple(self._elements(node.elts, scope, node))

    def _eval_Set(self, node: ast.Set, scope: _Scope) -> Any:
        items = self._elements(node.elts, scope, node)
        for x in items:
            if type(x) in _HASH_DEEP:
                self._weigh(x, node)
        return set(items)

    def _eval_Dict(self, node: ast.Dict, scope: _Scope) -> Any:
        out: dict[Any, Any] = {}
        for k, v in zip(node.keys, node.values):
            key = self._eval(k, scope)
            if type(key) in _HASH_DEEP:
                self._weigh(key, node)
            out[key] = self._eval(v, scope)
        self._check_len(len(out), node, "a dict")
        return out

    def _comprehension(self, node: Any, scope: _Scope, emit: Callable[[_Scope], None]) -> None:
        local_names = self._locals_cache.get(id(node))
        if local_names is None:
            names = set()
            stack = [g.target for g in node.generators]
            while stack:  # (ast.walk would import collections at run time)
                n = stack.pop()
                if isinstance(n, ast.Name):
                    names.add(n.id)
                elif isinstance(n, (ast.Tuple, ast.List)):
                    stack.extend(n.elts)
                elif isinstance(n, ast.Starred):
                    stack.append(n.value)
            local_names = frozenset(names)
            self._locals_cache[id(node)] = local_names
        inner = _Scope({}, local_names, scope, scope.fname)
        gens = node.generators
        last = len(gens) - 1

        def loop(i: int) -> None:
            g = gens[i]
            iterable = self._eval(g.iter, scope if i == 0 else inner)
            try:
                it = self._iter(iterable, g.iter)
            except TypeError as exc:
                raise self._convert(exc, g.iter) from None
            for item in it:
                self._tick(node)
                self._assign(g.target, item, inner)
                ok = True
                for cond in g.ifs:
                    if not self._eval(cond, inner):
                        ok = False
                        break
                if ok:
                    if i == last:
                        emit(inner)
                    else:
                        loop(i + 1)

        self.loops.append(node)
        try:
            loop(0)
        finally:
            self.loops.pop()

    def _eval_ListComp(self, node: ast.ListComp, scope: _Scope) -> Any:
        out: list[Any] = []
        limit = self.b.max_len

        def emit(inner: _Scope) -> None:
            out.append(self._eval(node.elt, inner))
            if len(out) > limit:
                self._check_len(len(out), node)
            self._alloc_n(1, node)

        self._comprehension(node, scope, emit)
        return out

    _eval_GeneratorExp = _eval_ListComp  # evaluated eagerly (bounded like a list)

    def _eval_SetComp(self, node: ast.SetComp, scope: _Scope) -> Any:
        out: set[Any] = set()

        def emit(inner: _Scope) -> None:
            value = self._eval(node.elt, inner)
            if type(value) in _HASH_DEEP:
                self._weigh(value, node)
            out.add(value)
            if len(out) > self.b.max_len:
                self._check_len(len(out), node, "a set")
            self._alloc_n(1, node)

        self._comprehension(node, scope, emit)
        return out

    def _eval_DictComp(self, node: ast.DictComp, scope: _Scope) -> Any:
        out: dict[Any, Any] = {}

        def emit(inner: _Scope) -> None:
            key = self._eval(node.key, inner)
            if type(key) in _HASH_DEEP:
                self._weigh(key, node)
            out[key] = self._eval(node.value, inner)
            if len(out) > self.b.max_len:
                self._check_len(len(out), node, "a dict")
            self._alloc_n(2, node)

        self._comprehension(node, scope, emit)
        return out

    def _eval_Lambda(self, node: ast.Lambda, scope: _Scope) -> Any:
        return self._make_function("<lambda>", node.args, node.body, True, node, scope)

    def _eval_JoinedStr(self, node: ast.JoinedStr, scope: _Scope) -> Any:
        parts = []
        total = 0
        for v in node.values:
            text = v.value if type(v) is ast.Constant else self._eval(v, scope)
            total += len(text)
            if total > self.b.max_str_len:
                self._check_str(total, node)
            parts.append(text)
        result = "".join(parts)
        self._alloc_n(len(result), node)
        return result

    def _eval_FormattedValue(self, node: ast.FormattedValue, scope: _Scope) -> Any:
        value = self._eval(node.value, scope)
        spec = "" if node.format_spec is None else self._eval(node.format_spec, scope)
        if node.conversion == ord("r"):
            value = self._to_str(value, node, use_repr=True)
        elif node.conversion == ord("a"):
            self._to_str(value, node, use_repr=True)  # bounds the work
            value = ascii(value)
        elif node.conversion == ord("s"):
            value = self._to_str(value, node)
        if not spec:
            return self._to_str(value, node)
        for digits in re.findall(r"\d+", spec):
            if len(digits) > len(str(_MAX_FORMAT_WIDTH)) or int(digits) > _MAX_FORMAT_WIDTH:
                raise self._error(
                    f"format spec {spec!r} asks for a width or precision above {_MAX_FORMAT_WIDTH}", node
                )
        if type(value) not in _SCALARS and type(value) is not ObjectView:
            raise TypeError(f"format spec {spec!r} only applies to numbers and strings, not {_tname(value)}")
        return format(value, spec)

    def _eval_Starred(self, node: ast.Starred, scope: _Scope) -> Any:  # pragma: no cover - rejected statically
        raise self._error("'*' is not allowed here", node)

    def _to_str(self, value: Any, node: Any, use_repr: bool = False) -> str:
        t = type(value)
        if t is str:
            text = repr(value) if use_repr else value
        elif t in _SCALARS:
            text = repr(value) if use_repr else str(value)
        elif t in _DEEP or t in _DICT_VIEWS:
            chars = self._weigh(value, node, chars=True)
            if chars > self.b.max_str_len:
                raise self._error(
                    f"printing this value would produce about {chars} characters; the limit is "
                    f"{self.b.max_str_len}",
                    node,
                )
            text = repr(value)
        else:
            text = repr(value)
        if text is not value:
            self._check_str(len(text), node)  # counts the new string against the allocation budget
        return text

    # ---- builtins -----------------------------------------------------------------------

    def _b_range(self, *args):
        if not 1 <= len(args) <= 3:
            raise TypeError(f"range expected 1 to 3 arguments, got {len(args)}")
        for a in args:
            if type(a) not in (int, bool):
                raise TypeError(f"range() needs whole numbers, got {_tname(a)}; convert with int(...) or round(...)")
        return range(*args)

    def _b_len(self, obj):
        if type(obj) not in _SIZED:
            raise TypeError(f"object of type '{_tname(obj)}' has no len()")
        try:
            return len(obj)
        except OverflowError:
            raise OverflowError("the range is too long to measure") from None

    def _minmax(self, fn: Callable, name: str, args: tuple, key: Any, default: Any) -> Any:
        node = self._call_node
        if not args:
            raise TypeError(f"{name} expected at least 1 argument, got 0")
        items = self._items(args[0], node, f"the argument of {name}()") if len(args) == 1 else args
        self._weigh(items, node)
        kw: dict[str, Any] = {}
        if key is not None:
            _check_callable(key, "key")
            kw["key"] = key
        if default is not _NOVALUE:
            if len(args) != 1:
                raise TypeError(f"Cannot specify a default for {name}() with multiple positional arguments")
            kw["default"] = default
        return fn(items, **kw)

    def _b_min(self, *args, key=None, default=_NOVALUE):
        return self._minmax(min, "min", args, key, default)

    def _b_max(self, *args, key=None, default=_NOVALUE):
        return self._minmax(max, "max", args, key, default)

    def _b_abs(self, x):
        return abs(x)

    def _b_round(self, number, ndigits=None):
        if ndigits is not None:
            if type(ndigits) not in (int, bool):
                raise TypeError(f"round() ndigits must be a whole number, not {_tname(ndigits)}")
            if abs(ndigits) > _MAX_ROUND_DIGITS:
                raise ValueError(f"round() ndigits must be between -{_MAX_ROUND_DIGITS} and {_MAX_ROUND_DIGITS}")
            return round(number, ndigits)
        return round(number)

    def _b_enumerate(self, iterable, start=0):
        if type(start) not in (int, bool):
            raise TypeError(f"enumerate() start must be a whole number, not {_tname(start)}")
        return enumerate(self._iter(iterable, self._call_node), start)

    def _b_zip(self, *iterables):
        return zip(*[self._iter(it, self._call_node) for it in iterables])

    def _b_sum(self, iterable, start=0):
        node = self._call_node
        items = self._items(iterable, node, "the argument of sum()")
        numbers = (int, float, bool, complex)
        for x in (start, *items):
            if type(x) not in numbers:
                raise TypeError(f"sum() adds numbers only, got {_tname(x)}")
        return sum(items, start)

    def _b_sorted(self, iterable, key=None, reverse=False):
        node = self._call_node
        items = self._items(iterable, node, "the argument of sorted()")
        self._weigh(items, node)
        if key is not None:
            _check_callable(key, "key")
        self._alloc_n(len(items), node)
        return sorted(items, key=key, reverse=bool(reverse))

    def _b_reversed(self, seq):
        if type(seq) not in (list, tuple, str, range, dict, *_DICT_VIEWS):
            raise TypeError(f"'{_tname(seq)}' object is not reversible")
        return reversed(seq)

    def _b_list(self, iterable=()):
        items = self._items(iterable, self._call_node, "the argument of list()")
        self._alloc_n(len(items), self._call_node)
        return list(items)

    def _b_tuple(self, iterable=()):
        items = self._items(iterable, self._call_node, "the argument of tuple()")
        self._alloc_n(len(items), self._call_node)
        return tuple(items)

    def _b_set(self, iterable=()):
        items = self._items(iterable, self._call_node, "the argument of set()")
        self._weigh(items, self._call_node)
        self._alloc_n(len(items), self._call_node)
        return set(items)

    def _b_dict(self, iterable=(), **kwargs):
        out = dict(self._pairs(iterable, self._call_node))
        out.update(kwargs)
        self._check_len(len(out), self._call_node, "a dict")
        return out

    def _b_float(self, x=0.0):
        if type(x) not in (int, float, bool, str):
            raise TypeError(f"float() argument must be a number or a string, not {_tname(x)}")
        return float(x)

    def _b_int(self, x=0, base=_NOVALUE):
        if type(x) not in (int, float, bool, str):
            raise TypeError(f"int() argument must be a number or a string, not {_tname(x)}")
        return int(x) if base is _NOVALUE else int(x, base)

    def _b_str(self, x=""):
        return self._to_str(x, self._call_node)

    def _b_repr(self, x):
        return self._to_str(x, self._call_node, use_repr=True)

    def _b_bool(self, x=False):
        return bool(x)

    def _b_any(self, iterable):
        return any(self._items(iterable, self._call_node, "the argument of any()"))

    def _b_all(self, iterable):
        return all(self._items(iterable, self._call_node, "the argument of all()"))

    def _b_print(self, *values, sep=" ", end="\n"):
        node = self._call_node
        if sep is None:
            sep = " "
        if type(sep) is not str or (end is not None and type(end) is not str):
            raise TypeError("print() sep and end must be strings")
        parts = [self._to_str(v, node) for v in values]
        total = sum(len(p) for p in parts) + len(sep) * max(len(parts) - 1, 0)
        self._check_str(total, node)
        text = sep.join(parts)
        if end not in (None, "\n"):
            text += end
        _skills.print(text)

    # ---- wrapped math functions (their C versions would iterate without limits) ---------

    def _m_fsum(self, iterable):
        return math.fsum(self._items(iterable, self._call_node, "the argument of fsum()"))

    def _m_prod(self, iterable, start=1):
        node = self._call_node
        result = start
        for x in self._items(iterable, node, "the argument of prod()"):
            result = self._binop(ast.Mult, result, x, node)
        return result

    def _m_dist(self, p, q):
        node = self._call_node
        return math.dist(tuple(self._items(p, node, "p")), tuple(self._items(q, node, "q")))


_STMT_TYPES = (
    ast.Expr, ast.Assign, ast.AugAssign, ast.AnnAssign, ast.If, ast.For, ast.While, ast.Break, ast.Continue,
    ast.Pass, ast.FunctionDef, ast.Return, ast.Import, ast.ImportFrom, ast.Assert, ast.Delete,
)  # fmt: skip
_EXPR_TYPES = (
    ast.Constant, ast.Name, ast.Attribute, ast.Subscript, ast.Slice, ast.Call, ast.BinOp, ast.UnaryOp, ast.BoolOp,
    ast.Compare, ast.IfExp, ast.List, ast.Tuple, ast.Set, ast.Dict, ast.ListComp, ast.SetComp, ast.DictComp,
    ast.GeneratorExp, ast.Lambda, ast.JoinedStr, ast.FormattedValue, ast.Starred,
)  # fmt: skip


_SIGNATURES: dict[Any, inspect.Signature] = {}


def _signature(fn: Callable, method: bool = False) -> inspect.Signature:
    """The signature of a skill or a builtin method (without ``self``), computed once per process."""
    func = getattr(fn, "__func__", fn)
    sig = _SIGNATURES.get(func)
    if sig is None:
        sig = inspect.signature(func)
        if method or func is not fn:
            sig = sig.replace(parameters=list(sig.parameters.values())[1:])
        _SIGNATURES[func] = sig
    return sig


def _check_callable(fn: Any, what: str) -> None:
    if type(fn) not in (_SandboxFunction, _Builtin, _Method):
        raise TypeError(f"{what} must be a function, got {_tname(fn)}")


def _short_repr(value: Any) -> str:
    if type(value) is int and value.bit_length() > _QUOTED_INT_BITS:
        return f"<{value.bit_length()}-bit integer>"
    text = repr(value) if type(value) in _SCALARS or type(value) is ObjectView else f"<{_tname(value)}>"
    return text if len(text) <= _QUOTED_VALUE_CHARS else text[: _QUOTED_VALUE_CHARS - 3] + "..."


def _not_iterable(value: Any) -> TypeError:
    hint = ""
    if type(value) is ObjectView:
        hint = f"; to loop over scene objects use 'for obj in objects', for coordinates use {value._id}.position"
    elif type(value) is int:
        hint = "; to count use range(n)"
    return TypeError(f"'{_tname(value)}' object is not iterable{hint}")


def _attr_message(obj: Any, name: str) -> str:
    t = type(obj)
    if t is str and name in ("format", "format_map"):
        return f"str.{name} is not available; use an f-string such as f\"{{x:.2f}}\""
    if t in (_SandboxFunction, _Builtin, _Method):
        return f"{_tname(obj)} {getattr(obj, 'name', '')!r} has no attribute {name!r}; functions have no fields"
    allowed = _METHODS.get(t)
    if allowed is not None:
        hint = _suggest(name, allowed, 1)
        return (
            f"'{t.__name__}' method {name!r} is not available{hint or '.'} "
            f"{t.__name__} methods you can use: {', '.join(sorted(allowed))}"
        )
    return f"'{_tname(obj)}' object has no attribute {name!r}"


def _frame_depth() -> int:
    depth = 0
    frame = sys._getframe(1)
    while frame is not None:
        depth += 1
        frame = frame.f_back
    return depth


# --------------------------------------------------------------------------------------
# entry point


def run_program(source: str, scene: Scene | None = None, budget: Budget | None = None) -> Plan:
    """Check and run an untrusted robot program against ``scene``; return the recorded :class:`Plan`.

    Nothing moves: skills record calls. Any rejection, budget stop or runtime
    error raises :class:`ProgramError` with the line and column.
    """
    b = budget or Budget()
    tree = check_program(source, b)
    scene = scene if scene is not None else Scene()
    return _Interpreter(source, tree, scene, b).run()


# Compute every signature at import time so that running a program never imports anything.
for _fn in SKILLS.values():
    _signature(_fn)
for _name in dir(_Interpreter):
    if _name.startswith(("_b_", "_m_")):
        _signature(getattr(_Interpreter, _name), method=True)
