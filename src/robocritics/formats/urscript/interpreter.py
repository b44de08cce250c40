"""Run a URScript syntax tree the way the controller would, recording the motion it commands.

Nothing here is Python ``eval``: the tree from :mod:`.syntax` is walked node by node. Every cost is
bounded: statements and expression nodes evaluated (:data:`MAX_STEPS`), call depth and so recursion
(:data:`MAX_CALL_DEPTH`), list and string sizes (:mod:`.builtins`), motions and their duration
(:mod:`.timeline`). A limit hit, a bad value or an unknown name is a :class:`URScriptError` naming the line;
a construct outside the subset an :class:`UnsupportedURScript` naming it and the line.

Loops: a ``while`` whose condition is constant true (PolyScope's "loop forever") or reads an input (a wait
for a sensor) runs for ``passes`` iterations, then the check goes on after it and says so in
:attr:`Interpreter.notes`. Threads: definitions are never refused; ``run`` of a thread that commands no
motion (PolyScope's step counter, RoboDK's ``Synchronize``) is ignored with a note; ``run`` of a thread that
commands motion is refused with the line of its motion command.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from . import poses as P
from .builtins import INPUT_READS, MAX_LIST, NO_OPS, PURE, REFUSED, BuiltinError, type_name
from .syntax import Node, UnsupportedURScript, URScriptError

__all__ = ["Interpreter", "MAX_STEPS", "MAX_CALL_DEPTH", "MAX_ACTIVE_BLOCKS", "MOTION_COMMANDS", "Halt"]

MAX_STEPS = 500_000
MAX_CALL_DEPTH = 48
#: Blocks being run at once, over all active calls (a block inside a block, or a call's body): bounds the
#: interpreter's own recursion, a few Python frames per block, well inside Python's limit of 1,000.
MAX_ACTIVE_BLOCKS = 100
MOTION_COMMANDS = frozenset({"movej", "movel", "movep", "movec", "servoj", "speedj", "speedl", "servoc", "stopj", "stopl"})


class _Break(Exception):
    pass


class _Continue(Exception):
    pass


class _Return(Exception):
    def __init__(self, value: Any):
        self.value = value


class Halt(Exception):
    """``halt`` or the end of the program: stop interpreting."""


@dataclass
class _Function:
    node: Node
    thread: bool


def _int32(x: int) -> int:
    return (x + 2**31) % 2**32 - 2**31


def _arith(op: str, a: Any, b: Any, line: int) -> Any:
    if op in ("==", "!="):
        eq = a == b if not (isinstance(a, list) or isinstance(b, list)) else list(a) == list(b)
        return eq if op == "==" else not eq
    if isinstance(a, bool) or isinstance(b, bool) or not isinstance(a, (int, float)) or not isinstance(b, (int, float)):
        if op == "+" and isinstance(a, str) and isinstance(b, str):
            return a + b
        raise URScriptError(f"{type_name(a)} {op} {type_name(b)} is not defined", line=line)
    if op in ("<", ">", "<=", ">="):
        return {"<": a < b, ">": a > b, "<=": a <= b, ">=": a >= b}[op]
    if op in ("/", "%") and b == 0:
        raise URScriptError(f"division by zero ({a} {op} 0)", line=line)
    if op == "+":
        out = a + b
    elif op == "-":
        out = a - b
    elif op == "*":
        out = a * b
    elif op == "/":
        out = a // b if isinstance(a, int) and isinstance(b, int) and a % b == 0 else a / b
    else:
        out = a % b
    if isinstance(out, int):
        return _int32(out)
    if not math.isfinite(out):
        raise URScriptError(f"{a} {op} {b} overflows", line=line)
    return out


class Interpreter:
    """Walks the tree; ``motion`` (an object with one method per motion command, see :mod:`.commands`) records."""

    def __init__(self, tree: list[Node], motion, *, passes: int = 1, max_steps: int = MAX_STEPS):
        self.tree = tree
        self.motion = motion
        self.passes = passes
        self.max_steps = max_steps
        self.steps = 0
        self.depth = 0
        self.active_blocks = 0
        self.globals: dict[str, Any] = {}
        self.functions: dict[str, _Function] = {}
        self.notes: list[str] = []
        self.loops: list[int] = []  # lines of the loops being run, innermost last
        self.input_reads = 0

    # ------------------------------------------------------------------ entry
    def run(self) -> None:
        """Run the file: its top-level statements, or, when it only defines functions, its last ``def``."""
        executable = [n for n in self.tree if n.kind not in ("def", "thread") and not (n.kind == "assign" and n.scope)]
        try:
            self.block(self.tree, None)
            defs = [n for n in self.tree if n.kind == "def"]
            if not executable and defs:
                main = defs[-1]
                if len(defs) > 1:
                    self.notes.append(f"line {main.line}: the file defines {len(defs)} functions and calls none; ran the last, {main.name}()")
                self.call_user(self.functions[main.name], [], {}, main.line)
        except Halt:
            pass
        except _Return:
            pass  # a `return` at the top level ends the program
        except (_Break, _Continue):
            raise URScriptError("break or continue outside a loop", line=self.loops[-1] if self.loops else 0) from None

    def tick(self, line: int) -> None:
        self.steps += 1
        if self.steps > self.max_steps:
            where = f" (in the loop at line {self.loops[-1]})" if self.loops else ""
            raise URScriptError(f"the script did not finish within {self.max_steps:,} steps{where}", line=line)

    # ------------------------------------------------------------------ statements
    def block(self, body: list[Node], frame: dict | None) -> None:
        self.active_blocks += 1
        try:
            if self.active_blocks > MAX_ACTIVE_BLOCKS:
                line = body[0].line if body else 0
                raise URScriptError(f"blocks and calls nest more than {MAX_ACTIVE_BLOCKS} deep while running", line=line)
            for node in body:
                self.tick(node.line)
                getattr(self, f"_exec_{node.kind}")(node, frame)
        finally:
            self.active_blocks -= 1

    def _exec_def(self, node: Node, frame: dict | None) -> None:
        self.functions[node.name] = _Function(node, node.kind == "thread")

    _exec_thread = _exec_def

    def _exec_expr(self, node: Node, frame: dict | None) -> None:
        self.eval(node.a, frame)

    def _exec_pass(self, node: Node, frame: dict | None) -> None:
        pass

    _exec_enter_critical = _exec_exit_critical = _exec_kill = _exec_join = _exec_pass

    def _exec_halt(self, node: Node, frame: dict | None) -> None:
        raise Halt()

    def _exec_break(self, node: Node, frame: dict | None) -> None:
        raise _Break()

    def _exec_continue(self, node: Node, frame: dict | None) -> None:
        raise _Continue()

    def _exec_return(self, node: Node, frame: dict | None) -> None:
        raise _Return(None if node.a is None else self.eval(node.a, frame))

    def _exec_run(self, node: Node, frame: dict | None) -> Any:
        return self.start_thread(node)

    def _exec_assign(self, node: Node, frame: dict | None) -> None:
        value = self.eval(node.b, frame)
        if node.op != "=":
            value = _arith(node.op[0], self.eval(node.a, frame), value, node.line)
        if isinstance(value, list):
            value = list(value)  # lists are values in URScript: no aliasing
        target = node.a
        if target.kind == "name":
            self.store(target.name, value, frame, node.scope)
            return
        container = self.eval(target.a, frame)
        index = self.index_of(container, self.eval(target.b, frame), target.line)
        if isinstance(container, P.Pose):
            if not isinstance(value, (int, float)) or isinstance(value, bool):
                raise URScriptError(f"a pose element must be a number, got {type_name(value)}", line=node.line)
            items = list(container)
            items[index] = float(value)
            if target.a.kind != "name":
                raise UnsupportedURScript("assignment to an element of an element", node.line)
            self.store(target.a.name, P.Pose(items), frame, "")
        elif isinstance(container, list):
            container[index] = value
        else:
            raise URScriptError(f"cannot assign to an element of {type_name(container)}", line=node.line)

    def store(self, name: str, value: Any, frame: dict | None, scope: str) -> None:
        if scope == "global" or frame is None:
            self.globals[name] = value
        elif scope == "local" or name in frame or name not in self.globals:
            frame[name] = value
        else:
            self.globals[name] = value

    def _exec_if(self, node: Node, frame: dict | None) -> None:
        for cond, body in node.branches:
            if self.truth(self.eval(cond, frame), cond.line):
                self.block(body, frame)
                return
        self.block(node.body, frame)

    def _exec_switch(self, node: Node, frame: dict | None) -> None:
        subject = self.eval(node.a, frame)
        default = None
        for value, body in node.branches:
            if value is None:
                default = body
            elif self.eval(value, frame) == subject:
                self.block(body, frame)
                return
        if default is not None:
            self.block(default, frame)

    def _exec_while(self, node: Node, frame: dict | None) -> None:
        forever = node.a.kind in ("bool", "num") and bool(node.a.value)
        iterations = 0
        self.loops.append(node.line)
        try:
            while True:
                reads = self.input_reads
                if not self.truth(self.eval(node.a, frame), node.line):
                    break
                waits = self.input_reads != reads
                if (forever or waits) and iterations >= self.passes:
                    what = "loops forever" if forever else "waits on an input (assumed to arrive)"
                    self.notes.append(f"line {node.line}: the loop {what}; judged {self.passes} pass(es) (--passes)")
                    break
                iterations += 1
                try:
                    self.block(node.body, frame)
                except _Break:
                    break
                except _Continue:
                    continue
        finally:
            self.loops.pop()

    def _exec_for(self, node: Node, frame: dict | None) -> None:
        bounds = [self.eval(a, frame) for a in node.items]
        if not all(isinstance(b, int) and not isinstance(b, bool) for b in bounds):
            raise URScriptError("range() takes whole numbers", line=node.line)
        self.loops.append(node.line)
        try:
            for i in range(*bounds):
                self.tick(node.line)
                self.store(node.name, i, frame, "")
                try:
                    self.block(node.body, frame)
                except _Break:
                    break
                except _Continue:
                    continue
        finally:
            self.loops.pop()

    # ------------------------------------------------------------------ threads
    def start_thread(self, node: Node) -> int:
        fn = self.functions.get(node.name)
        if fn is None or not fn.thread:
            raise URScriptError(f"run {node.name}(): no thread of that name is defined", line=node.line)
        motion = self.motion_in(fn.node, set())
        if motion is not None:
            raise UnsupportedURScript(
                f"thread {node.name} commanding motion ({motion[0]} at line {motion[1]})",
                node.line,
                "a second thread moving the arm beside the program is not simulated",
            )
        self.notes.append(f"line {node.line}: thread {node.name} commands no motion; ignored")
        return len(self.notes)

    def motion_in(self, fn: Node, seen: set[str]) -> tuple[str, int] | None:
        """The first motion command (name, line) in ``fn``'s body or a user function it calls, else None.

        One walk with an explicit stack (no Python recursion, so a long chain of functions cannot overflow it);
        each function is read once."""
        seen.add(fn.name)
        stack: list[Any] = list(fn.body)
        while stack:
            item = stack.pop()
            if isinstance(item, Node):
                if item.kind == "call":
                    if item.name in MOTION_COMMANDS:
                        return item.name, item.line
                    callee = self.functions.get(item.name)
                    if callee is not None and item.name not in seen:
                        seen.add(item.name)
                        stack.extend(callee.node.body)
                stack.extend([item.a, item.b, *item.items, *item.kwargs.values(), *item.body])
                for cond, body in item.branches:
                    stack.append(cond)
                    stack.extend(body)
        return None

    # ------------------------------------------------------------------ expressions
    def truth(self, value: Any, line: int) -> bool:
        if isinstance(value, (bool, int, float)):
            return bool(value)
        raise URScriptError(f"a condition must be a boolean or number, got {type_name(value)}", line=line)

    def index_of(self, container: Any, index: Any, line: int) -> int:
        if isinstance(index, bool) or not isinstance(index, int):
            if isinstance(index, float) and index.is_integer():
                index = int(index)
            else:
                raise URScriptError(f"an index must be a whole number, got {type_name(index)}", line=line)
        if not isinstance(container, (list, P.Pose, str)):
            raise URScriptError(f"{type_name(container)} cannot be indexed", line=line)
        if not 0 <= index < len(container):
            raise URScriptError(f"index {index} is out of range for {type_name(container)}", line=line)
        return index

    def lookup(self, name: str, frame: dict | None, line: int) -> Any:
        if frame is not None and name in frame:
            return frame[name]
        if name in self.globals:
            return self.globals[name]
        raise URScriptError(f"the variable {name!r} is used before it is assigned", line=line)

    def eval(self, node: Node, frame: dict | None) -> Any:
        self.tick(node.line)
        kind = node.kind
        if kind in ("num", "str", "bool"):
            if kind == "num" and not math.isfinite(node.value):
                raise URScriptError(f"the number {node.value} is out of range", line=node.line)
            return node.value
        if kind == "name":
            return self.lookup(node.name, frame, node.line)
        if kind == "binary":
            return self.binary(node, frame)
        if kind == "unary":
            value = self.eval(node.a, frame)
            if node.op == "not":
                return not self.truth(value, node.line)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise URScriptError(f"{node.op}{type_name(value)} is not defined", line=node.line)
            return -value if node.op == "-" else value
        if kind == "list":
            return [self.eval(item, frame) for item in node.items]
        if kind == "pose":
            items = [self.eval(item, frame) for item in node.items]
            if len(items) != 6 or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in items):
                raise URScriptError("a pose literal p[...] takes 6 numbers", line=node.line)
            return P.Pose(items)
        if kind == "index":
            container = self.eval(node.a, frame)
            return container[self.index_of(container, self.eval(node.b, frame), node.line)]
        if kind == "call":
            return self.call(node, frame)
        if kind == "run":
            return self.start_thread(node)
        raise UnsupportedURScript(kind, node.line)

    def binary(self, node: Node, frame: dict | None) -> Any:
        op = node.op
        if op in ("and", "or"):
            left = self.truth(self.eval(node.a, frame), node.line)
            if (op == "and" and not left) or (op == "or" and left):
                return left
            return self.truth(self.eval(node.b, frame), node.line)
        a, b = self.eval(node.a, frame), self.eval(node.b, frame)
        if op == "xor":
            return self.truth(a, node.line) != self.truth(b, node.line)
        return _arith(op, a, b, node.line)

    # ------------------------------------------------------------------ calls
    def call(self, node: Node, frame: dict | None) -> Any:
        name = node.name
        args = [self.eval(a, frame) for a in node.items]
        kwargs = {k: self.eval(v, frame) for k, v in node.kwargs.items()}
        handler = self.motion.handler(name)
        if handler is not None:  # motion, gripper, pose queries: the simulated arm (ahead of a same-named def)
            self.motion.at(node.line)
            return self.with_line(handler, args, kwargs, node)
        fn = self.functions.get(name)
        if fn is not None:
            if fn.thread:
                raise URScriptError(f"{name} is a thread: start it with run {name}()", line=node.line)
            return self.call_user(fn, args, kwargs, node.line)
        if name in INPUT_READS:
            self.input_reads += 1  # a loop waiting on this waits for the outside world
        if name in PURE:
            return self.with_line(PURE[name], args, kwargs, node)
        if name in NO_OPS or name.startswith("rq_"):
            if name in INPUT_READS:
                return 0 if "integer" in name or "float" in name or "analog" in name else False
            return None  # messages, outputs, sockets, installation settings, Robotiq driver internals
        if name in REFUSED:
            raise UnsupportedURScript(f"{name}()", node.line, REFUSED[name])
        raise UnsupportedURScript(f"{name}()", node.line, "not a URScript function robocritics knows, nor defined in the file")

    def with_line(self, fn, args: list, kwargs: dict, node: Node) -> Any:
        try:
            value = fn(*args, **kwargs)
        except BuiltinError as exc:
            raise URScriptError(f"{node.name}(): {str(exc)[:300]}", line=node.line) from None
        except TypeError as exc:
            raise URScriptError(f"{node.name}(): wrong arguments ({exc})", line=node.line) from None
        if isinstance(value, list) and len(value) > MAX_LIST:
            raise URScriptError(f"{node.name}() made a list of more than {MAX_LIST:,} items", line=node.line)
        if isinstance(value, float) and not math.isfinite(value):
            raise URScriptError(f"{node.name}() gave {value}, not a finite number", line=node.line)
        return value

    def call_user(self, fn: _Function, args: list, kwargs: dict, line: int) -> Any:
        params = fn.node.params
        if len(args) > len(params):
            raise URScriptError(f"{fn.node.name}() takes {len(params)} arguments, got {len(args)}", line=line)
        local: dict[str, Any] = {}
        for i, (pname, default) in enumerate(params):
            if i < len(args):
                local[pname] = args[i]
            elif pname in kwargs:
                local[pname] = kwargs.pop(pname)
            elif default is not None:
                local[pname] = self.eval(default, None)
            else:
                raise URScriptError(f"{fn.node.name}() is missing the argument {pname!r}", line=line)
        if kwargs:
            raise URScriptError(f"{fn.node.name}() has no parameter {next(iter(kwargs))!r}", line=line)
        self.depth += 1
        if self.depth > MAX_CALL_DEPTH:
            raise URScriptError(f"calls nest more than {MAX_CALL_DEPTH} deep (recursion?) in {fn.node.name}()", line=line)
        try:
            self.block(fn.node.body, local)
        except _Return as ret:
            return ret.value
        except (_Break, _Continue):
            raise URScriptError(f"break or continue outside a loop in {fn.node.name}()", line=fn.node.line) from None
        finally:
            self.depth -= 1
        return None
