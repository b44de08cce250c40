"""Critic-native repairs on real simulations (Pinocchio planner, built-in critics)."""

from __future__ import annotations

from pathlib import Path

import pytest

from robocritics import hookimpl
from robocritics.critic.plugins import pm
from robocritics.repair import Edit, Insert, MoveBlock, ScaleNumbers, apply_edits, paragraphs, repair
from robocritics.critic.verdict import Flag

PROGRAMS = Path(__file__).resolve().parents[1] / "examples" / "programs"


def _flag(report, critic):
    return next(v.flag for v in report.verdicts if v.critic == critic)


def test_edits_keep_comments_and_indentation():
    src = "# keep me\nfor i in [1]:\n    move_up(0.2)  # why\n    home()\n"
    out = apply_edits(src, [Insert(3, before=("set_speed(0.5)",), after=("set_speed(1)",)), ScaleNumbers(3, 0.5)])
    assert out == "# keep me\nfor i in [1]:\n    set_speed(0.5)\n    move_up(0.1)  # why\n    set_speed(1)\n    home()\n"


def test_spearing_repair_slows_only_the_plunge_and_names_its_line():
    src = (PROGRAMS / "recycling_naive.py").read_text()
    r = repair(src, "recycling", critics=["end_effector_pose", "joint_speed"])
    assert _flag(r.report, "end_effector_pose") != Flag.ERROR
    change = next(c for c in r.changes if c.critic == "end_effector_pose")
    assert change.line == 5 and "speed 1 ->" in change.what
    assert change.cost_s > 0  # slowing down costs cycle time
    # only the plunge is slowed: full speed is restored right after it
    assert "    set_speed(1)\n    close_gripper()" in r.program
    assert r.diff.count("+") >= 2


def test_space_usage_repair_lowers_heights_goal_still_met():
    src = (PROGRAMS / "sorting_naive.py").read_text()
    r = repair(src, "sorting", goal=["green_apple in white_box", "red_apple_1 in brown_box"])
    assert r.errors == []
    assert any(c.critic == "space_usage" and c.line == 11 for c in r.changes)
    assert "green_apple.z + 0.1" in r.program
    assert r.execution.object_inside("green_apple", "white_box")
    careful = repair((PROGRAMS / "sorting_careful.py").read_text(), "sorting")
    assert careful.changes == []  # nothing to repair
    assert r.execution.duration_s <= 1.5 * careful.execution.duration_s


class _Spoiler:
    """A plugin repair that 'fixes' spearing by a program that also leaves the workspace."""

    offered = 0

    @hookimpl
    def robocritics_repairs(self, verdict, execution, program):  # type: ignore[no-untyped-def]
        if verdict.critic != "end_effector_pose":
            return []
        _Spoiler.offered += 1
        first = min(c.line for c in execution.plan.calls)
        return [Edit("spoiler", first, "reach far out", "test", [Insert(first, before=("set_speed(0.05)", "move_to(0.0, 0.6, 0.5)"))])]


@pytest.fixture
def spoiler():
    plugin = _Spoiler()
    pm.register(plugin, name="test-spoiler")
    try:
        yield plugin
    finally:
        pm.unregister(plugin)


def test_plugin_repair_is_offered_and_one_that_adds_a_flag_is_rejected(spoiler):
    src = (PROGRAMS / "recycling_naive.py").read_text()
    r = repair(src, "recycling", critics=["end_effector_pose", "space_usage", "joint_speed"])
    assert _Spoiler.offered >= 1
    assert all(c.critic != "spoiler" for c in r.changes)
    assert "move_to(0.0, 0.6, 0.5)" not in r.program


def test_move_block_reorders_paragraphs_and_keeps_home_last():
    src = "# c\nmove_up(0.1)\nopen_gripper()\n\nmove_down(0.1)\nclose_gripper()\nhome()\n"
    assert paragraphs(src) == [(2, 3), (5, 7)]
    out = apply_edits(src, [MoveBlock(2, 5, 6)])
    assert out == "# c\nmove_down(0.1)\nclose_gripper()\n\nmove_up(0.1)\nopen_gripper()\n\nhome()\n"


CAREFUL_CYCLE_FACTOR = 1.5


@pytest.mark.parametrize(
    "task, goals",
    [
        ("sorting", ["green_apple in white_box", "red_apple_1 in brown_box", "red_apple_2 in brown_box"]),
        ("breakfast", ["fork in trash_bin", "apple on plate", "cupcake on plate"]),
        ("recycling", ["coffee_cup in trash_bin", "food_container in trash_bin", "water_bottle in trash_bin"]),
    ],
)
def test_every_bundled_naive_program_is_repaired_to_no_error(task, goals):
    naive = repair((PROGRAMS / f"{task}_naive.py").read_text(), task, goal=goals)
    careful = repair((PROGRAMS / f"{task}_careful.py").read_text(), task, goal=goals)
    print(f"{task}: repaired {naive.execution.duration_s:.1f} s vs careful {careful.execution.duration_s:.1f} s")
    assert naive.errors == [], [v.message for v in naive.errors]
    assert naive.execution.duration_s <= CAREFUL_CYCLE_FACTOR * careful.execution.duration_s
