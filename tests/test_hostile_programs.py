"""Hostile programs: every one must end in ProgramError without touching anything outside the skill API.

Two corpora. ``ESCAPES`` (below) tries to reach Python itself (imports, dunder walks,
forbidden builtins and statements) or to make huge values; each must be refused
with the right message while a tripwire watches the dangerous callables.
:mod:`hostile_corpus` attacks the budgets class by class (work inside one
statement, builtins' work, hash collisions, amplified error messages, memory,
stack); each case must hit exactly its limit at its line, end within a second of
CPU time with the default Budget, and all of them together must grow the
process's memory by less than 500 MB. The wall-clock limit is tested on a
simulated clock.
"""

from __future__ import annotations

import ast
import builtins
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from hostile_corpus import AMPLIFICATION, BUILTIN_WORK, CORPUS, MEMORY, ONE_STATEMENT, STACK, Hostile

from robocritics.errors import ProgramError
from robocritics.program import Budget, BudgetError, run_program
from robocritics.program.render import MESSAGE_CHARS
from robocritics.scene import Scene

SCENE = Scene.builtin("sorting")
CANARY_FILE = "/tmp/robocritics_sandbox_canary_{pid}".format(pid=os.getpid())


def stopped_clock() -> float:
    """A clock that never advances: only the limits that count work can stop a program."""
    return 0.0


WORK_LIMITS_ONLY = Budget(clock=stopped_clock)
"""The default limits with time taken out, so the same limit stops a program on a fast or a loaded machine."""


class SteppingClock:
    """A simulated clock that advances ``step_s`` seconds every time it is read (every few hundred work units)."""

    def __init__(self, step_s: float):
        self.step_s = step_s
        self.now_s = 0.0

    def __call__(self) -> float:
        self.now_s += self.step_s
        return self.now_s


# (id, program source, a substring the error message must contain)
ESCAPES: list[tuple[str, str, str]] = [
    # ---- imports ------------------------------------------------------------------------
    ("import_os", "import os\nos.system('touch " + CANARY_FILE + "')", "import of 'os' is not allowed"),
    ("from_os_system", "from os import system\nsystem('id')", "import of 'os' is not allowed"),
    ("import_os_path", "import os.path", "import of 'os.path' is not allowed"),
    ("dunder_import", "__import__('os').system('id')", "'__import__' is not allowed"),
    ("importlib", "import importlib\nimportlib.import_module('os')", "import of 'importlib' is not allowed"),
    ("import_subprocess", "import subprocess as sp\nsp.run(['id'])", "import of 'subprocess' is not allowed"),
    ("import_builtins", "import builtins\nbuiltins.open('/etc/passwd')", "import of 'builtins' is not allowed"),
    ("import_sys_modules", "import sys\nsys.modules['os'].system('id')", "import of 'sys' is not allowed"),
    ("math_loader", "import math as m\nm.__loader__.load_module('os')", "attribute '__loader__' is not allowed"),
    ("math_star", "from math import *", "import *"),
    ("relative_import", "from . import sandbox", "relative imports are not allowed"),
    ("from_lib_internals", "from robocritics import sandbox", "cannot import 'sandbox' from robocritics"),
    ("from_lib_dunder", "from lib import __dict__", "cannot import '__dict__'"),
    # ---- dunder walks -------------------------------------------------------------------
    ("subclasses", "().__class__.__mro__[1].__subclasses__()", "attribute '__class__' is not allowed"),
    ("skill_globals", "lib.move_to.__globals__['os']", "attribute '__globals__' is not allowed"),
    ("object_dict", "green_apple.__dict__", "attribute '__dict__' is not allowed"),
    ("code_object", "move_to.__code__.co_consts", "attribute '__code__' is not allowed"),
    ("lib_dict", "lib.__dict__['move_to']", "attribute '__dict__' is not allowed"),
    ("comprehension_walk", "[c for c in ().__class__.__base__.__subclasses__()]", "attribute '__class__'"),
    ("position_class", "objects[0].position.__class__", "attribute '__class__' is not allowed"),
    ("builtin_attr", "list.append", "has no attribute 'append'"),
    ("int_attr", "x = (1).real", "has no attribute 'real'"),
    ("underscore_name", "_x = 1", "names starting with '_'"),
    ("underscore_kwarg", "d = dict(__import__='os')", "keyword '__import__' is not allowed"),
    # ---- getattr games -------------------------------------------------------------------
    ("getattr", "getattr(green_apple, '__class__')", "'getattr' is not available"),
    ("vars", "g = vars()['getattr']", "'vars' is not available"),
    ("globals", "b = globals()['__builtins__']", "'globals' is not available"),
    ("locals", "l = locals()", "'locals' is not available"),
    ("type", "type(1).__subclasses__()", "'type' is not available"),
    ("setattr", "setattr(lib, 'move_to', print)", "'setattr' is not available"),
    ("object_subclasses", "object.__subclasses__()", "'object' is not available"),
    # ---- format strings -----------------------------------------------------------------
    ("str_format", "'{0.__class__}'.format(1)", "str.format is not available"),
    ("str_format_bound", "s = '{0.__class__.__mro__}'\nf = s.format\nf(1)", "str.format is not available"),
    ("format_map", "'{a}'.format_map({'a': 1})", "str.format_map is not available"),
    ("fstring_attr", "x = 1\nprint(f'{x.__class__}')", "attribute '__class__' is not allowed"),
    ("percent_format", "'%(a)s' % {'a': green_apple}", "'%' string formatting is not available"),
    ("format_builtin", "x = format(green_apple, '')", "'format' is not available"),
    ("fstring_width", "x = f'{1:>999999999}'", "width or precision above 1000"),
    ("fstring_nested_width", "w = 10**9\nx = f'{1:>{w}}'", "width or precision above 1000"),
    # ---- endless loops and recursion ------------------------------------------------------
    ("while_true", "while True: pass", "more than 100000 steps"),
    ("while_counter", "x = 0\nwhile x >= 0:\n    x += 1", "more than 100000 steps"),
    ("huge_for", "for i in range(10**18):\n    pass", "more than 100000 steps"),
    ("recursion", "def f(n):\n    return f(n + 1)\nf(0)", "nest more than 50 deep"),
    ("lambda_recursion", "f = lambda x: f(x)\nf(1)", "nest more than 50 deep"),
    ("mutual_recursion", "def a():\n    return b()\ndef b():\n    return a()\na()", "nest more than 50 deep"),
    ("exponential_calls", "def f(n):\n    if n == 0:\n        return 1\n    return f(n - 1) + f(n - 1)\nf(40)", "units of work"),
    ("sort_key_recursion", "def k(x):\n    return sorted([1, 2], key=k)\nk(0)", "nest more than 50 deep"),
    ("million_skill_calls", "for i in range(10**6):\n    move_up(0.01)", "more than 2000 skill calls"),
    ("skill_loop_in_helper", "def f():\n    while True:\n        home()\nf()", "more than 2000 skill calls"),
    # ---- huge values ---------------------------------------------------------------------
    ("list_range", "x = list(range(10**9))", "would have 1000000000 elements"),
    ("list_repeat", "x = [0] * 10**9", "would have 1000000000 elements"),
    ("str_repeat", "x = 'a' * 10**10", "10000000000 characters"),
    ("power_tower", "x = 10**10**10", "integer too large"),
    ("shift", "x = 1 << 10**9", "integer too large"),
    ("squaring", "x = 2\nfor i in range(100):\n    x = x * x", "integer too large"),
    ("int_parse", "x = int('9' * 4000)", "integer too large"),
    ("math_prod", "import math\nx = math.prod([2**4000] * 100)", "integer too large"),
    ("round_ndigits", "x = round(5, -10**9)", "ndigits"),
    ("sum_range", "x = sum(range(10**10))", "would have 10000000000 elements"),
    ("all_range", "x = all(range(1, 10**9))", "elements"),
    ("min_range", "x = min(range(10**9))", "elements"),
    ("float_in_range", "x = 0.5 in range(10**12)", "a range searched for a non-integer would have"),
    ("star_unpack", "a, *b = range(10**9)", "would have 1000000000 elements"),
    ("star_call", "print(*range(10**9))", "elements"),
    ("zip_list", "x = list(zip(range(10**9), range(10**9)))", "more than 10000 elements"),
    ("dict_of_range", "d = dict([range(10**9)])", "(key, value) pair"),
    ("join_range", "s = ' '.join(range(10**9))", "elements"),
    ("big_comprehension", "x = [i for i in range(10**9)]", "would have 10001 elements"),
    ("generator_sum", "x = sum(i for i in range(10**9))", "would have 10001 elements"),
    ("dict_comprehension", "x = {i: i for i in range(10**6)}", "10001 elements"),
    ("nested_comprehension", "x = [[i * j for i in range(10000)] for j in range(10000)]", "more than 100000 steps"),
    ("shared_list_compare", "a = [0] * 1000\nb = [a] * 1000\nc = [b] * 1000\nd = [[[0] * 1000] * 1000] * 1000\nc == d", "too large to compare"),
    ("shared_tuple_hash", "t = (0,) * 1000\nt2 = (t,) * 1000\nt3 = (t2,) * 1000\ns = {t3}", "too large to compare"),
    ("shared_print", "a = ['x' * 10000] * 10000\nprint(a)", "printing this value would produce more than"),
    ("self_containing", "a = []\na.append(a)\nprint(a == a)", "contains itself"),
    ("deep_data_repr", "a = []\nfor i in range(5000):\n    a = [a]\nprint(a)", "nested more than 100 levels"),
    ("deep_data_compare", "a = []\nb = []\nfor i in range(3000):\n    a = [a]\n    b = [b]\nx = a == b", "nested more"),
    ("deep_data_hash", "t = ()\nfor i in range(3000):\n    t = (t,)\nd = {t: 1}", "nested more than 100 levels"),
    ("append_forever", "a = []\nwhile True:\n    a.append('x' * 100000)", "in total"),
    ("retained_strings", "a = []\nb = list(range(5000))\nwhile True:\n    a.append(str(b))", "units of work"),
    ("retained_tuples", "a = []\nb = list(range(10000))\nwhile True:\n    a.append(list(zip(b, b)))", "in total"),
    ("append_to_iterated", "a = [1]\nfor x in a:\n    a.append(x)", "10001 elements"),
    ("string_doubling", "x = 'a'\nwhile True:\n    x = x + x", "characters"),
    ("join_bomb", "s = ' '.join(['a' * 10000] * 10000)", "characters"),
    ("replace_bomb", "s = ('a' * 10000).replace('a', 'a' * 10000)", "characters"),
    ("print_flood", "while True:\n    print('x' * 99999)", "printed more than"),
    # ---- forbidden statements ---------------------------------------------------------------
    ("try_except", "try:\n    move_to(0.3, 0, 0.1)\nexcept Exception:\n    pass", "try/except is not allowed"),
    ("raise", "raise SystemExit(1)", "raise is not allowed"),
    ("generator", "def g():\n    yield 1\ng()", "generators (yield) are not allowed"),
    ("class", "class A:\n    pass", "class definitions are not allowed"),
    ("with_open", "with open('/etc/passwd') as f:\n    pass", "'with' is not allowed"),
    ("async", "async def f():\n    await g()", "async code is not allowed"),
    ("global", "x = 1\ndef f():\n    global x\n    x = 2", "'global' is not allowed"),
    ("walrus", "(x := 5)", "':=' operator is not allowed"),
    ("match", "x = 1\nmatch x:\n    case 1:\n        pass", "match statements are not allowed"),
    ("lambda_default", "f = lambda x=().__class__: x", "attribute '__class__' is not allowed"),
    ("decorator", "@lib.move_to\ndef f():\n    pass", "decorators are not allowed"),
    ("varargs", "def f(*args):\n    pass", "'*args' parameters are not allowed"),
    ("double_star_call", "move_to(**{'x': 1})", "'**' unpacking in calls is not allowed"),
    ("bytes", "x = b'abc'", "bytes literals are not allowed"),
    # ---- forbidden builtins -------------------------------------------------------------------
    ("open", "open('/etc/passwd').read()", "'open' is not available"),
    ("open_write", "open('" + CANARY_FILE + "', 'w').write('x')", "'open' is not available"),
    ("exec", "exec('import os')", "'exec' is not available"),
    ("eval", "eval('1 + 1')", "'eval' is not available"),
    ("compile", "compile('1', 'x', 'exec')", "'compile' is not available"),
    ("breakpoint", "breakpoint()", "'breakpoint' is not available"),
    ("input", "input()", "'input' is not available"),
    ("exit", "exit()", "'exit' is not available"),
    # ---- writes to the API and the scene --------------------------------------------------------
    ("replace_skill", "lib.move_to = print", "cannot assign to attribute 'move_to'"),
    ("move_object", "green_apple.x = 5", "cannot assign to attribute 'x'"),
    ("delete_skill", "del lib.move_to", "cannot delete attribute 'move_to'"),
    ("subscript_object", "green_apple['colour']", "not subscriptable"),
    ("subscript_store_object", "green_apple['x'] = 1", "does not support item assignment"),
    ("mutate_position", "green_apple.position[0] = 1.0", "does not support item assignment"),
    ("call_namespace", "lib()", "not callable"),
    # ---- parser and nesting bombs -----------------------------------------------------------------
    ("deep_parens", "x = " + "(" * 300 + "1" + ")" * 300, "too many nested parentheses"),
    ("deep_unary", "x = " + "-" * 50000 + "1", "nests too deeply"),
    ("long_sum", "x = " + "+".join(["1"] * 20000), "nest"),
    ("deep_lists", "x = " + "[" * 150 + "]" * 150, "nests more than 100 levels"),
    ("deep_subscripts", "a = [0]\nx = a" + "[0]" * 500, "nests more than 100 levels"),
    ("deep_blocks", "".join(" " * i + "if True:\n" for i in range(98)) + " " * 98 + "x = [[[[1]]]]\n", "nests more than"),
    ("huge_source", "x = 1\n" * 30000, "characters long"),
    ("null_byte", "x = 1\x00", "null bytes"),
]


def _ids() -> list[str]:
    return [case[0] for case in ESCAPES]


GOOD_PROGRAM = "for a in objects:\n    if a.ripeness == 'ripe':\n        move_above(a)\nhome()\n"


def _good_plan_calls() -> list[str]:
    return [c.describe() for c in run_program(GOOD_PROGRAM, SCENE).calls]


EXPECTED_GOOD = [
    "move_above(red_apple_1, height=0.1)",
    "move_above(red_apple_2, height=0.1)",
    "home()",
]


class _Tripwire:
    """Replaces dangerous callables during a run; any call is recorded (and refused)."""

    def __init__(self) -> None:
        self.calls: list[str] = []

    def make(self, name: str):
        def trap(*args, **kwargs):
            self.calls.append(name)
            raise RuntimeError(f"tripwire: {name} called from a sandboxed program")

        return trap


def test_corpus_is_large_and_unique():
    assert len(ESCAPES) >= 40
    assert len(set(_ids())) == len(ESCAPES)


@pytest.mark.parametrize("name,source,expected", ESCAPES, ids=_ids())
def test_hostile_program_is_stopped(name, source, expected, monkeypatch):
    modules_before = set(sys.modules)
    if os.path.exists(CANARY_FILE):
        os.remove(CANARY_FILE)
    wire = _Tripwire()
    real_import = builtins.__import__
    imports: list[str] = []

    def tracking_import(module, *args, **kwargs):
        imports.append(module)
        return real_import(module, *args, **kwargs)

    real_compile = builtins.compile

    def parse_only_compile(source, filename, mode, flags=0, *args, **kwargs):
        # ast.parse is the only compile allowed: the program is never compiled to bytecode
        if not flags & ast.PyCF_ONLY_AST:
            wire.calls.append("builtins.compile")
            raise RuntimeError("tripwire: program compiled to bytecode")
        return real_compile(source, filename, mode, flags, *args, **kwargs)

    with monkeypatch.context() as m:
        for mod, attr in [
            (builtins, "open"),
            (builtins, "eval"),
            (builtins, "exec"),
            (builtins, "breakpoint"),
            (builtins, "input"),
            (os, "system"),
            (os, "popen"),
            (subprocess, "Popen"),
            (subprocess, "run"),
        ]:
            m.setattr(mod, attr, wire.make(f"{mod.__name__}.{attr}"))
        m.setattr(builtins, "compile", parse_only_compile)
        m.setattr(builtins, "__import__", tracking_import)
        imports.clear()  # monkeypatch itself imports while patching
        err = None
        try:
            run_program(source, SCENE, WORK_LIMITS_ONLY)
        except ProgramError as exc:  # anything else propagates and fails the test
            err = exc

    # for the right reason, with a position where one exists
    assert err is not None, f"{name} ran without error"
    assert expected in str(err)
    assert isinstance(err.reason, str) and err.reason
    assert err.line >= 0 and err.col >= 0
    # nothing outside the skill API ran
    assert wire.calls == []
    assert imports == []
    assert set(sys.modules) == modules_before
    assert not os.path.exists(CANARY_FILE)
    # the interpreter survives: a normal program still produces the same plan
    assert _good_plan_calls() == EXPECTED_GOOD


def test_errors_carry_lines_for_runtime_stops():
    for source, line in [
        ("x = 1\nwhile True:\n    x += 1\n", 2),
        ("home()\nfor i in range(10**6):\n    move_up(0.01)\n", 3),
        ("def f(n):\n    return f(n + 1)\n\nf(0)\n", 2),
        ("x = 1\ny = [0] * 10**9\n", 2),
    ]:
        with pytest.raises(ProgramError) as info:
            run_program(source, SCENE, WORK_LIMITS_ONLY)
        assert info.value.line == line, (source, str(info.value))


def test_wall_clock_budget_stops_slow_steps():
    # every step "takes" 0.25 s of simulated time; no other limit is near
    clock = SteppingClock(step_s=0.25)
    budget = Budget(max_seconds=1.0, max_steps=10**9, max_alloc_bytes=10**12, clock=clock)
    with pytest.raises(ProgramError) as info:
        run_program("a = list(range(10000))\nwhile True:\n    b = sorted(a)\n", SCENE, budget)
    assert "the program ran longer than 1 s" in info.value.reason
    assert info.value.line == 3  # the statement running when the time ran out
    started_s = clock.step_s  # the clock's first reading starts the run
    assert budget.max_seconds < clock.now_s - started_s <= budget.max_seconds + clock.step_s  # first reading past it


def test_wall_clock_budget_reads_only_the_injected_clock():
    # however long the run really takes, a clock that does not advance never runs out
    budget = Budget(max_seconds=1e-9, clock=stopped_clock)
    plan = run_program("for i in range(2000):\n    x = sorted([3, 1, 2])\nhome()\n", SCENE, budget)
    assert [c.skill for c in plan.calls] == ["home"]


def test_budget_is_configurable():
    with pytest.raises(ProgramError, match="more than 10 steps"):
        run_program("for i in range(100):\n    pass\n", SCENE, Budget(max_steps=10))
    with pytest.raises(ProgramError, match="more than 3 skill calls"):
        run_program("for i in range(5):\n    home()\n", SCENE, Budget(max_skill_calls=3))
    with pytest.raises(ProgramError, match="nest more than 5 deep"):
        run_program("def f(n):\n    return f(n - 1) if n else 0\nf(10)\n", SCENE, Budget(max_call_depth=5))
    with pytest.raises(ValueError, match="max_steps"):
        Budget(max_steps=0)
    with pytest.raises(ValueError, match="clock"):
        Budget(clock=0.5)


def test_recursion_limit_is_restored():
    before = sys.getrecursionlimit()
    with pytest.raises(ProgramError):
        run_program("def f(n):\n    return f(n + 1)\nf(0)", SCENE)
    run_program("def f(n):\n    return 0 if n == 0 else f(n - 1) + 1\nprint(f(45))", SCENE)
    assert sys.getrecursionlimit() == before


def test_deep_but_legal_recursion_works():
    plan = run_program(
        "def f(n):\n    if n == 0:\n        return 0\n    return 1 + f(n - 1)\nprint(f(48))\n", SCENE
    )
    assert plan.output == ["48"]


def test_real_stdout_untouched(capsys):
    plan = run_program("print('hello', green_apple)\n", SCENE)
    assert plan.output == ["hello green_apple"]
    assert capsys.readouterr().out == ""


# ---- the budget corpus (tests/hostile_corpus.py), run in a fresh process -----------------------------------

CPU_LIMIT_S = 1.0
"""CPU time a hostile program may take with the default Budget (its 0.5 s clock stops it; CPU time, not wall
time, so a loaded machine does not matter)."""
MEMORY_GROWTH_LIMIT_BYTES = 500_000_000
"""Peak memory the whole corpus, each case run twice, may add to a fresh process."""


@pytest.fixture(scope="module")
def corpus_run() -> dict:
    """What stopped each case, its CPU time, the memory growth and the audit events, from a fresh process."""
    script = Path(__file__).with_name("hostile_corpus.py")
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600, check=True)
    return json.loads(done.stdout)


def test_budget_corpus_covers_every_class():
    assert len(CORPUS) >= 40
    assert len({c.name for c in CORPUS}) == len(CORPUS)
    for section in (ONE_STATEMENT, BUILTIN_WORK, AMPLIFICATION, MEMORY, STACK):
        assert section
    limits = {c.limit for c in CORPUS}
    assert {"max_work", "max_nodes", "max_len", "max_str_len", "max_alloc_bytes", "max_call_depth"} <= limits


@pytest.mark.parametrize("case", CORPUS, ids=[c.name for c in CORPUS])
def test_budget_corpus_case_stops_at_its_limit_and_line(case: Hostile, corpus_run):
    outcome = corpus_run["cases"][case.name]["work_only"]
    assert outcome["error"] == ("BudgetError" if case.limit else "ProgramError"), outcome
    assert outcome["limit"] == case.limit, outcome["reason"]
    assert outcome["line"] == case.line, outcome["reason"]
    assert case.message in outcome["reason"]
    assert len(outcome["reason"]) <= MESSAGE_CHARS + 100  # every value in it bounded, the message clipped


@pytest.mark.parametrize("case", CORPUS, ids=[c.name for c in CORPUS])
def test_budget_corpus_case_ends_within_a_second(case: Hostile, corpus_run):
    outcome = corpus_run["cases"][case.name]["default"]
    assert outcome["error"] in ("BudgetError", "ProgramError"), outcome
    assert outcome["line"] > 0
    assert outcome["cpu_s"] < CPU_LIMIT_S


def test_budget_corpus_memory_and_escapes(corpus_run):
    assert corpus_run["peak_growth_bytes"] < MEMORY_GROWTH_LIMIT_BYTES
    assert corpus_run["audited"] == {}  # no import, open, exec, os, subprocess... during any run


def test_default_budget_stops_a_time_hog_with_the_real_clock():
    # the work limits are generous enough that the 0.5 s clock may end a run first; either way it ends soon
    with pytest.raises(BudgetError) as info:
        run_program("a = [[[0] * 30] * 30] * 30\nwhile True:\n    x = a == a[:]\n", SCENE)
    assert info.value.limit in ("max_seconds", "max_work")
    assert info.value.line == 3
