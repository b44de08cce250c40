"""The sandbox runs good programs to exact Plans, with Python semantics and actionable errors."""

from __future__ import annotations

import contextlib
import io
import math
import textwrap
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robocritics.errors import ProgramError
from robocritics.program import Budget, Plan, SkillCall, parse_program, run_program
from robocritics.program.language import MATH_NAMES, SAFE_BUILTINS, SAFE_METHODS, reference_markdown
from robocritics.scene import Scene

SORTING = Scene.builtin("sorting")


def run(source: str, scene: Scene = SORTING, budget: Budget | None = None) -> Plan:
    return run_program(textwrap.dedent(source).lstrip("\n"), scene, budget)


def calls(plan: Plan) -> list[tuple[str, dict, int, tuple[int, ...]]]:
    return [(c.skill, dict(c.args), c.line, c.call_stack) for c in plan.calls]


def error(source: str, scene: Scene = SORTING) -> ProgramError:
    with pytest.raises(ProgramError) as info:
        run(source, scene)
    return info.value


# ---- good programs: exact plans ---------------------------------------------------------------


PAPER_STYLE = """
import math

def move_above_pos(pos, height=0.1):
    lib.move_to(pos[0], pos[1], pos[2] + height)

def pick(obj):
    move_above_pos(obj.position)
    lib.open_gripper()
    lib.move_linear(obj)
    lib.close_gripper()
    lib.move_up(0.1)

def place_in(box):
    lib.move_above(box, height=0.05)
    lib.open_gripper()

lib.reduce_speed(50)
for apple in objects:
    if apple.ripeness == "ripe":
        pick(apple)
        place_in(brown_box)
    else:
        pick(apple)
        place_in(white_box)
lib.rotate_gripper(math.radians(90))
lib.home()
"""


def test_paper_style_program_plan_is_exact():
    plan = run(PAPER_STYLE)
    assert plan.source == textwrap.dedent(PAPER_STYLE).lstrip("\n")
    assert plan.output == []
    expected = [("reduce_speed", {"fraction": 0.5}, 17, ())]
    for apple, call_line, box, place_line in [
        ("red_apple_1", 20, "brown_box", 21),
        ("red_apple_2", 20, "brown_box", 21),
        ("green_apple", 23, "white_box", 24),
    ]:
        pos = SORTING.entity(apple).position
        expected += [
            ("move_to", {"target": (pos[0], pos[1], pos[2] + 0.1)}, 4, (call_line, 7)),
            ("open_gripper", {}, 8, (call_line,)),
            ("move_linear", {"object": apple}, 9, (call_line,)),
            ("close_gripper", {}, 10, (call_line,)),
            ("move_up", {"dz": 0.1}, 11, (call_line,)),
            ("move_above", {"object": box, "height": 0.05}, 14, (place_line,)),
            ("open_gripper", {}, 15, (place_line,)),
        ]
    expected += [
        ("rotate_gripper", {"angle": math.pi / 2}, 25, ()),
        ("home", {}, 26, ()),
    ]
    assert calls(plan) == expected


def test_columns_and_types_of_recorded_calls():
    plan = run("x = 0.3\nif True:\n    lib.move_to(x, 0.1, 0.2)\n    move_to((x, 0, 0.2))\n")
    first, second = plan.calls
    assert (first.line, first.col) == (3, 5)
    assert (second.line, second.col) == (4, 5)
    assert first.args == {"target": (0.3, 0.1, 0.2)}
    assert all(type(v) is float for v in first.args["target"])
    assert second.args == {"target": (0.3, 0.0, 0.2)}
    assert all(type(v) is float for v in second.args["target"])
    assert first.describe() == "move_to(x=0.3, y=0.1, z=0.2)"
    assert isinstance(first, SkillCall)


def test_attributes_loops_and_prints():
    plan = run(
        """
        ripe = [a for a in objects if a.ripeness == "ripe"]
        print(len(ripe), "ripe apples:", ", ".join(a.id for a in ripe))
        for a in sorted(objects, key=lambda o: o.x, reverse=True):
            print(f"{a.id}: {a.colour} at x={a.x:.2f}, top={a.top:.3f}")
        print(green_apple.attributes, white_box.kind, brown_box.floor)
        boxes = {c.colour: c for c in containers}
        move_above(boxes["brown"])
        """
    )
    assert plan.output == [
        "2 ripe apples: red_apple_1, red_apple_2",
        "green_apple: green at x=0.40, top=0.070",
        "red_apple_1: red at x=0.30, top=0.070",  # the sort is stable: equal x keep their order
        "red_apple_2: red at x=0.30, top=0.070",
        "{'colour': 'green', 'ripeness': 'unripe'} container 0.005",
    ]
    assert calls(plan) == [("move_above", {"object": "brown_box", "height": 0.1}, 7, ())]


def test_imports_of_math_and_lib():
    plan = run(
        """
        import math
        import lib
        import robot_lib as rl
        from math import pi, sqrt as root
        from lib import move_to as go
        go(0.3, 0, root(0.04))
        rl.rotate_gripper(pi / 4)
        lib.wait(math.floor(1.5))
        """
    )
    assert calls(plan) == [
        ("move_to", {"target": (0.3, 0.0, 0.2)}, 6, ()),
        ("rotate_gripper", {"angle": math.pi / 4}, 7, ()),
        ("wait", {"seconds": 1.0}, 8, ()),
    ]


def test_object_ids_as_strings_and_points():
    plan = run('move_to("green_apple")\nmove_above([0.3, 0.1, 0.0], height=0.2)\navoid_collision("white_box")\n')
    assert calls(plan) == [
        ("move_to", {"object": "green_apple"}, 1, ()),
        ("move_above", {"target": (0.3, 0.1, 0.0), "height": 0.2}, 2, ()),
        ("avoid_collision", {"object": "white_box"}, 3, ()),
    ]


def test_skills_called_from_a_sort_key_keep_the_call_site():
    plan = run("def k(o):\n    move_above(o)\n    return o.y\n\norder = sorted(objects, key=k)\n")
    assert [(c.line, c.call_stack) for c in plan.calls] == [(2, (5,))] * 3


def test_scene_positions_are_initial_and_read_only():
    plan = run("p = green_apple.position\nmove_to(green_apple)\nprint(p == green_apple.position, p)\n")
    assert plan.output == ["True (0.4, 0.0, 0.035)"]
    attrs = run("a = green_apple.attributes\na['colour'] = 'blue'\nprint(green_apple.colour)\n")
    assert attrs.output == ["green"]


def test_runs_are_independent():
    first = run("objects.append(1)\nx = 5\nprint(len(objects))\n")
    second = run("print(len(objects))\n")
    assert first.output == ["4"] and second.output == ["3"]
    e = error("print(x)\n")
    assert "name 'x' is not defined" in e.reason


def test_empty_program_and_no_scene():
    assert run("").calls == []
    plan = run_program("move_to(0.2, 0.1, 0.3)\nprint(objects)", None)
    assert calls(plan) == [("move_to", {"target": (0.2, 0.1, 0.3)}, 1, ())]
    assert plan.output == ["[]"]


# ---- Python semantics (differential against CPython) -------------------------------------------

SEMANTICS = [
    """
    x = 3
    y = x * 2 + 1
    a, b = 1, 2
    a, b = b, a
    print(x, y, a, b)
    """,
    """
    def f(a, b=2, *, c=3):
        return a + b * c
    print(f(1), f(1, 1), f(1, c=10), f(a=5, b=0))
    """,
    """
    xs = [3, 1, 2]
    xs.sort()
    ys = sorted(xs, reverse=True)
    print(xs, ys, min(xs), max(xs, key=lambda v: -v), sum(xs), len(xs))
    print(xs[::-1], xs[1:], xs[-1], list(reversed(xs)))
    """,
    """
    d = {"a": 1, "b": 2}
    d["c"] = 3
    for k, v in d.items():
        print(k, v)
    print(sorted(d), list(d.keys()), list(d.values()), d.get("z", 0), "a" in d)
    d.update({"e": 5}, f=6)
    print(d.pop("a"), d.setdefault("q", 9), d)
    """,
    """
    s = {1, 2, 3}
    s.add(4)
    s.discard(1)
    print(sorted(s), 2 in s, sorted(s.union({9})), sorted(s & {2, 3}))
    """,
    """
    total = 0
    for i in range(10):
        if i % 2 == 0:
            continue
        if i > 7:
            break
        total += i
    else:
        total = -1
    print(total)
    n = 0
    while n < 5:
        n += 1
    else:
        print("done", n)
    """,
    """
    sq = [i * i for i in range(6) if i % 2]
    pairs = [(i, j) for i in range(3) for j in range(i)]
    dd = {i: str(i) for i in range(3)}
    ss = {i % 3 for i in range(10)}
    print(sq, pairs, dd, sorted(ss), sum(i for i in range(5)), any(x > 3 for x in sq), all([]))
    """,
    """
    def outer():
        k = 10
        def inner(x):
            return x + k
        return inner
    g = outer()
    print(g(5))
    def counter():
        items = []
        def add(x):
            items.append(x)
            return len(items)
        return add
    c = counter()
    c(1)
    c(2)
    print(c(3))
    fs = [lambda: i for i in range(3)]
    print([f() for f in fs])
    """,
    """
    x = 5
    print(f"{x}", f"{x:>4}", f"{x * 1.5:.2f}", f"{'a'!r}", f"{x=}", f"{x!s:<3}|")
    print(str(3.0), repr("q"), int("12"), float("1.5"), round(2.675, 2), round(7.5), abs(-3), bool(0))
    print(7 // 2, 7 % 3, -7 // 2, 2 ** -1, 2 ** 10, 1e3, 10 / 4, int("ff", 16))
    """,
    """
    a = [1, 2, 3, 4, 5]
    first, *mid, last = a
    print(first, mid, last)
    (p, q), r = (1, 2), 3
    print(p, q, r)
    a[1:3] = [9]
    del a[0]
    print(a)
    t = (1, 2) + (3,)
    print(t, t.index(3), t.count(1), [0] * 3, "ab" * 2, 2 * [1])
    a += (7, 8)
    a *= 2
    print(a)
    """,
    """
    words = "Hello World".lower().split()
    print(words, "-".join(words), "abc".upper().replace("B", "x"), "  pad ".strip(), "x.y".split("."))
    print("hello".startswith("he"), "hello".find("l"), "abc".title(), "3".isdigit(), "a" in "cat")
    """,
    """
    import math
    from math import pi, sqrt as s
    print(round(math.sqrt(2), 6), round(pi, 4), s(16), math.floor(2.7), math.hypot(3, 4), math.radians(180) == pi)
    print(math.fsum([0.1] * 10), math.prod([1, 2, 3]), math.dist((0, 0), (3, 4)), math.isclose(1.0, 1.0 + 1e-12))
    """,
    """
    def fact(n):
        return 1 if n <= 1 else n * fact(n - 1)
    print(fact(20))
    def fib(n):
        a, b = 0, 1
        for i in range(n):
            a, b = b, a + b
        return a
    print(fib(30))
    """,
    """
    x = None
    print(x is None, x is not None, 1 < 2 < 3, 1 < 3 < 2, 1 == 1.0, [1] == [1], (1, 2) < (1, 3))
    print(not x, x or "default", 0 and 1, 1 and 2, "" or [] or 5)
    y = 1 if x else 2
    print(y, -(-3), +3, ~5, 5 & 3, 5 | 3, 5 ^ 3, 1 << 4, 256 >> 2)
    """,
    """
    grid = [[0] * 3 for i in range(3)]
    grid[1][2] = 5
    grid[0][0] += 2
    for row in grid:
        print(row)
    names = ["b", "a", "c"]
    for i, n in enumerate(names, 1):
        print(i, n)
    for a, b in zip(names, range(10)):
        print(a, b)
    print(list(zip([1, 2], "ab")), dict(zip("ab", [1, 2])), tuple("ab"), list(range(2, 10, 3)))
    """,
    """
    x = 10
    def f():
        return x * 2
    x = 20
    print(f())
    def g(lst=[]):
        lst.append(1)
        return len(lst)
    g()
    print(g())
    """,
    """
    x: float = 1.5
    y: int
    print(x)
    assert x > 1, "x too small"
    vals = [3, 1, 2]
    print(sorted(vals, key=lambda v: (v % 2, v)))
    print(max([], default=0), min(1, 2, 3), max("abc"), sum([0.5, 0.25], 1))
    d = {(1, 2): "a"}
    print(d[(1, 2)], (1, 2) in d, {1, 2} == {2, 1}, [1, [2, 3]] < [1, [2, 4]])
    """,
    """
    def classify(n):
        if n < 0:
            return "neg"
        elif n == 0:
            return "zero"
        return "pos"
    print([classify(v) for v in (-1, 0, 3)])
    def nothing():
        pass
    print(nothing())
    r = range(10)
    print(r[2:5], len(r), 3 in r, list(r[::3]), r[-1])
    """,
]


@pytest.mark.parametrize("source", SEMANTICS, ids=[f"prog{i}" for i in range(len(SEMANTICS))])
def test_matches_cpython(source):
    source = textwrap.dedent(source)
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        exec(compile(source, "<test>", "exec"), {})  # trusted test code, for reference
    assert run(source).output == buf.getvalue().splitlines()


def test_scoping_errors_match_python():
    e = error("x = 1\ndef f():\n    x += 1\n    return x\nf()\n")
    assert "local variable 'x' is used before it is assigned" in e.reason
    assert e.line == 3
    e = error("def f():\n    return y\ny2 = 1\nf()\n")
    assert "name 'y' is not defined" in e.reason and "'y2'" in e.reason


# ---- error positions and suggestions --------------------------------------------------------------


def test_unknown_skill_suggests_names():
    e = error("home()\nmove_too(0.3, 0, 0.2)\n")
    assert (e.line, e.col) == (2, 1)
    assert "name 'move_too' is not defined; did you mean 'move_to'" in e.reason


def test_unknown_lib_member_suggests_skill():
    e = error("x = 1\nlib.move_abve(green_apple)\n")
    assert (e.line, e.col) == (2, 5)
    assert "lib has no skill 'move_abve'; did you mean 'move_above'" in e.reason


def test_unknown_object_suggests_ids():
    e = error("move_above(green_aple)\n")
    assert (e.line, e.col) == (1, 12)
    assert "did you mean 'green_apple'" in e.reason
    e = error("move_to('gren_apple')\n")
    assert (e.line, e.col) == (1, 1)
    assert "unknown object 'gren_apple'; did you mean 'green_apple'" in e.reason


def test_unknown_attribute_lists_fields():
    e = error("if green_apple.ripness == 'ripe':\n    home()\n")
    assert (e.line, e.col) == (1, 16)
    assert "object 'green_apple' has no attribute 'ripness'; did you mean 'ripeness'?" in e.reason
    assert "It has: id," in e.reason and "colour" in e.reason


def test_local_names_are_suggested():
    e = error("apple_pos = green_apple.position\nmove_to(apple_poss)\n")
    assert "did you mean 'apple_pos'" in e.reason
    e = error("d = sqrt(2)\n")
    assert "did you mean math.sqrt?" in e.reason


def test_skill_argument_errors():
    cases = [
        ("move_to('a', 0.1, 0.2)", "x must be a number (metres), got str 'a'"),
        ("move_to(0.3, '0.1', 0.2)", "write 0.1 without quotes"),
        ("move_to(math.inf, 0, 0)", "x is inf; it must be a finite number"),
        ("move_to(float('nan'), 0, 0)", "x is nan"),
        ("move_to(300, 0, 100)", "coordinates are in metres"),
        ("move_to(0.3, 0.1)", "needs all three coordinates"),
        ("move_to(0.3)", "needs three coordinates"),
        ("move_to(0.1, 0.2, 0.3, 0.4)", "move_to(): too many positional arguments; usage: move_to(x, y, z)"),
        ("move_to([0.1, 0.2])", "a point needs 3 coordinates"),
        ("move_up(-0.1)", "use move_down to go the other way"),
        ("move_down(0)", "dz must be a positive distance"),
        ("move_up(50)", "more than 1 m"),
        ("rotate_gripper(90)", "angle is in radians; use math.radians(90)"),
        ("reduce_speed(0)", "1 <= percent <= 100"),
        ("reduce_speed(150)", "1 <= percent <= 100"),
        ("set_speed(50)", "for percent use reduce_speed(50)"),
        ("set_speed(True)", "got bool True"),
        ("wait(-1)", "seconds must be in 0..10"),
        ("wait(11)", "seconds must be in 0..10"),
        ("avoid_collision(0.3)", "obj must be a scene object"),
        ("move_above(green_apple, hieght=0.1)", "unexpected keyword argument 'hieght'; did you mean 'height'?"),
        ("move_above(green_apple, height=-0.1)", "height must be >= 0"),
        ("move_above(0.3, 0.1)", "move_above takes a scene object or a point"),
        ("open_gripper(1)", "open_gripper(): too many positional arguments"),
    ]
    for source, message in cases:
        e = error("import math\n" + source + "\n")
        assert message in e.reason, (source, e.reason)
        assert (e.line, e.col) == (2, 1), (source, str(e))


def test_errors_inside_helpers_point_at_the_helper_line():
    e = error("def go(p):\n    move_to(p[0], p[1], 1 / 0)\n\ngo((0.3, 0.1))\n")
    assert (e.line, e.col) == (2, 25)
    assert "ZeroDivisionError: division by zero" in e.reason
    assert "(in go(), called from line 4)" in e.reason
    e = error("def go(p):\n    move_to(p[0], p[1], p[5])\n\ngo((0.3, 0.1))\n")
    assert (e.line, e.col) == (2, 25)
    assert "IndexError: index 5 is out of range for a tuple of length 2" in e.reason


def test_runtime_errors_are_program_errors():
    cases = [
        ("x = [1, 2]\ny = x + 1", 2, 5, "TypeError: can only concatenate list"),
        ("d = {'colour': 'red'}\nc = d['color']", 2, 5, "KeyError: key 'color' is not in the dict; did you mean 'colour'?"),
        ("for o in green_apple:\n    pass", 1, 10, "use green_apple.position"),
        ("x = int('abc')", 1, 5, "ValueError: invalid literal for int()"),
        ("assert 1 > 2, 'bad'", 1, 1, "assertion failed: bad"),
        ("f = 3\nf()", 2, 1, "TypeError: 'int' object is not callable"),
        ("green_apple()", 1, 1, "green_apple is a scene object, not a function"),
        ("a, b = [1, 2, 3]", 1, 1, "too many values to unpack (expected 2)"),
        ("x = (1, 2)\nx[0] = 5", 2, 1, "a tuple cannot be changed"),
        ("x = 'abc'.format(1)", 1, 11, "str.format is not available"),
        ("x = [1].push(2)", 1, 9, "'list' method 'push' is not available"),
        ("print(sum(['a', 'b']))", 1, 7, "sum() adds numbers only"),
        ("def f(a):\n    return a\nf(1, 2)", 3, 1, "f() takes 1 positional argument but 2 were given"),
        ("def f(a):\n    return a\nf(b=2)", 3, 1, "unexpected keyword argument 'b'"),
        ("def f(a):\n    return a\nf()", 3, 1, "f() missing required argument 'a'"),
        ("x = range(1.5)", 1, 5, "range() needs whole numbers"),
        ("x = 1 + green_apple", 1, 5, "unsupported operand type(s) for +: 'int' and 'scene object'"),
    ]
    for source, line, col, message in cases:
        e = error(source + "\n")
        assert message in e.reason, (source, e.reason)
        assert (e.line, e.col) == (line, col), (source, str(e))


def test_static_errors_have_positions_and_list_all_problems():
    with pytest.raises(ProgramError) as info:
        parse_program("home()\nimport os\nx = 1\ny = x.__class__\nopen('f')\n")
    e = info.value
    assert (e.line, e.col) == (2, 8)
    assert "import of 'os' is not allowed; the program can only use the skill API (lib.move_to, ...) and math" in str(e)
    assert "line 4, column 7: attribute '__class__' is not allowed" in e.reason
    assert "line 5, column 1: 'open' is not available" in e.reason


def test_syntax_error_position():
    with pytest.raises(ProgramError) as info:
        parse_program("home()\nmove_to(0.3, 0.1\n")
    assert info.value.line == 2
    assert "syntax error" in info.value.reason


def test_parse_program_returns_tree_and_accepts_good_code():
    tree = parse_program(textwrap.dedent(PAPER_STYLE))
    assert tree.body and type(tree).__name__ == "Module"


def test_break_and_return_outside_their_blocks_are_rejected():
    for source, message in [
        ("break", "'break' outside a loop"),
        ("continue", "'continue' outside a loop"),
        ("return 1", "'return' outside a function"),
        ("for i in range(3):\n    def f():\n        break", "'break' outside a loop"),
    ]:
        with pytest.raises(ProgramError, match=message):
            parse_program(source)


def test_print_does_not_reach_stdout(capsys):
    plan = run("print('a', 1, sep='-')\nprint('b', end='!')\nprint()\n")
    assert plan.output == ["a-1", "b!", ""]
    assert capsys.readouterr().out == ""


def test_api_objects_have_friendly_reprs():
    plan = run("print(move_to, lib, math, math.sqrt, green_apple, [white_box], len)\n")
    assert plan.output == [
        "<skill move_to> <module 'lib'> <module 'math'> <built-in function sqrt> green_apple [white_box] "
        "<built-in function len>"
    ]


# ---- hypothesis: arithmetic equals CPython --------------------------------------------------------

_LEAVES = st.one_of(
    st.integers(-(10**6), 10**6).map(lambda v: f"({v})"),
    st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False).map(lambda v: f"({v!r})"),
    st.booleans().map(str),
)
_BINARY = ["+", "-", "*", "/", "//", "%", "<", ">", "==", "!=", "<=", ">=", "and", "or", "&", "|", "^"]


def _extend(children):
    binary = st.tuples(children, st.sampled_from(_BINARY), children).map(lambda t: f"({t[0]} {t[1]} {t[2]})")
    unary = st.tuples(st.sampled_from(["-", "+", "not ", "~"]), children).map(lambda t: f"({t[0]}{t[1]})")
    power = st.tuples(_LEAVES, st.integers(-2, 3)).map(lambda t: f"({t[0]} ** {t[1]})")
    # shift counts stay literal and small so that CPython itself stays fast
    shift = st.tuples(children, st.sampled_from(["<<", ">>"]), st.integers(-1, 70)).map(
        lambda t: f"({t[0]} {t[1]} {t[2]})"
    )
    cond = st.tuples(children, children, children).map(lambda t: f"({t[0]} if {t[1]} else {t[2]})")
    return st.one_of(binary, unary, power, shift, cond)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.recursive(_LEAVES, _extend, max_leaves=10))
def test_arithmetic_matches_python(expr):
    try:
        expected = eval(expr, {"__builtins__": {}})  # trusted, generated by the test
        if isinstance(expected, int) and expected.bit_length() > 4096:
            expected_text = "too large"
        else:
            expected_text = repr(expected)
    except (ArithmeticError, TypeError, ValueError) as exc:
        expected_text = type(exc).__name__
    except MemoryError:  # a shift by a huge count
        expected_text = "too large"
    try:
        got_text = run_program(f"result = {expr}\nprint(repr(result))\n", SORTING).output[0]
    except ProgramError as exc:
        if "integer too large" in exc.reason:
            got_text = "too large"
        else:
            got_text = exc.reason.split(":")[0]
    if expected_text == "too large" or got_text == "too large":
        # the sandbox refuses big integers before computing them; Python may fail differently
        assert got_text == "too large" and expected_text in ("too large", "OverflowError", "ValueError", "MemoryError")
    else:
        assert got_text == expected_text, expr


# ---- one list of builtins: sandbox, docs and prompt ---------------------------------------------

DOCS = Path(__file__).resolve().parent.parent / "docs" / "programs.md"


def test_every_listed_builtin_exists_in_a_program_and_nothing_else():
    from robocritics.program.sandbox import _FORBIDDEN_NAMES, _Interpreter

    implemented = {name[len("_b_") :] for name in dir(_Interpreter) if name.startswith("_b_")}
    assert implemented == set(SAFE_BUILTINS)
    assert not set(SAFE_BUILTINS) & set(_FORBIDDEN_NAMES)
    shown = run("print(" + ", ".join(SAFE_BUILTINS) + ")\n").output[0]
    assert shown == " ".join(f"<built-in function {name}>" for name in SAFE_BUILTINS)
    e = error("x = callable(len)\n")  # a real builtin that is not listed does not exist
    assert "'callable' is not available" in e.reason


def test_listed_methods_and_math_names_are_real_and_usable():
    for t, names in SAFE_METHODS.items():
        for name in names:
            assert callable(getattr(t, name)), (t, name)
    assert all(hasattr(math, name) for name in MATH_NAMES)
    plan = run("from math import " + ", ".join(MATH_NAMES) + "\nprint(sqrt(4.0), prod([2, 3]), 'a,b'.split(','))\n")
    assert plan.output == ["2.0 6 ['a', 'b']"]


def test_docs_list_exactly_the_sandbox_builtins():
    text = DOCS.read_text(encoding="utf-8")
    begin = "<!-- begin: generated by robocritics.program.language.reference_markdown() -->\n"
    end = "<!-- end: generated -->"
    assert begin in text and end in text
    block = text.split(begin, 1)[1].split(end, 1)[0]
    expected = reference_markdown()
    assert block == expected, f"regenerate the block in {DOCS.name} with reference_markdown():\n{expected}"
    documented = [line.split("`")[1] for line in block.splitlines() if line.startswith("| `")]
    assert documented == list(SAFE_BUILTINS)
