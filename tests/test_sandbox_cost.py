"""The sandbox's cost model piece by piece: work units, the clock inside expressions, weights, hash keys, bytes,
bounded text, the interpreter's stack, and runs in many threads at once."""

from __future__ import annotations

import gc
import pickle
import sys
import threading
import time
import tracemalloc

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics.errors import ProgramError
from robocritics.program import Budget, BudgetError, run_program
from robocritics.program.check import parse_program
from robocritics.program.interpreter import _Interpreter
from robocritics.program.keys import MAX_KEYS_PER_HASH, KeyGuard
from robocritics.program.meter import LimitReached, Meter
from robocritics.program.render import (
    MESSAGE_CHARS,
    VALUE_CHARS,
    TooDeep,
    TooLong,
    bounded_repr,
    clip,
    full_repr,
)
from robocritics.scene import Scene

SCENE = Scene.builtin("sorting")
WORK_ONLY = Budget(clock=lambda: 0.0)


def run(source: str, budget: Budget = WORK_ONLY) -> _Interpreter:
    """Run ``source`` to its end; the interpreter, whose meter tells what the run cost."""
    interp = _Interpreter(source, parse_program(source, budget), SCENE, budget)
    interp.run()
    return interp


def work_of(source: str) -> int:
    return run(source).meter.work


def stopped(source: str, budget: Budget = WORK_ONLY) -> BudgetError:
    with pytest.raises(BudgetError) as info:
        run_program(source, SCENE, budget)
    return info.value


class CountingClock:
    """A simulated clock: ``step_s`` later every time it is read; counts the readings."""

    def __init__(self, step_s: float):
        self.step_s = step_s
        self.now_s = 0.0
        self.readings = 0

    def __call__(self) -> float:
        self.readings += 1
        self.now_s += self.step_s
        return self.now_s


# ---- work units ------------------------------------------------------------------------------------------


def test_every_node_and_step_costs_work_and_the_count_is_deterministic():
    source = "x = 0\nfor i in range(100):\n    x = x + i * 2\n"
    first, second = work_of(source), work_of(source)
    assert first == second
    assert 100 * 5 <= first <= 100 * 12  # per iteration: the step, the statement, five nodes


def test_one_statement_of_many_nodes_is_stopped_by_work_at_its_line():
    source = "a = 1\nx = " + " and ".join(["a"] * 15000) + "\n"
    error = stopped(source, Budget(max_work=10_000, clock=lambda: 0.0))
    assert (error.limit, error.line) == ("max_work", 2)


def test_builtin_work_is_priced_by_the_elements_it_touches():
    base = work_of("a = list(range(5000))\n")
    sort_scalars = work_of("a = list(range(5000))\nb = sorted(a)\n") - base
    sort_lists = work_of("a = [[i] * 50 for i in range(100)]\nb = sorted(a)\n") - work_of("a = [[i] * 50 for i in range(100)]\n")
    assert 100 < sort_scalars < 10_000  # n log n cheap comparisons
    assert sort_lists > 20 * 100  # a hundred comparisons of 50-element lists cost more than a hundred scalars
    copy = work_of("a = list(range(5000))\nb = a[:]\n") - base
    assert 5000 // 32 <= copy <= 5000 // 32 + 10


def test_comparison_costs_the_lighter_side():
    setup = "big = [[0] * 100] * 100\nsame = [[0] * 100] * 100\n"
    base = work_of(setup)
    light = work_of(setup + "x = big == 1\n") - base
    heavy = work_of(setup + "x = big == same\n") - base
    assert light <= 5
    assert heavy > 10_000 // 32


def test_a_charge_the_budget_cannot_pay_is_refused_before_the_work():
    meter = Meter(Budget(max_work=100, clock=lambda: 0.0))
    meter.start()
    meter.spend(60)
    with pytest.raises(LimitReached) as info:
        meter.spend(50)
    assert info.value.limit == "max_work"
    assert meter.work == 60  # nothing was paid for work that was not done


# ---- the clock inside expressions and before builtin work ---------------------------------------------------


def test_the_clock_is_read_inside_one_long_expression():
    clock = CountingClock(step_s=0.01)
    budget = Budget(max_seconds=0.5, clock=clock)
    source = "a = 1\nx = " + " and ".join(["a"] * 15000) + "\n"
    error = stopped(source, budget)
    assert (error.limit, error.line) == ("max_seconds", 2)
    assert 0.5 < clock.now_s <= 0.5 + 2 * clock.step_s  # stopped at the first reading past the deadline


def test_the_clock_is_read_before_long_builtin_work():
    readings: list[float] = []

    def clock() -> float:  # the start, then far past the deadline
        readings.append(0.0 if not readings else 100.0)
        return readings[-1]

    error = stopped("a = [0] * 1000\nb = sorted(a)\n", Budget(max_seconds=1.0, clock=clock))
    assert (error.limit, error.line) == ("max_seconds", 2)


def test_a_short_program_never_reads_the_clock_after_the_start():
    clock = CountingClock(step_s=1000.0)  # any reading after the first is past the deadline
    plan = run_program("x = [1, 2, 3]\nhome()\n", SCENE, Budget(max_seconds=1.0, clock=clock))
    assert [c.skill for c in plan.calls] == ["home"]
    assert clock.readings == 1


# ---- weights ------------------------------------------------------------------------------------------------


def test_weights_count_shared_parts_every_time_and_stop_past_the_cap():
    meter = Meter(Budget(max_work=10**9, clock=lambda: 0.0))
    meter.start()
    row = [0] * 10
    assert meter.weigh([row] * 10) == (1 + 10) + 10 * (1 + 10)  # each container: itself and its elements
    assert meter.weigh("x" * 640) == 11
    huge = (0,)
    for _ in range(60):
        huge = (huge, huge)
    assert 100 < meter.weigh(huge, cap=100) <= 102  # 2**60 leaves, but the walk stops at the cap
    deep: list = []
    for _ in range(200):
        deep = [deep]
    with pytest.raises(LimitReached) as info:
        meter.weigh(deep)
    assert info.value.limit == "max_nesting"


def test_a_walk_never_does_more_work_than_the_budget_has_left():
    meter = Meter(Budget(max_work=50, max_nodes=10**9, clock=lambda: 0.0))
    meter.start()
    with pytest.raises(LimitReached) as info:
        meter.weigh([[0] * 10] * 10_000)
    assert info.value.limit == "max_work"


# ---- hash keys -------------------------------------------------------------------------------------------------


def test_few_keys_may_share_a_hash_and_no_more():
    meter = Meter(Budget(clock=lambda: 0.0))
    meter.start()
    keys = KeyGuard(meter)
    p = 2**61 - 1
    colliding = [k * p for k in range(1, MAX_KEYS_PER_HASH + 2)]
    assert len({hash(k) for k in colliding}) == 1
    for k in colliding[:MAX_KEYS_PER_HASH]:
        keys.admit(k)
        keys.admit(k)  # the same key again is no new collision
    with pytest.raises(ValueError, match="same hash value"):
        keys.admit(colliding[-1])
    for k in (-1, -2, 1.0, 1, True, "text", (1, 2)):  # natural collisions and equal keys are fine
        keys.admit(k)


def test_small_integers_and_strings_are_admitted_in_one_pass():
    meter = Meter(Budget(clock=lambda: 0.0))
    meter.start()
    keys = KeyGuard(meter)
    keys.admit_all(list(range(-5000, 5000)))
    keys.admit_all([str(i) for i in range(10000)])
    assert keys.by_hash == {}  # their hashes cannot be forged: nothing to remember
    assert meter.work < 10_000


def test_unhashable_keys_fail_as_in_python_before_any_walk():
    with pytest.raises(ProgramError, match="unhashable type: 'list'"):
        run_program("d = {}\nd[[1, 2]] = 3\n", SCENE)
    with pytest.raises(ProgramError, match="unhashable type: 'list'"):
        run_program("x = {(1, [2]): 3}\n", SCENE)


def test_dict_and_set_semantics_survive_the_key_guard():
    plan = run_program(
        "d = {1: 'a', True: 'b', 1.0: 'c'}\ns = {-1, -2, 2**61 - 1, 0}\nt = {(1, 2): 3}\n"
        "print(d, sorted(s), t[(1, 2)], (1, 2) in t, d.keys() - {1}, sorted(d.items() | [(5, 6)]))\n",
        SCENE,
    )
    assert plan.output == ["{1: 'c'} [-2, -1, 0, 2305843009213693951] 3 True set() [(1, 'c'), (5, 6)]"]


# ---- bytes -------------------------------------------------------------------------------------------------------


def test_memory_is_counted_in_bytes_of_what_was_made():
    small = run("x = [i for i in range(1000)]\n").meter.memory
    big = run("x = [2**4000 + i for i in range(1000)]\n").meter.memory
    assert 9_000 < small < 100_000
    assert big > 1000 * 500  # each 4000-bit integer is over 500 bytes
    error = stopped("x = [2**4000 + i for i in range(1000)]\n", Budget(max_alloc_bytes=200_000, clock=lambda: 0.0))
    assert (error.limit, error.line) == ("max_alloc_bytes", 1)


def test_a_stopped_program_frees_its_values_at_once():
    # without the garbage collector: the error must not keep the interpreter's frames (and values) alive
    gc.collect()
    gc.disable()
    try:
        tracemalloc.start()
        with pytest.raises(BudgetError):
            run_program("a = []\nwhile True:\n    a.append('x' * 99999)\n", SCENE, WORK_ONLY)
        current, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    finally:
        gc.enable()
    assert peak > 40_000_000
    assert current < 2_000_000


# ---- bounded text ---------------------------------------------------------------------------------------------------

_values = st.recursive(
    st.one_of(st.integers(), st.floats(allow_nan=False), st.text(max_size=5), st.none(), st.booleans()),
    lambda inner: st.one_of(
        st.lists(inner, max_size=4),
        st.lists(inner, max_size=4).map(tuple),
        st.dictionaries(st.text(max_size=3), inner, max_size=3),
        st.sets(st.integers(), max_size=3),
    ),
    max_leaves=20,
)


@settings(max_examples=200, deadline=None)
@given(_values)
def test_full_repr_is_python_repr(value):
    text, steps = full_repr(value, 10**6, 100)
    assert text == repr(value)
    assert steps <= len(text) + 1


def _abbreviated(value) -> bool:
    """Whether bounded_repr writes part of ``value`` short (long strings, wide integers, deep nesting)."""
    if type(value) is str:
        return len(value) > VALUE_CHARS
    if type(value) is int:
        return value.bit_length() > 64
    if type(value) in (list, tuple, set):
        return any(_abbreviated(v) for v in value)
    if type(value) is dict:
        return any(_abbreviated(v) for v in (*value, *value.values()))
    return False


@settings(max_examples=200, deadline=None)
@given(_values, st.integers(1, 80))
def test_bounded_repr_is_short_whatever_the_value(value, limit):
    text = bounded_repr(value, limit)
    assert len(text) <= limit + 3
    if len(repr(value)) <= limit and not _abbreviated(value):
        assert text == repr(value)


def test_repr_of_exponential_or_self_containing_data_is_cheap():
    shared = [[[[0] * 10] * 10] * 10] * 10
    with pytest.raises(TooLong):
        full_repr(shared, 1000, 100)
    assert len(bounded_repr(shared)) <= VALUE_CHARS + 3
    loop: list = []
    loop.append(loop)
    assert full_repr(loop, 100, 100)[0] == repr(loop) == "[[...]]"
    deep: list = []
    for _ in range(1000):
        deep = [deep]
    with pytest.raises(TooDeep):
        full_repr(deep, 10**6, 100)
    assert bounded_repr(2**4000) == "<4001-bit integer>"
    assert clip("x" * 5000).endswith("... (3000 more characters)")


def test_every_error_message_is_bounded():
    huge = "'x' * 100000"
    for source in [
        f"assert False, {huge}",
        f"d = {{{huge}: 1}}\nx = d['y']",
        f"x = float({huge})",
        f"move_to({huge})",
        "x = " + "n" * 50000,
    ]:
        with pytest.raises(ProgramError) as info:
            run_program(source, SCENE)
        assert len(info.value.reason) <= MESSAGE_CHARS + 100, source[:40]


def test_budget_errors_name_their_limit_and_pickle():
    error = stopped("while True:\n    pass\n")
    assert (error.limit, error.line) == ("max_steps", 1)
    copy = pickle.loads(pickle.dumps(error))
    assert (type(copy), copy.limit, copy.line, copy.col, copy.reason) == (
        BudgetError, error.limit, error.line, error.col, error.reason
    )


def test_the_static_check_of_a_long_non_ascii_line_is_linear():
    source = "é = [" + ", ".join(["é"] * 30000) + "]"
    started = time.process_time()
    parse_program(source[:100_000])
    assert time.process_time() - started < 1.0  # columns are computed only for problems (was quadratic: 2 s)


# ---- the stack and threads ------------------------------------------------------------------------------------------

DEEP_BUT_LEGAL = "def f(n):\n    if n == 0:\n        return 0\n    return 1 + f(n - 1)\nprint(f(45))\n"


def _at_depth(frames: int, fn):
    return fn() if frames <= 0 else _at_depth(frames - 1, fn)


@pytest.mark.parametrize(
    "source",
    [
        "def f(n):\n    return f(n + 1)\nf(0)\n",
        "def k(x):\n    return sorted([1, 2], key=k)\nk(0)\n",
        "def f(n):\n    return [[f(n + 1) for a in range(1)] for b in range(1)]\nf(0)\n",
        "f = lambda n: max([1], key=lambda v: f(n))\nf(0)\n",
    ],
)
def test_deep_recursion_stops_itself_whatever_the_callers_stack(source):
    # the interpreter counts its own frames: from any depth of the caller it stops with max_call_depth,
    # never by running into Python's recursion limit (which it never changes)
    for caller_frames in (0, 300, 600, sys.getrecursionlimit() - 150):
        try:
            error = _at_depth(caller_frames, lambda: stopped(source))
        except RecursionError:  # the caller itself has no room left: not the sandbox's doing
            continue
        assert error.limit == "max_call_depth", error.reason
        assert "nests too deeply (deep recursion" not in error.reason  # the backstop was not needed


def test_the_recursion_limit_is_never_changed(monkeypatch):
    def refuse(limit: int) -> None:
        raise AssertionError("the sandbox changed the process's recursion limit")

    monkeypatch.setattr(sys, "setrecursionlimit", refuse)
    assert run_program(DEEP_BUT_LEGAL, SCENE).output == ["45"]
    with pytest.raises(BudgetError):
        run_program("def f(n):\n    return f(n + 1)\nf(0)\n", SCENE)


def test_eight_threads_run_programs_at_once():
    programs = [
        (DEEP_BUT_LEGAL, ["45"]),
        ("x = sorted([3, 1, 2], key=lambda v: -v)\nprint(x)\n", ["[3, 2, 1]"]),
        ("for a in objects:\n    move_above(a)\nprint(len(objects))\n", ["3"]),
    ]
    results: list[object] = []
    start = threading.Barrier(8)

    def worker(index: int) -> None:
        start.wait()
        try:
            for round_ in range(20):
                source, output = programs[(index + round_) % len(programs)]
                # the work meter, not the 0.5 s wall clock: eight threads on a loaded 2-core machine are slow
                assert run_program(source, SCENE, Budget(clock=lambda: 0.0)).output == output
                with pytest.raises(BudgetError):  # and hostile ones, deep in the stack, alongside
                    run_program("def f(n):\n    return f(n + 1)\nf(0)\n", SCENE, Budget(clock=lambda: 0.0))
            results.append("ok")
        except BaseException as exc:  # noqa: BLE001 - reported below
            results.append(exc)

    limit_before = sys.getrecursionlimit()
    threads = [threading.Thread(target=worker, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert results == ["ok"] * 8
    assert sys.getrecursionlimit() == limit_before


def test_a_finished_program_frees_its_values_at_once():
    gc.collect()
    gc.disable()
    try:
        tracemalloc.start()
        source = (  # values in a dict, kept by a closure, appended to a list the program was given
            "d = {str(i): [str(i) * 100] for i in range(2000)}\n"
            "def keep():\n    return d\n"
            "objects.append(d)\n"
        )
        run_program(source, SCENE, WORK_ONLY)
        current, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    finally:
        gc.enable()
    assert peak > 1_000_000
    assert current < 100_000  # (Python keeps a few thousand freed small tuples for reuse: none made here)
