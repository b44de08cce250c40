"""What a robot program may call besides the skills: the one list of sandbox builtins, methods and math names.

The sandbox (:mod:`robocritics.program.sandbox`) builds a program's namespace
from these tables, the skill reference pasted into LLM prompts
(:func:`robocritics.program.skills.api_reference`) names the builtins from
:data:`SAFE_BUILTINS`, and the "What programs may call" section of
``docs/programs.md`` is :func:`reference_markdown` (a test keeps it in step).
Anything not listed here does not exist for a program.
"""

from __future__ import annotations

import ast
from types import MappingProxyType
from typing import Mapping

__all__ = ["SAFE_BUILTINS", "SAFE_METHODS", "MATH_NAMES", "STATEMENT_TYPES", "EXPRESSION_TYPES", "reference_markdown"]

SAFE_BUILTINS: Mapping[str, str] = MappingProxyType(
    {
        "range": "whole numbers from start to stop (exclusive) in steps: range(stop), range(start, stop, step)",
        "len": "number of elements of a list, tuple, dict, set, str or range",
        "min": "smallest of an iterable or of several arguments (key=, default= as in Python)",
        "max": "largest of an iterable or of several arguments (key=, default= as in Python)",
        "abs": "absolute value of a number",
        "round": "round(x) to a whole number, round(x, n) to n decimals",
        "enumerate": "(index, element) pairs of an iterable, counting from start=0",
        "zip": "tuples of the elements at the same position of several iterables",
        "sum": "sum of numbers, plus start=0",
        "sorted": "a new sorted list (key=, reverse=)",
        "reversed": "the elements of a sequence in reverse order",
        "list": "a new list from an iterable",
        "tuple": "a new tuple from an iterable",
        "dict": "a new dict from key/value pairs and keyword arguments",
        "set": "a new set from an iterable",
        "float": "a number or numeric string as a float",
        "int": "a number or numeric string as a whole number (int(text, base) too)",
        "str": "the text of a value",
        "repr": "the text of a value, strings quoted",
        "bool": "the truth value of a value",
        "any": "whether any element of an iterable is true",
        "all": "whether every element of an iterable is true",
        "print": "write one line to the program's output log, not a terminal (sep=, end=)",
    }
)
"""Builtin functions of robot programs: name -> what it does, in one line (the sandbox bounds the work each does)."""

SAFE_METHODS: Mapping[type, tuple[str, ...]] = MappingProxyType(
    {
        list: tuple("append extend insert pop remove index count reverse sort copy clear".split()),
        dict: tuple("keys values items get pop setdefault update copy clear".split()),
        set: tuple(
            "add discard remove pop union intersection difference issubset issuperset update copy clear".split()
        ),
        str: tuple(
            "upper lower strip lstrip rstrip startswith endswith split join replace find count index title "
            "capitalize isdigit isalpha".split()
        ),
        tuple: tuple("index count".split()),
    }
)
"""Methods a program may call on its own values, by type (``str.format`` is missing on purpose: f-strings only)."""

MATH_NAMES: tuple[str, ...] = tuple(
    (
        "pi e tau inf nan sqrt sin cos tan asin acos atan atan2 sinh cosh tanh hypot degrees radians floor ceil "
        "trunc fabs exp log log10 log2 pow copysign fmod isclose isfinite isinf isnan gcd isqrt modf remainder "
        "fsum prod dist"
    ).split()
)
"""Members of ``math`` a program may use (``import math``, ``from math import ...``)."""

#: The statements and expressions programs may use: the AST node types the interpreter runs.
STATEMENT_TYPES = (
    ast.Expr, ast.Assign, ast.AugAssign, ast.AnnAssign, ast.If, ast.For, ast.While, ast.Break, ast.Continue,
    ast.Pass, ast.FunctionDef, ast.Return, ast.Import, ast.ImportFrom, ast.Assert, ast.Delete,
)  # fmt: skip
EXPRESSION_TYPES = (
    ast.Constant, ast.Name, ast.Attribute, ast.Subscript, ast.Slice, ast.Call, ast.BinOp, ast.UnaryOp, ast.BoolOp,
    ast.Compare, ast.IfExp, ast.List, ast.Tuple, ast.Set, ast.Dict, ast.ListComp, ast.SetComp, ast.DictComp,
    ast.GeneratorExp, ast.Lambda, ast.JoinedStr, ast.FormattedValue, ast.Starred,
)  # fmt: skip



def reference_markdown() -> str:
    """The "What programs may call" section of ``docs/programs.md``, rendered from the tables above."""
    lines = [
        "| builtin | what it does |",
        "|---|---|",
        *(f"| `{name}` | {text} |" for name, text in SAFE_BUILTINS.items()),
        "",
        "Methods of the program's own values:",
        "",
        *(f"* `{t.__name__}`: {', '.join(names)}" for t, names in SAFE_METHODS.items()),
        "",
        f"`math` members: {', '.join(MATH_NAMES)}.",
    ]
    return "\n".join(lines) + "\n"
