"""The interpreter's own runtime values: scopes, control-flow signals, and the functions a program sees.

None of these classes is callable from C: a program's functions, builtins and
methods are only ever called by the interpreter (``_Interpreter._call``), so a
builtin such as ``sorted`` can never re-enter the interpreter with work or
stack frames nobody counted.
"""

from __future__ import annotations

import inspect
import re
from typing import Any, Callable

from .skills import Namespace, ObjectView

__all__: list[str] = []


class Signal(BaseException):
    """Control flow (break/continue/return); never caught by error conversion."""


class Break(Signal):
    pass


class Continue(Signal):
    pass


class Return(Signal):
    def __init__(self, value: Any):
        self.value = value


class Scope:
    """The variables of the module, of one function call or of one comprehension."""

    __slots__ = ("vars", "locals", "parent", "fname")

    def __init__(self, vars: dict, locals: frozenset | None, parent: "Scope | None", fname: str):
        self.vars = vars
        self.locals = locals  # None for the module scope (everything assigned there is global)
        self.parent = parent
        self.fname = fname


class _SandboxFunction:
    """A function defined by the program (``def`` or ``lambda``)."""

    __slots__ = ("name", "params", "kwonly", "defaults", "closure", "locals", "body", "is_lambda")

    def __init__(self, name, params, kwonly, defaults, closure, locals_, body, is_lambda):
        self.name = name
        self.params = params
        self.kwonly = kwonly
        self.defaults = defaults
        self.closure = closure
        self.locals = locals_
        self.body = body
        self.is_lambda = is_lambda

    def __repr__(self) -> str:
        return f"<function {self.name}>"


_SIGNATURES: dict[Any, inspect.Signature] = {}


def signature(fn: Callable, method: bool = False) -> inspect.Signature:
    """The signature of a skill or a builtin method (without ``self``), computed once per process."""
    func = getattr(fn, "__func__", fn)
    sig = _SIGNATURES.get(func)
    if sig is None:
        sig = inspect.signature(func)
        if method or func is not fn:
            sig = sig.replace(parameters=list(sig.parameters.values())[1:])
        _SIGNATURES[func] = sig
    return sig


class _Builtin:
    """A builtin, skill or math function as the program sees it. ``fn`` is called by the interpreter only."""

    __slots__ = ("name", "fn", "kind", "sig")

    def __init__(self, name: str, fn: Callable, kind: str, bind: bool = True):
        self.name = name
        self.fn = fn
        self.kind = kind
        self.sig = signature(fn) if bind else None

    def __repr__(self) -> str:
        return f"<skill {self.name}>" if self.kind == "skill" else f"<built-in function {self.name}>"


class _Method:
    """A method of one of the program's own values (``items.append``), taken as a value."""

    __slots__ = ("obj", "name")

    def __init__(self, obj: Any, name: str):
        self.obj = obj
        self.name = name

    def __repr__(self) -> str:
        return f"<method {type(self.obj).__name__}.{self.name}>"


CALLABLES = (_SandboxFunction, _Builtin, _Method)


class _NoValue:
    def __repr__(self) -> str:
        return "<no value>"


NOVALUE = _NoValue()
"""The default of optional arguments whose absence matters (``max(..., default=...)``)."""
MISSING = object()

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


def tname(value: Any) -> str:
    """The type name of ``value`` as a program knows it."""
    return _TYPE_NAMES.get(type(value), type(value).__name__)


def clean(message: str) -> str:
    """``message`` with the sandbox's class names replaced by the names a program knows."""
    return _INTERNAL_NAMES.sub(lambda m: _CLEAN_NAMES[m.group(1)], message)


def check_callable(fn: Any, what: str) -> None:
    if type(fn) not in CALLABLES:
        raise TypeError(f"{what} must be a function, got {tname(fn)}")
