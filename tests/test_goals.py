"""robocritics.goals: parsing goals, checking their ids against a scene, and their outcome on a final scene."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from robocritics.errors import GoalError, RoboCriticsError
from robocritics.goals import Goal, check_outcomes, parse_goals, program_goals
from robocritics.scene import Scene
from robocritics.pipeline import simulate


@pytest.fixture(scope="module")
def breakfast():
    return Scene.builtin("breakfast")


@pytest.mark.parametrize(
    "text, goal",
    [
        ("green_apple in white_box", Goal(object="green_apple", relation="in", target="white_box")),
        ("cupcake on plate", Goal(object="cupcake", relation="on", target="plate")),
        ("  fork   inside trash_bin ", Goal(object="fork", relation="in", target="trash_bin")),
        ("apple onto table", Goal(object="apple", relation="on", target="table")),
    ],
)
def test_parse(text, goal):
    assert Goal.parse(text) == goal
    assert Goal.parse(str(goal)) == goal  # str() is the canonical text
    assert Goal.parse(goal) is goal


def test_goal_is_frozen_and_hashable():
    goal = Goal.parse("cupcake on plate")
    with pytest.raises(Exception):
        goal.object = "fork"  # type: ignore[misc]
    assert len({goal, Goal.parse("cupcake  on plate")}) == 1


@pytest.mark.parametrize(
    "text, words",
    [
        ("green_apple", "is not '<object> in <container>'"),
        ("", "is not '<object> in <container>'"),
        ("green apple in white_box", "is not '<object> in <container>'"),
        ("green_apple at white_box", "unknown relation 'at'; use 'in' or 'on'"),
        ("cupcake onn plate", "did you mean 'on'?"),
        ("a in b; import os", "is not"),
        ("x" * 5000, "(5,000 characters)"),  # quoted briefly
    ],
)
def test_parse_errors_say_what_is_wrong(text, words):
    with pytest.raises(GoalError) as info:
        Goal.parse(text)
    assert words in str(info.value)
    assert len(str(info.value)) < 300
    assert isinstance(info.value, RoboCriticsError) and isinstance(info.value, ValueError)


def test_parse_refuses_what_is_not_text():
    with pytest.raises(GoalError, match="not int"):
        Goal.parse(3)  # type: ignore[arg-type]


@given(st.text(max_size=80))
def test_parse_either_gives_a_goal_or_a_goal_error(text):
    try:
        goal = Goal.parse(text)
    except GoalError as exc:
        assert str(exc)
    else:
        assert goal.relation in ("in", "on") and goal.object.isidentifier() and goal.target.isidentifier()
        assert goal.object in text and goal.target in text


@pytest.mark.parametrize(
    "text, words",
    [
        ("cupcak on plate", "no object 'cupcak' in scene 'breakfast'; did you mean 'cupcake'?"),
        ("fork in trash", "no container 'trash' in scene 'breakfast'; did you mean 'trash_bin'?"),
        ("fork on trash_bin", "'trash_bin' is a container: use 'in'"),
        ("apple in plate", "'plate' is an object: use 'on'"),
        ("brown_box in trash_bin", "a container cannot be moved"),
        ("plate on plate", "cannot rest on itself"),
    ],
)
def test_check_names_the_bad_id(breakfast, text, words):
    with pytest.raises(GoalError) as info:
        Goal.parse(text).check(breakfast)
    assert words in str(info.value)


def test_parse_goals_keeps_order_drops_duplicates_and_checks_ids(breakfast):
    goals = parse_goals(["fork in trash_bin", "cupcake on plate", Goal.parse("fork in trash_bin")], breakfast)
    assert [str(g) for g in goals] == ["fork in trash_bin", "cupcake on plate"]
    assert parse_goals(None) == [] and parse_goals("cupcake on plate") == [Goal.parse("cupcake on plate")]
    with pytest.raises(GoalError):
        parse_goals(["fork in bin"], breakfast)


CUPCAKE_TO_TABLE = """
lib.open_gripper()
lib.move_above(cupcake, 0.08)
lib.move_linear(cupcake.x, cupcake.y, cupcake.z)
lib.close_gripper()
lib.move_up(0.10)
lib.move_to(0.31, -0.12, cupcake.z + 0.02)
lib.move_down(0.08)
lib.open_gripper()
lib.move_up(0.08)
lib.home()
expect(cupcake, on=plate)
expect(fork, on="table")
"""


@pytest.fixture(scope="module")
def misplaced(breakfast):
    return simulate(CUPCAKE_TO_TABLE, breakfast)


def test_outcome_says_where_the_object_ended(breakfast, misplaced):
    met, where = Goal.parse("cupcake on plate").outcome(misplaced)
    final = misplaced.final_scene.entity("cupcake")
    assert not met
    assert where.startswith("cupcake ended on the table at (0.31, -0.12) m")
    plate = breakfast.entity("plate")
    distance = ((final.position[0] - plate.position[0]) ** 2 + (final.position[1] - plate.position[1]) ** 2) ** 0.5
    assert where.endswith(f", {distance:.2f} m from plate")
    assert Goal.parse("cupcake on table").outcome(misplaced)[0]
    met, where = Goal.parse("cupcake in brown_box").outcome(misplaced)
    assert not met and "from brown_box" in where


def test_an_unmoved_object_is_judged_where_it_started(breakfast, misplaced):
    # the fork was never moved: it lies on the plate from the start
    assert Goal.parse("fork on plate").outcome(misplaced) == (True, "fork ended where it started at (0.30, 0.00) m")
    assert not Goal.parse("fork on table").met(misplaced)
    assert Goal.parse("apple in brown_box").met(misplaced)


def test_program_goals_come_from_expect_calls_with_their_lines(misplaced):
    stated = program_goals(misplaced.plan)
    assert [(str(g), line) for g, line in stated] == [("cupcake on plate", 12), ("fork on table", 13)]
    outcomes = check_outcomes(misplaced, ["cupcake on plate", "apple in brown_box"])
    by_goal = {o.goal: o for o in outcomes}
    assert list(by_goal) == ["cupcake on plate", "apple in brown_box", "fork on table"]
    assert by_goal["cupcake on plate"].lines == (12,) and not by_goal["cupcake on plate"].met
    assert by_goal["apple in brown_box"].met and by_goal["apple in brown_box"].lines == ()
    assert not by_goal["fork on table"].met


def test_expect_is_checked_by_the_sandbox(breakfast):
    from robocritics.errors import ProgramError

    for program, words in [
        ("expect(cupcake)\nhome()", "give exactly one of inside="),
        ("expect(cupcake, inside=brown_box, on=plate)\nhome()", "give exactly one of"),
        ("expect(cupcake, inside=brown_bx)\nhome()", "did you mean 'brown_box'"),
        ("expect(cupcake, on='tabel')\nhome()", "unknown object"),
        ("expect(cupcake, inside=plate)\nhome()", "'plate' is an object: use 'on'"),
        ("expect(brown_box, on=plate)\nhome()", "a container cannot be moved"),
    ]:
        with pytest.raises(ProgramError, match=words):
            simulate(program, breakfast)


def test_expect_makes_no_motion(breakfast):
    with_expect = simulate("home()\nexpect(apple, inside=brown_box)\n", breakfast)
    without = simulate("home()\n", breakfast)
    assert len(with_expect.trajectory) == len(without.trajectory)
    assert [s.skill for s in with_expect.trajectory.steps] == ["home"]


def test_an_object_stacked_above_the_rim_is_not_in_the_box():
    # the naive sorting program drops both ripe apples at the box centre: the second rests on the first, its
    # centre above the rim, so it is not in the box
    from pathlib import Path

    scene = Scene.builtin("sorting")
    source = (Path(__file__).parent.parent / "examples/programs/sorting_naive.py").read_text()
    execution = simulate(source, scene)
    assert execution.resting_on["red_apple_2"] == "red_apple_1"
    met, where = Goal.parse("red_apple_2 in brown_box").outcome(execution)
    z = execution.final_scene.entity("red_apple_2").position[2]
    assert not met
    assert where.endswith(f"its centre {z - scene.entity('brown_box').top:.2f} m above the rim of brown_box")
    assert Goal.parse("red_apple_1 in brown_box").met(execution)
