"""Hostile programs that attack the sandbox's budgets, one class of attack per section.

Every case names the limit it must hit (the :class:`~robocritics.program.BudgetError`
``limit``, a Budget field, or ``""`` for a plain :class:`~robocritics.errors.ProgramError`
whose message must contain ``message``) and the line the error must name. The
cases are run with the default Budget and a clock that never advances, so only
the limits that count work or sizes can stop them, at the same line on any
machine (tests/test_hostile_programs.py).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Hostile:
    name: str
    source: str
    limit: str
    """The Budget field a BudgetError must name, or "" for a ProgramError whose message contains ``message``."""
    line: int
    message: str = ""


_SORTED_A = "a = list(range(10000))\n"
_SHARED_TUPLE = "t = (0,)\nfor i in range(60):\n    t = (t, t)\n"  # 2**60 leaves, 61 objects
_SHARED_TUPLE_TWIN = "u = (0,)\nfor i in range(60):\n    u = (u, u)\n"
_P = "P = 2**61 - 1\n"  # hash(k * P) == 0 for every k

ONE_STATEMENT = [
    Hostile("and_chain_of_sorts", _SORTED_A + "x = " + " and ".join(["sorted(a)"] * 2000), "max_work", 2),
    Hostile("or_chain_in_loop", "for i in range(1000):\n    x = " + " or ".join(["[]"] * 5000), "max_work", 2),
    Hostile(
        "chained_comparison_of_shared_lists",
        "a = [[[0] * 30] * 30] * 30\nb = [[[0] * 30] * 30] * 30\nx = " + " == ".join(["a", "b"] * 1500),
        "max_work",
        3,
    ),
    Hostile("list_display_of_sorts", _SORTED_A + "x = [" + ", ".join(["sorted(a)"] * 2000) + "]", "max_work", 2),
    Hostile("call_with_heavy_arguments", _SORTED_A + "print(" + ", ".join(["len(sorted(a))"] * 2000) + ")", "max_work", 2),
    Hostile("fstring_of_heavy_parts", "a = list(range(3000))\nx = f'" + "{len(str(a))}" * 3000 + "'", "max_work", 2),
    Hostile(
        "dict_display_of_sorts",
        _SORTED_A + "x = {" + ", ".join(f"{i}: sorted(a)" for i in range(2000)) + "}",
        "max_work",
        2,
    ),
    Hostile("comprehension_of_sorts", _SORTED_A + "x = [sorted(a) for i in range(10000)]", "max_work", 2),
    Hostile("temporaries_in_one_statement", "s = 'x' * 50000\nx = [" + ", ".join(["s + s"] * 3000) + "]", "max_alloc_bytes", 2),
]

BUILTIN_WORK = [
    # hash collisions: every key of these has one hash value, so each insertion would compare with all others
    Hostile("set_of_colliding_ints", _P + "x = set([k * P for k in range(10000)])", "", 2, "have the same hash value"),
    Hostile("dict_of_colliding_ints", _P + "x = {k * P: k for k in range(10000)}", "", 2, "have the same hash value"),
    Hostile("set_of_colliding_floats", "x = {1.5 * 2.0 ** (61 * k) for k in range(16)}", "", 1, "have the same hash value"),
    Hostile("set_of_colliding_tuples", _P + "x = {(0, k * P) for k in range(10000)}", "", 2, "have the same hash value"),
    Hostile("dict_update_colliding", _P + "d = {}\nd.update([(k * P, 0) for k in range(1000)])", "", 3, "same hash"),
    Hostile("set_union_colliding", _P + "s = {1}\nx = s.union([k * P for k in range(1000)])", "", 3, "same hash"),
    Hostile(
        "items_view_xor_colliding",
        _P + "d = {0: 0}\nx = d.items() ^ [(0, k * P) for k in range(1000)]",
        "",
        3,
        "same hash",
    ),
    # dict views combined with endless or huge iterables
    Hostile("keys_minus_huge_range", "d = {1: 2}\nx = d.keys() - range(10**12)", "max_len", 2),
    Hostile("keys_or_endless_zip", "d = {1: 2}\nx = d.keys() | zip(range(10**12))", "max_len", 2),
    Hostile("items_and_huge_range", "d = {1: 2}\nx = d.items() & range(10**12)", "max_len", 2),
    # sorting, min/max and comparisons of huge equal structures
    Hostile(
        "sorted_by_huge_equal_keys",
        "x = sorted(range(1000), key=lambda i: [[[[0] * 10] * 10] * 10] * 10)",
        "max_nodes",
        1,
    ),
    Hostile("max_by_huge_equal_keys", "x = max(range(10000), key=lambda i: [[[0] * 10] * 10] * 10)", "max_nodes", 1),
    Hostile(
        "list_sort_by_huge_keys",
        "a = list(range(500))\na.sort(key=lambda i: (((0,) * 20,) * 20,) * 20)",
        "max_nodes",
        2,
    ),
    Hostile("min_of_shared_lists", "a = [[[0] * 100] * 100] * 100\nx = min(a)", "max_nodes", 2),
    Hostile("compare_shared_tuples", _SHARED_TUPLE + _SHARED_TUPLE_TWIN + "x = t == u", "max_nodes", 7),
    Hostile("less_than_shared_tuples", _SHARED_TUPLE + _SHARED_TUPLE_TWIN + "x = t < u", "max_nodes", 7),
    Hostile("shared_tuple_in_list", _SHARED_TUPLE + _SHARED_TUPLE_TWIN + "x = t in [u, u]", "max_nodes", 7),
    Hostile("count_shared_tuples", _SHARED_TUPLE + _SHARED_TUPLE_TWIN + "x = [u] * 100\ny = x.count(t)", "max_nodes", 8),
    Hostile("set_of_shared_tuple", _SHARED_TUPLE + "x = {t}", "max_nodes", 4),
    Hostile("dict_get_shared_tuple", _SHARED_TUPLE + "d = {}\nx = d.get(t)", "max_nodes", 5),
    Hostile("sorted_shared_tuples", _SHARED_TUPLE + _SHARED_TUPLE_TWIN + "x = sorted([t, u])", "max_nodes", 7),
    # long builtin work in loops: each call is bounded, the loop runs out of work
    Hostile("sort_in_loop", "a = [i * 7919 % 10007 for i in range(10000)]\nwhile True:\n    b = sorted(a)", "max_work", 3),
    Hostile(
        "worst_case_substring_search",
        "s = 'a' * 100000\nn = 'a' * 99 + 'b'\nfor i in range(100000):\n    x = n in s",
        "max_work",
        4,
    ),
    Hostile("big_int_to_text_loop", "x = 2 ** 4000\nfor i in range(100000):\n    s = str(x)", "max_work", 3),
    Hostile("big_int_parse_loop", "s = '9' * 1200\nwhile True:\n    x = int(s)", "max_work", 3),
    Hostile("insert_at_front_loop", "a = list(range(9000))\nwhile True:\n    a.insert(0, 1)\n    a.pop()", "max_work", 3),
    Hostile("repr_of_nested_loop", "a = [[[0.5] * 10] * 10] * 10\nwhile True:\n    x = repr(a)", "max_work", 3),
    Hostile("set_compare_loop", "a = set(range(10000))\nb = set(range(10000))\nwhile True:\n    x = a == b", "max_work", 4),
    Hostile("keys_minus_set_loop", "d = {i: i for i in range(10000)}\nwhile True:\n    x = d.keys() - {1}", "max_alloc_bytes", 3),
    Hostile("wide_zip_loop", "a = [1] * 10000\nfor t in zip(*[a] * 10000):\n    pass", "max_work", 2),
    # sizes refused before anything is built
    Hostile("wide_zip_list", "a = [1] * 10000\nx = list(zip(*[a] * 10000))", "max_nodes", 2),
    Hostile("nested_wide_zip_list", "a = [1] * 10000\nx = list(enumerate(zip(*[a] * 10000)))", "max_nodes", 2),
    Hostile("sum_of_huge_range", "x = sum(range(10**10))", "max_len", 1),
    Hostile("any_of_endless_generator", "x = any(i < 0 for i in range(10**12))", "max_len", 1),
    Hostile("float_in_huge_range", "x = 0.5 in range(10**12)", "max_len", 1),
    Hostile("join_bomb", "s = ' '.join(['a' * 10000] * 10000)", "max_str_len", 1),
    Hostile("replace_bomb", "s = ('a' * 10000).replace('a', 'a' * 10000)", "max_str_len", 1),
    Hostile("split_into_many", "s = 'a,' * 50000\nx = s.split(',')", "max_len", 2),
    Hostile("print_of_shared_strings", "a = ['x' * 10000] * 10000\nprint(a)", "max_str_len", 2),
    Hostile("self_extension", "a = [1]\nwhile True:\n    a += a", "max_len", 3),
    Hostile("deep_data_hash", "t = ()\nfor i in range(3000):\n    t = (t,)\nd = {t: 1}", "max_nesting", 4),
    Hostile("deep_data_print", "a = []\nfor i in range(5000):\n    a = [a]\nprint(a)", "max_nesting", 4),
]

AMPLIFICATION = [
    # every value that reaches an error message is quoted in a few dozen characters
    Hostile("set_remove_huge_key", "s = set()\ns.remove('x' * 100000)", "", 2, "KeyError: 'xxxx"),
    Hostile(
        "dict_key_error_lists_huge_keys",
        "d = {'k' * 50000 + str(i): i for i in range(20)}\nx = d['y' * 100000]",
        "",
        2,
        "is not in the dict",
    ),
    Hostile("list_index_huge_value", "a = [[[[['x' * 1000] * 10] * 10] * 10] * 10]\n[1].index(a)", "", 2, "is not in list"),
    Hostile("float_of_huge_text", "x = float('x' * 100000)", "", 1, "could not convert string to float"),
    Hostile("dict_pop_huge_tuple", "x = {}.pop((1,) * 10000)", "", 1, "KeyError: (1, 1, 1"),
    Hostile("assert_huge_message", "assert 1 == 2, 'x' * 100000", "", 1, "assertion failed: xxx"),
    Hostile("name_error_huge_name", "x = " + "n" * 50000 + " + 1", "", 1, "is not defined"),
    Hostile("attribute_huge_name", "x = green_apple." + "a" * 50000, "", 1, "has no attribute"),
    Hostile("method_huge_name", "x = [1]." + "a" * 50000 + "()", "", 1, "method 'aaaa"),
    Hostile("skill_unknown_huge_object", "move_to('x' * 100000)", "", 1, "unknown object 'xxxx"),
    Hostile("skill_huge_keyword", "move_to(0.1, 0.2, 0.3, " + "a" * 50000 + "=1)", "", 1, "unexpected keyword"),
    Hostile("function_huge_keyword", "def f():\n    pass\nf(" + "a" * 50000 + "=1)", "", 3, "unexpected keyword"),
    Hostile("index_huge_int", "x = [1, 2]\ny = x[2 ** 4000]", "", 2, "IndexError"),
    Hostile("format_spec_huge", "w = '<' * 50000\nx = f'{1:{w}}'", "", 2, "ValueError"),
    Hostile("power_message_huge_operands", "x = 3 ** 2000\ny = x ** x", "max_int_bits", 2),
]

MEMORY = [
    Hostile("big_int_rows", "x = [[2**4000 + i for i in range(10000)] for j in range(190)]", "max_alloc_bytes", 1),
    Hostile("list_copies", "x = [[j * 0.5] * 10000 for j in range(1000)]", "max_alloc_bytes", 1),
    Hostile("string_accumulation", "a = []\nwhile True:\n    a.append('x' * 99999)", "max_alloc_bytes", 3),
    Hostile("dict_of_big_values", "d = {}\nfor i in range(10**6):\n    d[i] = [i] * 1000", "max_alloc_bytes", 3),
    Hostile("tuple_rows", "rows = [tuple(range(10000)) for i in range(1000)]", "max_alloc_bytes", 1),
]

STACK = [
    Hostile("recursion", "def f(n):\n    return f(n + 1)\nf(0)", "max_call_depth", 2),
    Hostile(
        "recursion_through_comprehensions",
        "def f(n):\n    return [[[f(n + 1) for a in range(1)] for b in range(1)] for c in range(1)]\nf(0)",
        "max_call_depth",
        2,
    ),
    Hostile("recursion_through_sort_key", "def k(x):\n    return sorted([1, 2], key=k)\nk(0)", "max_call_depth", 2),
    Hostile("recursion_through_max_key", "f = lambda n: max([1], key=lambda v: f(n))\nf(0)", "max_call_depth", 1),
]

CORPUS = ONE_STATEMENT + BUILTIN_WORK + AMPLIFICATION + MEMORY + STACK


ALLOWED_AUDIT_EVENTS = {"compile", "sys._getframe", "object.__getattr__", "builtins.id"}
"""What a run may make Python audit: parsing the program (ast.parse), the interpreter counting its frames and
clearing them after an error (tb_frame), id() of its own values. An import, open, exec, os.*, subprocess.*,
socket.* or any other event means something outside the skill API ran."""


def run_corpus() -> dict:
    """Run every case twice in this process: with a clock that never advances (only work limits stop it) and
    with the default Budget (its real clock as the backstop); report what stopped it, its CPU time, the
    process's peak memory growth and every audit event the runs raised. Run as a script by
    tests/test_hostile_programs.py, in a fresh process whose memory and audit hooks nothing else has touched."""
    import os
    import sys
    import time

    from robocritics.errors import ProgramError
    from robocritics.program import Budget, BudgetError, run_program
    from robocritics.scene import Scene

    scene = Scene.builtin("sorting")
    work_only = Budget(clock=lambda: 0.0)

    def attempt(source: str, budget: Budget | None) -> dict:
        start = time.thread_time()
        try:
            run_program(source, scene, budget)
            outcome: dict = {"error": None}
        except BudgetError as exc:
            outcome = {"error": "BudgetError", "limit": exc.limit, "line": exc.line, "reason": exc.reason}
        except ProgramError as exc:
            outcome = {"error": "ProgramError", "limit": "", "line": exc.line, "reason": exc.reason}
        outcome["cpu_s"] = time.thread_time() - start
        return outcome

    attempt("x = sorted([3, 1, 2])", None)  # warm up: everything the runs use is imported and allocated once
    page = os.sysconf("SC_PAGE_SIZE")
    with open("/proc/self/statm") as f:
        resident_before = int(f.read().split()[1]) * page
    audited: dict[str, str] = {}
    running: list[str] = []

    def tripwire(event: str, args: tuple) -> None:
        if running and event not in ALLOWED_AUDIT_EVENTS:
            audited.setdefault(event, running[0])
        elif running and event == "object.__getattr__" and args[1] != "tb_frame":
            audited.setdefault(f"{event} {args[1]}", running[0])

    sys.addaudithook(tripwire)  # for good: this process only runs the corpus
    results = {}
    for case in CORPUS:
        running.append(case.name)
        results[case.name] = {"work_only": attempt(case.source, work_only), "default": attempt(case.source, None)}
        running.clear()
    return {"cases": results, "peak_growth_bytes": peak_resident_bytes() - resident_before, "audited": audited}


def peak_resident_bytes() -> int:
    """This process's peak resident set size [bytes] since it started (exec'd).

    From /proc's VmHWM, which belongs to the address space and so starts afresh at exec: getrusage's
    ru_maxrss survives fork and exec, so a child of a large pytest process would report the parent's size.
    """
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    raise RuntimeError("no VmHWM in /proc/self/status")


if __name__ == "__main__":
    import json
    import sys

    json.dump(run_corpus(), sys.stdout)
