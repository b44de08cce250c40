"""The AST interpreter that runs a checked program: statements, expressions, names, calls.

Every evaluated node and every step is paid to the run's
:class:`~robocritics.program.meter.Meter` (which reads the clock every few hundred
units, so the deadline is checked inside long expressions too); the work of
operations on values is priced by the mixins (:mod:`.operations`,
:mod:`.builtins`, :mod:`.methods`).

The interpreter recurses in Python for nested calls and expressions but never
changes the process's recursion limit: at every call it counts the Python
frames it is using (:meth:`_Interpreter._enter_call`) and refuses to go past a
fixed room that fits under the limit, so runs in several threads never
disturb each other.
"""

from __future__ import annotations

import ast
import math
import sys
from itertools import islice
from typing import Any, Callable, Iterator

from ..errors import ProgramError
from ..scene import Scene
from .budget import Budget, BudgetError
from .builtins import _Builtins
from .check import MATH_ALL, MODULE_ALIASES, Source, quote
from .keys import KeyGuard
from .frames import released, stack_depth
from .messages import ALLOWED_METHODS, attr_message, called_from, usage
from .language import EXPRESSION_TYPES, MATH_NAMES, SAFE_BUILTINS, STATEMENT_TYPES
from .meter import MAKE_OPS, SLOT_BYTES, LimitReached, Meter
from .methods import _Methods
from .operations import TUPLE_ITERATORS, _Operations, produced_size
from .plan import Plan
from .render import bounded_repr, clip
from .skills import SKILLS, Namespace, ObjectView, Recorder, _close_names, _CURRENT
from .values import (
    MISSING,
    _Break,
    _Builtin,
    _Continue,
    _Method,
    _Return,
    _SandboxFunction,
    _Scope,
    _Signal,
    clean,
    signature,
    tname,
)

__all__: list[str] = []

_MAX_INTERPRETER_FRAMES = 600
"""Python frames the interpreter may use for nested calls (a call takes ~8 frames plus ~2 per level of the
expression it sits in): room for ``max_call_depth`` plain recursive calls."""
_RESERVED_FRAMES = 300
"""Frames kept free under the recursion limit above the last call: nested expressions (up to ``max_nesting``
levels at ~2 frames each), a builtin, a skill and the error handling that may follow."""
_CALL_UNITS = 4
"""Work units of a call beyond its nodes: binding the arguments, making the scope, counting the frames."""
_FUNCTION_UNITS = 2
"""Work units of making a function (``def`` or ``lambda``) beyond its nodes."""
_CALL_SCOPE_BYTES = 200
"""Memory of one call's scope (a dict of its variables and the scope record)."""
_FUNCTION_BYTES = 200
"""Memory of one function object the program defines (``def`` or ``lambda``)."""
_MAX_KEYS_SHOWN = 20
"""Keys listed in a KeyError message."""
_SUGGESTED_KEYS = 1_000
"""A mistyped dict key is compared with at most this many of the dict's string keys."""

# math functions whose C versions would iterate without limits: the interpreter implements them (_m_<name>)
_MATH_WRAPPED = ("fsum", "prod", "dist")



_BIG_INT_ARG = 2**64
"""Integers from this size on cost a math function big-int work (paid like writing them in decimal)."""


class _Interpreter(_Builtins, _Methods, _Operations):
    def __init__(self, source: str, tree: ast.Module, scene: Scene, budget: Budget):
        self.tree = tree
        self.b = budget
        self.src = Source(source)
        self.plan = Plan(source=source, calls=[], output=[])
        self.rec = Recorder(scene, self.plan, budget)
        self.meter = Meter(budget)
        self.keys = KeyGuard(self.meter)
        self.depth = 0
        self.call_lines: list[int] = []
        self.loops: list[Any] = []
        self.frame_marks: list[tuple[Any, int]] = []
        """(frame of a running call, interpreter frames in use up to it), innermost last."""
        self.frame_room = 0
        self.module_scope = _Scope({}, None, None, "<module>")
        self.closure_scopes: list[_Scope] = []
        """Scopes in which the program made a function: the function and the scope refer to each other."""
        self._call_node: Any = None
        self._locals_cache: dict[int, frozenset] = {}
        self._exec_table = {t: getattr(self, "_exec_" + t.__name__) for t in STATEMENT_TYPES}
        self._eval_table = {t: getattr(self, "_eval_" + t.__name__) for t in EXPRESSION_TYPES}
        self.modules, self.base = self._namespace(self.rec.views)

    def _namespace(self, views: dict[str, ObjectView]) -> tuple[dict[str, Namespace], dict[str, Any]]:
        """The modules ``lib`` and ``math``, and every name a program sees before it assigns any."""
        lib_members = {name: _Builtin(name, fn, "skill") for name, fn in SKILLS.items()}
        math_members: dict[str, Any] = {}
        for name in MATH_NAMES:
            if name in _MATH_WRAPPED:
                math_members[name] = _Builtin(name, getattr(self, "_m_" + name), "builtin")
                continue
            value = getattr(math, name)
            math_members[name] = _Builtin(name, value, "math", bind=False) if callable(value) else value
        modules = {"lib": Namespace("lib", lib_members, "skill"), "math": Namespace("math", math_members, "member")}
        base: dict[str, Any] = {name: _Builtin(name, getattr(self, "_b_" + name), "builtin") for name in SAFE_BUILTINS}
        base.update(lib_members)
        base["lib"] = modules["lib"]
        base["math"] = modules["math"]
        base["objects"] = [v for v in views.values() if v._fields["kind"] == "object"]
        base["containers"] = [v for v in views.values() if v._fields["kind"] == "container"]
        base.update(views)
        return modules, base

    # ---- running ----------------------------------------------------------------------

    def run(self) -> Plan:
        token = _CURRENT.set(self.rec)
        error: ProgramError | None = None
        try:
            self.frame_room = min(_MAX_INTERPRETER_FRAMES, sys.getrecursionlimit() - stack_depth() - _RESERVED_FRAMES)
            self.frame_marks = [(sys._getframe(), 0)]
            self.meter.start()
            self._exec_block(self.tree.body, self.module_scope)
        except ProgramError as exc:
            error = exc
        except RecursionError:  # a backstop: _enter_call stops calls well before the recursion limit
            error = BudgetError("the program nests too deeply (deep recursion or nested expressions)", limit="max_call_depth")
        except MemoryError:
            error = BudgetError("the program ran out of memory; keep lists and strings small", limit="max_alloc_bytes")
        finally:
            _CURRENT.reset(token)
            self._forget()
        if error is not None:
            raise released(error)
        return self.plan

    def _forget(self) -> None:
        """Drop what ties the interpreter to itself and to the program's values (its builtins are its own bound
        methods, a reference cycle), so everything the run made is freed when the run ends, not at the next
        garbage collection. The plan and the meter stay."""
        self.base, self.modules, self._exec_table, self._eval_table = {}, {}, {}, {}
        self.keys = KeyGuard(self.meter)
        self.frame_marks = []
        for scope in (self.module_scope, *self.closure_scopes):
            scope.vars.clear()
        self.closure_scopes = []

    # ---- errors -----------------------------------------------------------------------

    def _pos(self, node: Any) -> tuple[int, int]:
        line = getattr(node, "lineno", 0) or 0
        return line, self.src.col(line, getattr(node, "col_offset", None))

    def _error(self, message: str, node: Any) -> ProgramError:
        line, col = self._pos(node)
        return ProgramError(clip(message), line, col)

    def _limit(self, message: str, node: Any, limit: str) -> BudgetError:
        """The error for passing the Budget field ``limit`` at ``node``."""
        line, col = self._pos(node)
        return BudgetError(clip(message), line, col, limit=limit)

    def _limit_error(self, hit: LimitReached, node: Any) -> BudgetError:
        return self._limit(hit.message, node, hit.limit)

    def _attr_error(self, message: str, node: ast.Attribute) -> ProgramError:
        line = node.end_lineno or node.lineno
        col = self.src.col(line, (node.end_col_offset or 0) - len(node.attr.encode("utf-8")))
        return ProgramError(clip(message), line, col)

    def _convert(self, exc: BaseException, node: Any) -> ProgramError:
        """A ProgramError at ``node`` for an exception raised by an operation, its message bounded."""
        if isinstance(exc, RecursionError):
            return self._limit(
                "the program nests too deeply (deep recursion or nested expressions); simplify it",
                node,
                "max_call_depth",
            )
        if isinstance(exc, MemoryError):
            return self._limit("the program ran out of memory; keep lists and strings small", node, "max_alloc_bytes")
        if isinstance(exc, KeyError):  # the key itself, which str(exc) would print in full
            text = bounded_repr(exc.args[0]) if exc.args else ""
        else:
            text = ", ".join(clip(a) if type(a) is str else bounded_repr(a) for a in exc.args)
        text = clean(clip(text))
        return self._error(f"{type(exc).__name__}: {text}" if text else type(exc).__name__, node)

    def _tick(self, node: Any) -> None:
        """Count a step at ``node``; a program that runs too many is stopped at its innermost loop."""
        try:
            self.meter.step()
        except LimitReached as hit:
            where = self.loops[-1] if self.loops and hit.limit == "max_steps" else node
            raise self._limit_error(hit, where) from None

    def _charge_produced(self, item: Any, node: Any) -> None:
        """Pay for the tuple a zip(), enumerate() or items() iterator just made for one loop iteration."""
        try:
            self.meter.spend_ops(MAKE_OPS * produced_size(item, self.b.max_nodes))
        except LimitReached as hit:
            raise self._limit_error(hit, node) from None

    # ---- statements -------------------------------------------------------------------

    def _exec_block(self, body: list, scope: _Scope) -> None:
        table = self._exec_table
        for stmt in body:
            try:
                self._tick(stmt)
                table[type(stmt)](stmt, scope)
            except (ProgramError, _Signal):
                raise
            except LimitReached as hit:
                raise self._limit_error(hit, stmt) from None
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

        makes_tuples = type(it) in TUPLE_ITERATORS

        def iterations() -> Iterator[None]:
            for item in it:
                self._tick(node)
                if makes_tuples:
                    self._charge_produced(item, node)
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
            module = self.modules[MODULE_ALIASES[alias.name]]
            scope.vars[alias.asname or alias.name] = module

    def _exec_ImportFrom(self, node: ast.ImportFrom, scope: _Scope) -> None:
        module = self.modules[MODULE_ALIASES[node.module or ""]]
        for alias in node.names:
            scope.vars[alias.asname or alias.name] = module._lookup(alias.name)

    def _exec_Assert(self, node: ast.Assert, scope: _Scope) -> None:
        if not self._eval(node.test, scope):
            message = "assertion failed"
            if node.msg is not None:
                text = clip(self._to_str(self._eval(node.msg, scope), node.msg))
                # control characters escaped: the message is printed to terminals and sent to the LLM as is
                message += ": " + "".join(c if c.isprintable() else c.encode("unicode_escape").decode() for c in text)
            raise self._error(message, node)

    def _exec_Delete(self, node: ast.Delete, scope: _Scope) -> None:
        for target in node.targets:
            self._delete(target, scope)

    def _delete(self, target: Any, scope: _Scope) -> None:
        if isinstance(target, ast.Name):
            if target.id in scope.vars:
                del scope.vars[target.id]
            else:
                raise self._error(f"NameError: name {quote(target.id)} is not defined here", target)
        elif isinstance(target, ast.Subscript):
            obj = self._eval(target.value, scope)
            key = self._eval(target.slice, scope)
            try:
                self._delitem(obj, key, target)
            except (ProgramError, LimitReached):
                raise
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
            if type(value) in (list, tuple, str, dict, set, range) and not starred:
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
        rest = self._made(items[i : len(items) - after])
        self._assign(elts[i].value, rest, scope)
        for elt, item in zip(elts[i + 1 :], items[len(items) - after :]):
            self._assign(elt, item, scope)

    # ---- items ----------------------------------------------------------------------------

    def _getitem(self, obj: Any, key: Any, node: Any) -> Any:
        t = type(obj)
        if t is dict:
            self.keys.lookup(key)
            try:
                return obj[key]
            except KeyError:
                raise self._key_error(obj, key, node) from None
        if t is list or t is tuple or t is str or t is range:
            if type(key) is slice:
                result = obj[key]
                if t is not range:
                    self.meter.spend_ops(len(result))
                return self._made(result)
            try:
                return obj[key]
            except IndexError:
                if type(key) is int:
                    raise self._error(
                        f"IndexError: index {bounded_repr(key)} is out of range for a {t.__name__} of length "
                        f"{len(obj)}",
                        node,
                    ) from None
                raise
        hint = ""
        if t is ObjectView:
            hint = f"; use fields such as {obj._id}.position or {obj._id}.attributes['colour']"
        raise TypeError(f"'{tname(obj)}' object is not subscriptable{hint}")

    def _key_error(self, d: dict, key: Any, node: Any) -> ProgramError:
        hint = _close_names(key, islice((k for k in d if type(k) is str), _SUGGESTED_KEYS)) if type(key) is str else ""
        shown = ", ".join(bounded_repr(k) for k in islice(d, _MAX_KEYS_SHOWN))
        more = f" and {len(d) - _MAX_KEYS_SHOWN} more" if len(d) > _MAX_KEYS_SHOWN else ""
        return self._error(
            f"KeyError: key {bounded_repr(key)} is not in the dict{hint or '.'} Keys: {shown or '(none)'}{more}", node
        )

    def _setitem(self, obj: Any, key: Any, value: Any, node: Any) -> None:
        t = type(obj)
        if t is dict:
            self._dict_store(obj, key, value, node)
        elif t is list:
            if type(key) is slice:
                items = list(self._items(value, node, "the assigned sequence"))
                before = len(obj)
                self._grow(before, len(items), node)
                self.meter.spend_ops(before + len(items))
                obj[key] = items
                self.meter.allocate(SLOT_BYTES * max(len(obj) - before, 0))
            else:
                try:
                    obj[key] = value
                except IndexError:
                    if type(key) is int:
                        raise self._error(
                            f"IndexError: index {bounded_repr(key)} is out of range for a list of length {len(obj)}",
                            node,
                        ) from None
                    raise
        else:
            hint = "; scene objects are read-only" if t is ObjectView else ""
            if t is tuple or t is str:
                hint = f"; a {t.__name__} cannot be changed, build a new one or use a list"
            raise TypeError(f"'{tname(obj)}' object does not support item assignment{hint}")

    def _delitem(self, obj: Any, key: Any, node: Any) -> None:
        t = type(obj)
        if t is dict:
            self.keys.lookup(key)
        elif t is list:
            self.meter.spend_ops(len(obj))
        else:
            raise TypeError(f"'{tname(obj)}' object does not support item deletion")
        del obj[key]

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
        self.meter.spend(_FUNCTION_UNITS)
        self.meter.allocate(_FUNCTION_BYTES)
        if scope is not self.module_scope and (not self.closure_scopes or self.closure_scopes[-1] is not scope):
            self.closure_scopes.append(scope)
        return _SandboxFunction(name, params, kwonly, defaults, scope, local_names, body, is_lambda)

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
        name = quote(fn.name)[1:-1]
        if len(args) > len(params):
            raise TypeError(
                f"{name}() takes {len(params)} positional argument{'s' if len(params) != 1 else ''} "
                f"but {len(args)} {'were' if len(args) != 1 else 'was'} given"
            )
        values = dict(zip(params, args))
        for key, value in kwargs.items():
            if key in values:
                raise TypeError(f"{name}() got multiple values for argument {quote(key)}")
            if key not in params and key not in fn.kwonly:
                raise TypeError(
                    f"{name}() got an unexpected keyword argument {quote(key)}"
                    f"{_close_names(key, (*params, *fn.kwonly), 1)}"
                )
            values[key] = value
        for p in (*params, *fn.kwonly):
            if p not in values:
                if p in fn.defaults:
                    values[p] = fn.defaults[p]
                else:
                    raise TypeError(f"{name}() missing required argument {quote(p)}")
        return values

    def _enter_call(self, node: Any) -> None:
        """Count the Python frames the interpreter uses up to this call (only those since the enclosing call
        are walked) and refuse the call past the room it has under the recursion limit."""
        frame = sys._getframe(1)
        mark, in_use = self.frame_marks[-1]
        f = frame
        while f is not None and f is not mark:
            in_use += 1
            f = f.f_back
        if in_use > self.frame_room:
            raise self._limit(
                f"function calls nest too deeply: {self.depth} calls deep, with the expressions around them, need "
                f"more than {self.frame_room} interpreter frames; use a loop instead of deep recursion",
                node,
                "max_call_depth",
            )
        self.frame_marks.append((frame, in_use))

    def _invoke(self, fn: _SandboxFunction, args: Any, kwargs: dict, node: Any) -> Any:
        if self.depth >= self.b.max_call_depth:
            raise self._limit(
                f"function calls nest more than {self.b.max_call_depth} deep; does a recursive function lack a "
                "base case? Use a loop instead",
                node,
                "max_call_depth",
            )
        self._tick(node)
        try:
            self.meter.spend(_CALL_UNITS)
            self.meter.allocate(_CALL_SCOPE_BYTES)
            values = self._bind(fn, args, kwargs)
        except LimitReached as hit:
            raise self._limit_error(hit, node) from None
        except TypeError as exc:
            raise self._convert(exc, node) from None
        self._enter_call(node)
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
            raise called_from(exc, fn, line) from None
        finally:
            self.depth -= 1
            self.call_lines.pop()
            self.frame_marks.pop()

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
        raise TypeError(f"'{tname(func)}' object is not callable{hint}")

    def _call_builtin(self, b: _Builtin, args: Any, kwargs: dict) -> Any:
        node = self._call_node
        if b.sig is not None:
            try:
                b.sig.bind(*args, **kwargs)
            except TypeError as exc:
                text = str(exc)
                unexpected = text.split("unexpected keyword argument ", 1)
                hint = _close_names(unexpected[1].strip("'"), b.sig.parameters, 1) if len(unexpected) > 1 else ""
                raise self._error(f"{b.name}(): {text}{hint}; usage: {usage(b)}", node) from None
        if b.kind == "skill" or b.name == "print":
            line, col = self._pos(node)
            self.rec.where = (line, col, tuple(self.call_lines))
        if b.kind == "math":
            self.meter.spend_ops(len(args))
            for a in args:  # gcd, isqrt, log... of big integers do big-int division: quadratic in their length
                if type(a) is int and not -_BIG_INT_ARG < a < _BIG_INT_ARG:
                    self._charge_int_text(a)
            return self._new_value(b.fn(*args, **kwargs), node)
        return b.fn(*args, **kwargs)

    # ---- expressions ------------------------------------------------------------------

    def _eval(self, node: Any, scope: _Scope) -> Any:
        meter = self.meter
        meter.work += 1
        try:
            if meter.work >= meter.alarm:
                meter.check()
            return self._eval_table[type(node)](node, scope)
        except (ProgramError, _Signal):
            raise
        except LimitReached as hit:
            raise self._limit_error(hit, node) from None
        except Exception as exc:
            raise self._convert(exc, node) from None

    def _eval_Constant(self, node: ast.Constant, scope: _Scope) -> Any:
        return node.value

    def _eval_Name(self, node: ast.Name, scope: _Scope) -> Any:
        name = node.id
        s: _Scope | None = scope
        while s is not None:
            value = s.vars.get(name, MISSING)
            if value is not MISSING:
                return value
            if s.locals is not None and name in s.locals:
                raise self._error(
                    f"UnboundLocalError: local variable {quote(name)} is used before it is assigned in "
                    f"{quote(s.fname)[1:-1]}()"
                    + (
                        "; assigning to a name anywhere in a function makes it local there: use another name "
                        "or pass the value as an argument"
                        if self._defined_outside(name, s)
                        else ""
                    ),
                    node,
                )
            s = s.parent
        value = self.base.get(name, MISSING)
        if value is not MISSING:
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
        if name in MATH_ALL:
            return f"name {name!r} is not defined; did you mean math.{name}? (or write 'from math import {name}')"
        candidates: set[str] = set(self.base)
        s: _Scope | None = scope
        while s is not None:
            candidates.update(s.vars)
            if s.locals:
                candidates.update(s.locals)
            s = s.parent
        text = f"name {quote(name)} is not defined{_close_names(name, sorted(candidates))}"
        if not text.endswith("?"):
            ids = list(self.rec.views)
            text += f". Skills: {', '.join(SKILLS)}; scene objects: {', '.join(ids) or '(none)'}"
        return text

    def _eval_Attribute(self, node: ast.Attribute, scope: _Scope) -> Any:
        return self._attribute(self._eval(node.value, scope), node)

    def _attribute(self, obj: Any, node: ast.Attribute) -> Any:
        name = node.attr
        t = type(obj)
        if t is ObjectView or t is Namespace:
            try:
                value = obj._lookup(name)
            except AttributeError as exc:
                raise self._attr_error(str(exc), node) from None
            if type(value) in (dict, list):  # a fresh copy of scene data
                self._made(value)
            return value
        allowed = ALLOWED_METHODS.get(t)
        if allowed is not None and name in allowed:
            return self._made(_Method(obj, name))
        raise self._attr_error(attr_message(obj, name), node)

    def _eval_Subscript(self, node: ast.Subscript, scope: _Scope) -> Any:
        obj = self._eval(node.value, scope)
        key = self._eval(node.slice, scope)
        return self._getitem(obj, key, node)

    def _eval_Slice(self, node: ast.Slice, scope: _Scope) -> Any:
        parts = []
        for part in (node.lower, node.upper, node.step):
            value = None if part is None else self._eval(part, scope)
            if value is not None and type(value) not in (int, bool):
                raise TypeError(f"slice indices must be whole numbers or None, not {tname(value)}")
            parts.append(value)
        return slice(*parts)

    def _eval_Call(self, node: ast.Call, scope: _Scope) -> Any:
        func_node = node.func
        if type(func_node) is ast.Attribute:  # obj.method(...) calls the method without making it a value
            obj = self._eval(func_node.value, scope)
            allowed = ALLOWED_METHODS.get(type(obj))
            if allowed is not None and func_node.attr in allowed:
                args, kwargs = self._arguments(node, scope)
                return self._call(_Method(obj, func_node.attr), args, kwargs, node)
            func = self._attribute(obj, func_node)
        else:
            func = self._eval(func_node, scope)
        args, kwargs = self._arguments(node, scope)
        return self._call(func, args, kwargs, node)

    def _arguments(self, node: ast.Call, scope: _Scope) -> tuple[list, dict]:
        args: list[Any] = []
        for a in node.args:
            if type(a) is ast.Starred:
                value = self._eval(a.value, scope)
                try:
                    args.extend(self._items(value, a, "the '*' argument"))
                except TypeError as exc:
                    raise self._convert(exc, a) from None
                if len(args) > self.b.max_len:
                    raise self._limit(f"too many arguments (more than {self.b.max_len})", a, "max_len")
            else:
                args.append(self._eval(a, scope))
        kwargs = {kw.arg: self._eval(kw.value, scope) for kw in node.keywords}
        return args, kwargs

    def _eval_BinOp(self, node: ast.BinOp, scope: _Scope) -> Any:
        left = self._eval(node.left, scope)
        right = self._eval(node.right, scope)
        return self._binop(type(node.op), left, right, node)

    def _eval_UnaryOp(self, node: ast.UnaryOp, scope: _Scope) -> Any:
        return self._unaryop(type(node.op), self._eval(node.operand, scope), node)

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

    def _eval_IfExp(self, node: ast.IfExp, scope: _Scope) -> Any:
        return self._eval(node.body if self._eval(node.test, scope) else node.orelse, scope)

    def _elements(self, elts: list, scope: _Scope, node: Any) -> list:
        out: list[Any] = []
        for e in elts:
            if type(e) is ast.Starred:
                value = self._eval(e.value, scope)
                try:
                    items = self._items(value, e, "the '*' expansion")
                except TypeError as exc:
                    raise self._convert(exc, e) from None
                self._grow(len(out), len(items), node)
                self.meter.spend_ops(len(items))
                out.extend(items)
            else:
                out.append(self._eval(e, scope))
        self._check_len(len(out), node)
        return out

    def _eval_List(self, node: ast.List, scope: _Scope) -> Any:
        return self._made(self._elements(node.elts, scope, node))

    def _eval_Tuple(self, node: ast.Tuple, scope: _Scope) -> Any:
        return self._made(tuple(self._elements(node.elts, scope, node)))

    def _eval_Set(self, node: ast.Set, scope: _Scope) -> Any:
        return self._set_of(self._elements(node.elts, scope, node), node)

    def _eval_Dict(self, node: ast.Dict, scope: _Scope) -> Any:
        out: dict[Any, Any] = {}
        for k, v in zip(node.keys, node.values):
            key = self._eval(k, scope)
            self.keys.admit(key)
            out[key] = self._eval(v, scope)
        self._check_len(len(out), node, "a dict")
        return self._made(out)

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
            makes_tuples = type(it) in TUPLE_ITERATORS
            for item in it:
                self._tick(node)
                if makes_tuples:
                    self._charge_produced(item, node)
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
            loop = None  # noqa: F841 - the function refers to itself through this variable: break the cycle

    def _eval_ListComp(self, node: ast.ListComp, scope: _Scope) -> Any:
        out: list[Any] = []
        limit = self.b.max_len

        def emit(inner: _Scope) -> None:
            out.append(self._eval(node.elt, inner))
            if len(out) > limit:
                self._check_len(len(out), node)
            self.meter.allocate(SLOT_BYTES)

        self._comprehension(node, scope, emit)
        return self._made(out)

    _eval_GeneratorExp = _eval_ListComp  # evaluated eagerly (bounded like a list)

    def _eval_SetComp(self, node: ast.SetComp, scope: _Scope) -> Any:
        out: set[Any] = set()

        def emit(inner: _Scope) -> None:
            self._set_store(out, self._eval(node.elt, inner), node)

        self._comprehension(node, scope, emit)
        return self._made(out)

    def _eval_DictComp(self, node: ast.DictComp, scope: _Scope) -> Any:
        out: dict[Any, Any] = {}

        def emit(inner: _Scope) -> None:
            key = self._eval(node.key, inner)
            self._dict_store(out, key, self._eval(node.value, inner), node)

        self._comprehension(node, scope, emit)
        return self._made(out)

    def _eval_Lambda(self, node: ast.Lambda, scope: _Scope) -> Any:
        return self._make_function("<lambda>", node.args, node.body, True, node, scope)

    def _eval_JoinedStr(self, node: ast.JoinedStr, scope: _Scope) -> Any:
        parts = []
        total = 0
        for v in node.values:
            text = v.value if type(v) is ast.Constant else self._eval(v, scope)
            total += len(text)
            self._check_str(total, node)
            parts.append(text)
        self.meter.spend_chars(total)
        return self._made("".join(parts))

    def _eval_FormattedValue(self, node: ast.FormattedValue, scope: _Scope) -> Any:
        value = self._eval(node.value, scope)
        spec = "" if node.format_spec is None else self._eval(node.format_spec, scope)
        if node.conversion == ord("r"):
            value = self._to_str(value, node, use_repr=True)
        elif node.conversion == ord("a"):
            value = self._to_str(value, node, use_repr=True).encode("ascii", "backslashreplace").decode("ascii")
            self._check_str(len(value), node)
        elif node.conversion == ord("s"):
            value = self._to_str(value, node)
        if not spec:
            return self._to_str(value, node)
        return self._format(value, spec, node)

    def _eval_Starred(self, node: ast.Starred, scope: _Scope) -> Any:  # pragma: no cover - rejected statically
        raise self._error("'*' is not allowed here", node)


# Compute every signature at import time so that running a program never imports anything.
for _fn in SKILLS.values():
    signature(_fn)
for _name in dir(_Interpreter):
    if _name.startswith(("_b_", "_m_")):
        signature(getattr(_Interpreter, _name), method=True)
