"""The skill API: normalised arguments, validation, ObjectView, the Plan types and the prompt reference."""

from __future__ import annotations

import copy
import inspect
import json
import math
import pickle

import pytest

from robocritics.errors import ProgramError
from robocritics.program import (
    SAFE_BUILTINS,
    SKILLS,
    Budget,
    Plan,
    SkillCall,
    api_reference,
    recording,
    run_program,
)
from robocritics.program import skills
from robocritics.program.plan import FrozenArgs
from robocritics.scene import Scene

SORTING = Scene.builtin("sorting")

ALL_SKILLS = {
    "expect",
    "move_to",
    "move_linear",
    "move_above",
    "move_up",
    "move_down",
    "open_gripper",
    "close_gripper",
    "rotate_gripper",
    "reduce_speed",
    "set_speed",
    "avoid_collision",
    "home",
    "wait",
}


def test_skill_table():
    assert set(SKILLS) == ALL_SKILLS
    for name, fn in SKILLS.items():
        assert fn.__name__ == name
        assert getattr(skills, name) is fn


# (call as written in a program, skill, normalised args)
NORMALISED = [
    ("move_to(0.3, 0.1, 0.2)", "move_to", {"target": (0.3, 0.1, 0.2)}),
    ("move_to(1, 0, 0)", "move_to", {"target": (1.0, 0.0, 0.0)}),
    ("move_to([0.3, -0.1, 0.25])", "move_to", {"target": (0.3, -0.1, 0.25)}),
    ("move_to(green_apple.position)", "move_to", {"target": (0.4, 0.0, 0.035)}),
    ("move_to(green_apple)", "move_to", {"object": "green_apple"}),
    ("move_to(white_box)", "move_to", {"object": "white_box"}),
    ("move_to(x=0.3, y=0.0, z=0.1)", "move_to", {"target": (0.3, 0.0, 0.1)}),
    ("move_linear(0.3, 0.1, 0.05)", "move_linear", {"target": (0.3, 0.1, 0.05)}),
    ("move_linear(red_apple_1)", "move_linear", {"object": "red_apple_1"}),
    ("move_above(green_apple)", "move_above", {"object": "green_apple", "height": 0.1}),
    ("move_above(brown_box, height=0.05)", "move_above", {"object": "brown_box", "height": 0.05}),
    ("move_above(brown_box, 0)", "move_above", {"object": "brown_box", "height": 0.0}),
    ("move_above((0.3, 0.1, 0.0))", "move_above", {"target": (0.3, 0.1, 0.0), "height": 0.1}),
    ("move_up(0.1)", "move_up", {"dz": 0.1}),
    ("move_down(1)", "move_down", {"dz": 1.0}),
    ("open_gripper()", "open_gripper", {}),
    ("close_gripper()", "close_gripper", {}),
    ("rotate_gripper(math.pi / 2)", "rotate_gripper", {"angle": math.pi / 2}),
    ("rotate_gripper(-6.28)", "rotate_gripper", {"angle": -6.28}),
    ("reduce_speed(30)", "reduce_speed", {"fraction": 0.3}),
    ("reduce_speed(100)", "reduce_speed", {"fraction": 1.0}),
    ("set_speed(0.25)", "set_speed", {"fraction": 0.25}),
    ("set_speed(1)", "set_speed", {"fraction": 1.0}),
    ("avoid_collision(white_box)", "avoid_collision", {"object": "white_box"}),
    ("avoid_collision('green_apple')", "avoid_collision", {"object": "green_apple"}),
    ("home()", "home", {}),
    ("wait(0)", "wait", {"seconds": 0.0}),
    ("wait(2.5)", "wait", {"seconds": 2.5}),
]


@pytest.mark.parametrize("call,skill,args", NORMALISED, ids=[c for c, _, _ in NORMALISED])
def test_normalised_arguments(call, skill, args):
    plan = run_program(call, SORTING)
    (recorded,) = plan.calls
    assert recorded.skill == skill
    assert dict(recorded.args) == args
    for value in recorded.args.values():
        if isinstance(value, tuple):
            assert all(type(v) is float for v in value)
        elif not isinstance(value, str):
            assert type(value) is float
    # the same through lib.
    assert run_program("lib." + call, SORTING).calls[0].args == recorded.args


REJECTED = [
    ("move_to(0.3, 0.1, None)", "needs all three coordinates"),
    ("move_to(0.3, None, 0.1)", "needs all three coordinates"),
    ("move_to(green_apple, 0.1, 0.2)", "give either one point/object or three numbers"),
    ("move_to((0.1, 0.2, 'z'))", "point[2] must be a number"),
    ("move_to({'x': 1})", "needs three coordinates"),
    ("move_to(0.3, 0.1, 11)", "far outside any robot's reach"),
    ("move_linear(1e309, 0, 0)", "is inf"),
    ("move_above(green_apple, height=2)", "more than 1 m"),
    ("move_above(green_apple, height='high')", "height must be a number (metres)"),
    ("move_above('blue_box')", "unknown object 'blue_box'"),
    ("move_up(True)", "dz must be a number"),
    ("move_down(1.5)", "more than 1 m"),
    ("rotate_gripper(7)", "use math.radians(7)"),
    ("rotate_gripper(float('nan'))", "angle is nan"),
    ("reduce_speed(-5)", "1 <= percent <= 100"),
    ("set_speed(0)", "0.01 <= fraction <= 1"),
    ("set_speed(1.5)", "for percent use reduce_speed(1.5)"),
    ("avoid_collision()", "missing a required argument: 'obj'"),
    ("avoid_collision((0.1, 0.2, 0.3))", "obj must be a scene object"),
    ("wait(10.5)", "seconds must be in 0..10"),
    ("home(1)", "too many positional arguments"),
    ("wait(seconds=1, s=2)", "unexpected keyword argument 's'"),
]


@pytest.mark.parametrize("call,message", REJECTED, ids=[c for c, _ in REJECTED])
def test_rejected_arguments(call, message):
    with pytest.raises(ProgramError) as info:
        run_program("import math\nx = 1\n" + call + "\n", SORTING)
    assert message in info.value.reason
    assert (info.value.line, info.value.col) == (3, 1)


def test_skill_call_limit_names_the_line():
    with pytest.raises(ProgramError) as info:
        run_program("for i in range(3000):\n    wait(0)\n", SORTING)
    assert info.value.line == 2
    assert "more than 2000 skill calls" in info.value.reason


# ---- ObjectView -----------------------------------------------------------------------------------


def test_object_view_fields():
    views = skills.views_of(SORTING)
    apple = views["green_apple"]
    assert apple.id == apple.name == "green_apple"
    assert apple.kind == "object" and apple.shape == "sphere" and apple.graspable is True
    assert apple.position == (0.4, 0.0, 0.035)
    assert (apple.x, apple.y, apple.z) == apple.position
    assert apple.size == (0.035,)
    assert apple.top == pytest.approx(0.07) and apple.bottom == pytest.approx(0.0)
    assert apple.height == pytest.approx(0.07) and apple.width == pytest.approx(0.07)
    assert apple.colour == "green" and apple.ripeness == "unripe"
    assert apple.attributes == {"colour": "green", "ripeness": "unripe"}
    box = views["white_box"]
    assert box.kind == "container" and box.graspable is False
    assert box.top == pytest.approx(0.08) and box.floor == pytest.approx(0.005)
    assert box.width == pytest.approx(0.2) and box.colour == "white"
    assert str(apple) == repr(apple) == "green_apple"
    assert f"{apple:>12}" == " green_apple"
    assert apple == views["green_apple"] and apple != box
    assert len({apple, views["green_apple"], box}) == 2


def test_object_view_is_read_only_and_copies_attributes():
    apple = skills.views_of(SORTING)["green_apple"]
    with pytest.raises(AttributeError, match="read-only"):
        apple.x = 5
    with pytest.raises(AttributeError, match="read-only"):
        del apple.colour
    attrs = apple.attributes
    attrs["colour"] = "blue"
    assert apple.colour == "green"
    with pytest.raises(AttributeError, match="did you mean 'ripeness'"):
        apple.ripness


def test_object_view_of_nested_attributes_is_a_copy():
    scene = Scene.model_validate(
        {
            "objects": [
                {
                    "id": "cup",
                    "shape": "cylinder",
                    "size": [0.04, 0.1],
                    "position": [0.3, 0, 0.05],
                    "attributes": {"tags": ["fragile"], "id": "shadowed", "fill": {"ml": 200}},
                }
            ]
        }
    )
    plan = run_program(
        "t = cup.tags\nt.append('x')\nprint(cup.tags, cup.id, cup.fill['ml'], cup.attributes['id'])\n", scene
    )
    assert plan.output == ["['fragile'] cup 200 shadowed"]


# ---- recording from trusted Python ------------------------------------------------------------------


def test_recording_context_records_with_python_lines():
    with recording(SORTING) as plan:
        skills.move_above("green_apple")
        line = inspect.currentframe().f_lineno - 1
        skills.close_gripper()
    assert [c.skill for c in plan.calls] == ["move_above", "close_gripper"]
    assert plan.calls[0].line == line
    assert plan.calls[0].args == {"object": "green_apple", "height": 0.1}


def test_skills_outside_a_run_explain_themselves():
    with pytest.raises(ProgramError, match="run_program"):
        skills.home()


# ---- Plan and SkillCall -------------------------------------------------------------------------------


def test_skill_call_is_frozen_hashable_and_serialisable():
    call = SkillCall("move_to", {"target": (0.3, 0.1, 0.2)}, 3, 5, (10,))
    assert isinstance(call.args, FrozenArgs)
    assert call.args == {"target": (0.3, 0.1, 0.2)}
    with pytest.raises(TypeError):
        call.args["target"] = (0, 0, 0)  # type: ignore[index]
    with pytest.raises(TypeError):
        call.args.update(x=1)  # type: ignore[attr-defined]
    with pytest.raises(AttributeError):
        call.line = 4  # type: ignore[misc]
    assert hash(call) == hash(SkillCall("move_to", {"target": (0.3, 0.1, 0.2)}, 3, 5, (10,)))
    assert pickle.loads(pickle.dumps(call)) == call
    assert copy.deepcopy(call) == call
    assert SkillCall.from_dict(json.loads(json.dumps(call.to_dict()))) == call


def test_describe():
    cases = [
        (SkillCall("move_to", {"target": (0.3, 0.1, 0.2)}, 1), "move_to(x=0.3, y=0.1, z=0.2)"),
        (SkillCall("move_linear", {"object": "green_apple"}, 1), "move_linear(green_apple)"),
        (SkillCall("move_above", {"object": "white_box", "height": 0.05}, 1), "move_above(white_box, height=0.05)"),
        (
            SkillCall("move_above", {"target": (0.3, 0.0, 0.0), "height": 0.1}, 1),
            "move_above(x=0.3, y=0, z=0, height=0.1)",
        ),
        (SkillCall("move_up", {"dz": 0.1}, 1), "move_up(dz=0.1)"),
        (SkillCall("rotate_gripper", {"angle": math.pi / 2}, 1), "rotate_gripper(angle=1.571)"),
        (SkillCall("reduce_speed", {"fraction": 0.3}, 1), "reduce_speed(percent=30)"),
        (SkillCall("set_speed", {"fraction": 0.5}, 1), "set_speed(fraction=0.5)"),
        (SkillCall("avoid_collision", {"object": "white_box"}, 1), "avoid_collision(white_box)"),
        (SkillCall("wait", {"seconds": 1.0}, 1), "wait(seconds=1)"),
        (SkillCall("home", {}, 1), "home()"),
    ]
    for call, text in cases:
        assert call.describe() == text


def test_plan_round_trip_and_describe():
    plan = run_program("move_above(green_apple)\nmove_to(0.3, 0, 0.1)\nprint('ok')\n", SORTING)
    again = Plan.from_dict(json.loads(json.dumps(plan.to_dict())))
    assert again == plan
    assert plan.describe() == "line 1: move_above(green_apple, height=0.1)\nline 2: move_to(x=0.3, y=0, z=0.1)"


# ---- the reference for the system prompt -----------------------------------------------------------------


def test_api_reference_lists_every_skill_with_its_docstring():
    text = api_reference()
    for name, fn in SKILLS.items():
        assert skills.usage(name) in text
        summary = inspect.cleandoc(fn.__doc__).splitlines()[0]
        assert summary in text
        assert "Example:" in fn.__doc__
    assert "print(*values" in text
    assert "metres" in text and "radians" in text
    assert "INITIAL scene" in text
    assert "move_to(x, y, z)  |  move_to(point)  |  move_to(obj)" in text


def test_docstring_examples_run():
    """Every example line in the skill docstrings is a valid program for the sorting scene."""
    for name, fn in [*SKILLS.items(), ("print", skills.print)]:
        doc = inspect.cleandoc(fn.__doc__)
        example = doc.split("Example:")[1]
        lines = [line.strip().split("  #")[0] for line in example.strip().splitlines()]
        plan = run_program("import math\n" + "\n".join(lines), SORTING)
        if name != "print":
            assert name in [c.skill for c in plan.calls], name


def test_api_reference_names_the_sandbox_builtins():
    text = " ".join(api_reference().split())
    assert "the builtins " + ", ".join(SAFE_BUILTINS) + "." in text


def test_skill_docstrings_state_the_limits_the_skills_enforce():
    assert f"0 <= seconds <= {skills._MAX_WAIT_S:g}" in skills.wait.__doc__
    for fn in (skills.move_up, skills.move_down):
        assert f"0 < dz <= {skills._MAX_MOVE_M:g}" in fn.__doc__
    assert f"must be 0..{skills._MAX_MOVE_M:g}" in skills.move_above.__doc__
    last_ok = f"wait({skills._MAX_WAIT_S:g})\nmove_up({skills._MAX_MOVE_M:g})\n"
    assert [c.skill for c in run_program(last_ok, SORTING).calls] == ["wait", "move_up"]


def test_recording_takes_the_sandbox_budget():
    two_calls = Budget(max_skill_calls=2)
    with pytest.raises(ProgramError, match="more than 2 skill calls"), recording(SORTING, budget=two_calls):
        for _ in range(3):
            skills.home()


def test_skill_limits_are_budget_errors_naming_the_field():
    from robocritics.program import BudgetError

    with pytest.raises(BudgetError) as info:
        run_program("for i in range(3000):\n    wait(0)\n", SORTING)
    assert (info.value.limit, info.value.line) == ("max_skill_calls", 2)
    with pytest.raises(BudgetError) as info:
        run_program("for i in range(100):\n    print('x' * 5000)\n", SORTING)
    assert (info.value.limit, info.value.line) == ("max_output_chars", 2)


def test_skill_errors_quote_huge_values_briefly():
    for call in ("move_to('x' * 100000)", "move_to(2 ** 4000, 0, 0)", "move_above(green_apple, height=10 ** 300)"):
        with pytest.raises(ProgramError) as info:
            run_program(call + "\n", SORTING)
        assert len(info.value.reason) < 400, call


def test_describe_names_a_posture_that_is_not_the_default():
    from robocritics import Scene, simulate

    program = 'move_to(0.3, 0.1, 0.2, posture="natural")\nmove_above(green_apple, 0.1, posture="natural")\nhome()\n'
    described = [c.describe() for c in simulate(program, Scene.builtin("sorting")).plan.calls]
    assert described[:2] == ["move_to(x=0.3, y=0.1, z=0.2, posture='natural')",
                             "move_above(green_apple, height=0.1, posture='natural')"]  # fmt: skip
    default = simulate("move_to(0.3, 0.1, 0.2)\n", Scene.builtin("sorting")).plan.calls[0].describe()
    assert "posture" not in default
