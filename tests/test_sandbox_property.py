"""Property: random programs from the grammar of the allowed subset never escape and never exceed their budget.

Hypothesis writes programs of the sandbox's own language (assignments, ``if``,
``for``/``while`` loops, functions, comprehensions, displays, f-strings, calls to
the builtins, methods, ``math`` and the skills), with the sizes an attacker would
pick (``10**6`` iterations, ``'x' * 10**5``, ``2 ** 4000``, nested repetition), and
runs each under a small Budget whose clock is this thread's CPU time. Whatever
the program does:

* nothing outside the skill API runs: an audit hook, armed only during the run,
  sees no import, open, exec, os/subprocess/socket call or other event beyond
  parsing the program, counting frames and ``id()``; the real builtins it could
  reach are replaced by traps; ``sys.modules`` and the recursion limit are unchanged;
* it ends in a Plan or a ProgramError with a line, never another exception;
* the meter never passes the work or memory budget, the memory Python really
  allocated during the run (tracemalloc) stays under twice the memory budget, and
  the CPU time under twice the time budget;
* a second run with a stopped clock ends the same way after the same work.
"""

from __future__ import annotations

import builtins
import os
import subprocess
import sys
import time
import tracemalloc

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robocritics.errors import ProgramError
from robocritics.program import Budget
from robocritics.program.check import parse_program
from robocritics.program.interpreter import _Interpreter
from robocritics.scene import Scene

SCENE = Scene.builtin("sorting")
BUDGET = Budget(
    max_steps=10_000,
    max_work=50_000,
    max_skill_calls=200,
    max_call_depth=20,
    max_seconds=0.25,
    max_len=1_000,
    max_str_len=10_000,
    max_alloc_bytes=2_000_000,
    max_nodes=20_000,
    max_output_chars=10_000,
    clock=time.thread_time,
)
"""Small limits, so a run that goes to them is quick; the clock is the CPU time of the running thread."""
STOPPED = Budget(**{**{f: getattr(BUDGET, f) for f in BUDGET.__dataclass_fields__}, "clock": lambda: 0.0})
ALLOWED_AUDIT_EVENTS = {"compile", "sys._getframe", "builtins.id", "object.__getattr__"}


# ---- the tripwire ------------------------------------------------------------------------------------------

_armed: list[str] = []
_audited: list[str] = []


def _audit(event: str, args: tuple) -> None:
    if not _armed:
        return
    if event not in ALLOWED_AUDIT_EVENTS or (event == "object.__getattr__" and args[1] != "tb_frame"):
        _audited.append(event)


sys.addaudithook(_audit)  # audit hooks cannot be removed; it does nothing unless a run is armed


class _Traps:
    """Real builtins a program must never reach, replaced by traps during each run."""

    TARGETS = [(builtins, "open"), (builtins, "eval"), (builtins, "exec"), (builtins, "__import__"),
               (builtins, "input"), (os, "system"), (os, "popen"), (subprocess, "Popen")]  # fmt: skip

    def __init__(self) -> None:
        self.sprung: list[str] = []
        self.saved = [(mod, name, getattr(mod, name)) for mod, name in self.TARGETS]

    def __enter__(self) -> "_Traps":
        for mod, name, _ in self.saved:
            setattr(mod, name, self._trap(f"{mod.__name__}.{name}"))
        return self

    def __exit__(self, *exc: object) -> None:
        for mod, name, real in self.saved:
            setattr(mod, name, real)

    def _trap(self, name: str):
        def trap(*args, **kwargs):
            self.sprung.append(name)
            raise RuntimeError(f"tripwire: {name}")

        return trap


# ---- the grammar -------------------------------------------------------------------------------------------

NAMES = ["a", "b", "c", "d"]
SMALL_INTS = st.integers(-3, 12).map(str)
SIZES = st.sampled_from(["3", "10", "100", "10**3", "10**5", "10**9", "10**12"])
TYPED_SIZES = st.sampled_from(["3", "10", "100", "300", "1000", "10**4"])
"""Sizes of well-typed values: mostly within the limits, so that programs run long and keep what they make."""
LITERALS = st.one_of(
    SMALL_INTS,
    st.sampled_from(["0.5", "-2.25", "1e300", "True", "None", "''", "'ab'", "'x,y'", "2**61 - 1", "2**4000", "math.pi"]),
)
BINARY = ["+", "-", "*", "/", "//", "%", "**", "<<", ">>", "&", "|", "^"]
COMPARE = ["<", "<=", "==", "!=", ">", "in", "not in", "is"]
BUILTINS_1 = ["len", "sorted", "sum", "min", "max", "list", "tuple", "set", "str", "repr", "abs", "round", "any",
              "all", "reversed", "enumerate", "bool", "int", "float", "range", "dict"]  # fmt: skip
METHODS = ["append({e})", "extend({e})", "pop()", "sort()", "index({e})", "count({e})", "keys()", "values()",
           "items()", "get({e})", "update({e})", "add({e})", "union({e})", "join({e})", "split({e})",
           "replace({e}, {e})", "upper()", "copy()", "remove({e})", "insert(0, {e})"]  # fmt: skip
MATH = ["sqrt", "floor", "fsum", "prod", "isqrt", "hypot", "log", "gcd"]
SKILL_CALLS = ["move_to(0.3, 0.1, 0.2)", "move_above(green_apple)", "wait(0)", "home()", "open_gripper()",
               "move_to({e})", "print({e})", "avoid_collision({e})"]  # fmt: skip
SCENE_VALUES = ["objects", "containers", "green_apple.position", "green_apple.attributes", "white_box.top"]


@st.composite
def typed(draw, kind: str, depth: int = 0) -> str:
    """A well-typed int, list or str expression: these run long and grow large, where random ones fail fast."""
    leaf = depth >= 2 or draw(st.integers(0, 2)) == 0
    t = lambda k: draw(typed(k, depth + 1))  # noqa: E731
    size = draw(TYPED_SIZES)
    if kind == "int":
        if leaf:
            return draw(st.sampled_from(["d", "i", "len(a)", "7", "2**4000", "-1"]))
        return draw(st.sampled_from([
            f"({t('int')} {draw(st.sampled_from(['+', '-', '*', '//', '%', '**', '<<']))} {t('int')})",
            f"len({t('list')})", f"sum({t('list')})", f"max({t('list')} + [0])", f"({t('list')}).count({t('int')})",
            f"len({t('str')})", f"int(str({t('int')}))",
        ]))  # fmt: skip
    if kind == "list":
        if leaf:
            return draw(st.sampled_from(["a", f"list(range({size}))", "[1, 2, 3]", f"[0] * {size}"]))
        return draw(st.sampled_from([
            f"[{t('int')}, {t('int')}]", f"[{t('int')} for i in range({size})]", f"sorted({t('list')})",
            f"({t('list')} + {t('list')})", f"({t('list')} * {size})", f"[{t('list')}] * {size}",
            f"({t('list')})[{t('int')}:{t('int')}]", f"sorted({t('list')}, key=lambda v: -v)",
            f"list(zip({t('list')}, {t('list')}))", f"list(set({t('list')}))", f"[{t('list')}, {t('list')}]",
        ]))  # fmt: skip
    if leaf:
        return draw(st.sampled_from(["c", f"'x' * {size}", "'a,b,c'"]))
    return draw(st.sampled_from([
        f"str({t('list')})", f"({t('str')} + {t('str')})", f"','.join(str(v) for v in {t('list')})",
        f"({t('str')}).replace('x', 'xx')", "f\"{" + t("list") + "}{" + t("int") + "}\"", f"repr({t('str')})",
        f"({t('str')}).upper()",
    ]))  # fmt: skip


@st.composite
def expressions(draw, depth: int = 0) -> str:
    """An expression of the allowed subset (bounded nesting; sizes as an attacker would choose them)."""
    if depth >= 2 or draw(st.integers(0, 3)) == 0:
        return draw(st.one_of(LITERALS, st.sampled_from(NAMES + ["i"] + SCENE_VALUES)))
    e = lambda: draw(expressions(depth + 1))  # noqa: E731
    kind = draw(st.integers(0, 20))
    if kind >= 18:
        return draw(typed(draw(st.sampled_from(["int", "list", "str"]))))
    if kind == 0:
        return f"({e()} {draw(st.sampled_from(BINARY))} {e()})"
    if kind == 1:
        ops = draw(st.lists(st.sampled_from(COMPARE), min_size=1, max_size=3))
        return "(" + e() + "".join(f" {op} {e()}" for op in ops) + ")"
    if kind == 2:
        return "(" + f" {draw(st.sampled_from(['and', 'or']))} ".join(e() for _ in range(draw(st.integers(2, 4)))) + ")"
    if kind == 3:
        return f"({draw(st.sampled_from(['-', 'not ', '~']))}{e()})"
    if kind == 4:
        return f"({e()} if {e()} else {e()})"
    if kind == 5:
        items = ", ".join(draw(st.sampled_from(["{x}", "*{x}"])).format(x=e()) for _ in range(draw(st.integers(0, 4))))
        return draw(st.sampled_from(["[{}]", "({},)", "{{{}}}"])).format(items) if items else "[]"
    if kind == 6:
        return "{" + ", ".join(f"{e()}: {e()}" for _ in range(draw(st.integers(0, 3)))) + "}"
    if kind == 7:
        shape = draw(st.sampled_from(["[{e} for i in {it}]", "[{e} for i in {it} if {c}]", "{{{e} for i in {it}}}",
                                      "{{i: {e} for i in {it}}}", "sum({e} for i in {it})"]))  # fmt: skip
        return shape.format(e=e(), it=f"range({draw(SIZES)})" if draw(st.booleans()) else e(), c=e())
    if kind == 8:
        return f"{draw(st.sampled_from(BUILTINS_1))}({e()})"
    if kind == 9:
        return f"{draw(st.sampled_from(['max', 'min', 'sorted']))}({e()}, key=lambda v: {e()})"
    if kind == 10:
        receiver = draw(st.sampled_from(NAMES)) if draw(st.booleans()) else f"({e()})"
        return f"{receiver}.{draw(st.sampled_from(METHODS)).format(e=e())}"
    if kind == 11:
        return f"({e()})[{e()}]" if draw(st.booleans()) else f"({e()})[{e()}:{e()}]"
    if kind == 12:
        return draw(st.sampled_from(["f'{a}-{b!r}'", "f'{d:>8}|{c}'", "f'{i:.3f}'", "f'{a}{a}{a}'"]))
    if kind == 13:
        return f"([{e()}] * {draw(SIZES)})" if draw(st.booleans()) else f"('x' * {draw(SIZES)})"
    if kind == 14:
        return f"(lambda v: {e()})({e()})"
    if kind == 15:
        return f"math.{draw(st.sampled_from(MATH))}({e()})"
    if kind == 16:
        return f"zip({e()}, {e()})" if draw(st.booleans()) else f"dict(zip({e()}, {e()}))"
    return f"f({e()})"


@st.composite
def statements(draw, depth: int = 0, indent: str = "") -> list[str]:
    """One statement (as source lines) of the allowed subset."""
    e = lambda: draw(expressions())  # noqa: E731
    kind = draw(st.integers(0, 13 if depth < 2 else 8))
    name = draw(st.sampled_from(NAMES))
    if kind == 0:
        return [f"{indent}{name} = {e()}"]
    if kind == 1:
        return [f"{indent}{name} {draw(st.sampled_from(['+=', '*=', '-=', '|=']))} {e()}"]
    if kind == 2:
        return [indent + draw(st.sampled_from(SKILL_CALLS)).format(e=e())]
    if kind == 3:
        return [f"{indent}print({e()}, {e()})"]
    if kind == 4:
        return [f"{indent}{name}[{e()}] = {e()}"]
    if kind == 5:
        name, of = draw(st.sampled_from([("a", "list"), ("c", "str"), ("d", "int")]))
        return [f"{indent}{name} = {draw(typed(of))}"]
    if kind == 6:
        return [f"{indent}a.append({draw(typed('int'))})"]
    if kind == 7:
        return [f"{indent}b[{draw(typed('str'))}] = {draw(typed('list'))}"]
    if kind == 8:  # a loop that keeps what it makes, or keeps redoing heavy work
        keep = draw(st.sampled_from(["a.append({x})", "b[i] = {x}", "c = {x}", "d = {x}", "a = a + [{x}]"]))
        made = draw(typed(draw(st.sampled_from(["int", "list", "str"]))))
        return [f"{indent}for i in range({draw(SIZES)}):", f"{indent}    " + keep.format(x=made)]
    if kind == 9:
        return [f"{indent}assert {e()}, {e()}"]
    body = draw(blocks(depth + 1, indent + "    "))
    if kind == 10:
        return [f"{indent}if {e()}:", *body, f"{indent}else:", *draw(blocks(depth + 1, indent + "    "))]
    if kind == 11:
        iterable = f"range({draw(SIZES)})" if draw(st.booleans()) else e()
        return [f"{indent}for i in {iterable}:", *body]
    if kind == 12:
        condition = f"d < {draw(SIZES)}" if draw(st.booleans()) else e()
        return [f"{indent}while {condition}:", *body, f"{indent}    d = d * 2 + 1"]
    return [f"{indent}def f(v):", *body, f"{indent}    return {e()}"]


@st.composite
def blocks(draw, depth: int = 0, indent: str = "") -> list[str]:
    lines: list[str] = []
    for _ in range(draw(st.integers(1, 2))):
        lines += draw(statements(depth, indent))
    return lines


@st.composite
def programs(draw) -> str:
    # every name starts with a value of another type; f exists before a generated def replaces it
    lines = ["import math", "a = [3, 1, 2]", "b = {'k': 1, 2: 'v'}", "c = 'some text'", "d = 7", "i = 0",
             "def f(v):", "    return v"]  # fmt: skip
    for _ in range(draw(st.integers(1, 5))):
        lines += draw(statements())
    return "\n".join(lines) + "\n"


# ---- the property ------------------------------------------------------------------------------------------


def _run(source: str, budget: Budget) -> tuple[_Interpreter, tuple]:
    """Run ``source``; the interpreter (its meter) and the outcome (error kind, limit, line, or the plan)."""
    interp = _Interpreter(source, parse_program(source, budget), SCENE, budget)
    try:
        plan = interp.run()
        return interp, ("plan", len(plan.calls), tuple(plan.output))
    except ProgramError as exc:
        return interp, (type(exc).__name__, getattr(exc, "limit", ""), exc.line, exc.reason)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(programs())
def test_random_programs_never_escape_nor_exceed_their_budget(source):
    try:
        parse_program(source, BUDGET)
    except ProgramError:
        return  # a generated program the static check refuses (e.g. return outside a def) is fine
    modules_before = set(sys.modules)
    recursion_limit = sys.getrecursionlimit()
    tracemalloc.start()
    started_cpu_s = time.thread_time()
    with _Traps() as traps:
        _armed.append("run")
        try:
            interp, outcome = _run(source, BUDGET)  # anything but a ProgramError propagates and fails
        finally:
            _armed.clear()
    cpu_s = time.thread_time() - started_cpu_s
    _, peak_bytes = tracemalloc.get_traced_memory()
    tracemalloc.stop()

    assert traps.sprung == [] and _audited == [], (traps.sprung, _audited)
    assert set(sys.modules) == modules_before
    assert sys.getrecursionlimit() == recursion_limit
    if outcome[0] != "plan":
        assert outcome[2] > 0, outcome  # every error names a line
    meter = interp.meter
    assert meter.work <= BUDGET.max_work + 1  # the hot path may count the one node that trips the limit
    assert meter.steps <= BUDGET.max_steps + 1
    assert meter.memory <= BUDGET.max_alloc_bytes
    assert peak_bytes <= 2 * BUDGET.max_alloc_bytes
    assert cpu_s <= 2 * BUDGET.max_seconds

    again, outcome_again = _run(source, STOPPED)
    if outcome[1] != "max_seconds":  # without the clock the same limit stops it after the same work
        assert outcome_again == outcome
        assert again.meter.work == meter.work
