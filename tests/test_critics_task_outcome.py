"""task_outcome: goals checked on the final scene of real simulations of the bundled scenes."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from robocritics.critic import Flag, critique, get_critics
from robocritics.pipeline import check
from robocritics.critic.builtin.task_outcome import GoalOutcome, TaskOutcomeCritic
from robocritics.errors import CriticError, GoalError
from robocritics.goals import Goal
from robocritics.scene import Scene
from robocritics.pipeline import simulate

EXAMPLES = Path(__file__).parent.parent / "examples" / "programs"

#: the natural goal of each bundled task (see the comments at the top of its careful example)
TASK_GOALS = {
    "breakfast": ["fork in trash_bin", "cupcake on plate", "apple on plate"],
    "recycling": ["coffee_cup in trash_bin", "food_container in trash_bin", "water_bottle in trash_bin"],
    "sorting": ["red_apple_1 in brown_box", "red_apple_2 in brown_box", "green_apple in white_box"],
}


@pytest.fixture(scope="module")
def careful():
    return {name: simulate((EXAMPLES / f"{name}_careful.py").read_text(), Scene.builtin(name)) for name in TASK_GOALS}


@pytest.mark.parametrize("name", sorted(TASK_GOALS))
def test_the_careful_examples_meet_their_goals(careful, name):
    report = critique(careful[name], goals=TASK_GOALS[name])
    verdict = report.verdicts[-1]
    assert verdict.critic == "task_outcome" and verdict.flag is Flag.OK, verdict.message
    assert verdict.message == f"all 3 task goals met: {'; '.join(TASK_GOALS[name])}"
    assert report.passed and report.score == 10.0


def test_the_wrong_box_fails_naming_where_the_apple_ended(careful):
    report = critique(careful["sorting"], goals=["green_apple in brown_box", "red_apple_1 in brown_box"])
    verdict = report.verdicts[-1]
    assert verdict.flag is Flag.ERROR
    final = careful["sorting"].final_scene.entity("green_apple")
    x, y = final.position[:2]
    assert f"'green_apple in brown_box' — green_apple ended in white_box at ({x:.2f}, {y:.2f}) m" in verdict.message
    assert verdict.message.startswith("1 of 2 task goals unmet")
    assert verdict.evidence.objects == ["green_apple"]
    assert "green_apple" in verdict.hint
    # beside the score: the five motion critics still score 10, but the report fails
    assert report.score == 10.0 and report.has_errors and not report.passed
    assert [v.critic for v in report.scored_verdicts] == [v.critic for v in report.verdicts[:-1]]


def test_a_program_that_puts_the_object_in_the_wrong_place_fails_through_its_own_expect():
    scene = Scene.builtin("sorting")
    source = (EXAMPLES / "sorting_careful.py").read_text().replace(
        'box = brown_box if apple.ripeness == "ripe" else white_box', "box = brown_box"
    ).replace('"brown_box": [(-0.05, -0.05), (0.05, 0.05)]', '"brown_box": [(-0.05, -0.05), (0.05, 0.05), (0.0, 0.0)]')
    source += "\nexpect(green_apple, inside=white_box)\n"
    execution, report = check(source, scene)
    verdict = next(v for v in report.verdicts if v.critic == "task_outcome")
    assert verdict.flag is Flag.ERROR
    assert "green_apple ended in brown_box" in verdict.message and "m from white_box" in verdict.message
    assert verdict.evidence.lines == [len(source.splitlines())]  # the expect() line


def test_no_goals_skips_it_by_default_and_says_so_when_named(careful):
    report = critique(careful["sorting"])
    assert "task_outcome" not in report.critics
    named = critique(careful["sorting"], critics=["joint_speed", "task_outcome"])
    assert named.critics == ["joint_speed", "task_outcome"]
    assert named.verdicts[1].flag is Flag.OK and "nothing to check" in named.verdicts[1].message


def test_goals_need_an_execution_and_valid_ids(careful):
    with pytest.raises(CriticError, match="only an Execution has"):
        critique(careful["sorting"].trajectory, careful["sorting"].scene, goals=["green_apple in white_box"])
    with pytest.raises(GoalError, match="did you mean 'white_box'"):
        critique(careful["sorting"], goals=["green_apple in whte_box"])


def test_goals_are_checked_whichever_critics_were_chosen(careful):
    report = critique(careful["sorting"], critics="joint_speed", goals=["green_apple in brown_box"])
    assert report.critics == ["joint_speed", "task_outcome"] and report.has_errors
    assert report.score == 10.0


def test_the_critic_alone_reads_the_goals_of_the_run(careful):
    """An ordinary critic of the run contract: the goals travel in the Execution, not in its params."""
    critic = TaskOutcomeCritic()
    run = replace(careful["sorting"], goals=(Goal.parse("green_apple in brown_box"), Goal.parse("green_apple in white_box")))
    assert critic.requested(run) and not critic.requested(replace(run, goals=(), plan=None))
    verdict = critic.check(run, critic.Params())
    assert verdict.flag is Flag.ERROR and verdict.value == 1.0 and verdict.threshold == 2.0
    assert verdict.evidence.objects == ["green_apple"]
    assert "'green_apple in brown_box' — green_apple ended in white_box" in verdict.message
    assert [g["goal"] for g in verdict.details["goals"]] == ["green_apple in brown_box", "green_apple in white_box"]
    assert critique(run, critics="joint_speed").flag_of("task_outcome") is Flag.ERROR  # asked for by the run


def test_registered_like_the_others_when_its_entry_point_is_installed():
    # pyproject's entry point (task_outcome = "robocritics.critic.builtin.task_outcome") makes it installed; without it
    # critique() still brings it whenever there are goals
    installed = get_critics()
    if "task_outcome" in installed:
        assert isinstance(installed["task_outcome"], TaskOutcomeCritic)
    from robocritics.critic.builtin import task_outcome

    seen = []
    task_outcome.register_critics(seen.append)
    assert [c.name for c in seen] == ["task_outcome"]
