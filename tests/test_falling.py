"""Objects resting on one that is lifted fall to the support below (breakfast: the cupcake sits on the apple)."""

from __future__ import annotations

import numpy as np
import pytest

from robocritics.scene import Scene
from robocritics.pipeline import simulate

# lift the apple from under the cupcake (inside the brown box) and set it down on the table
LIFT_APPLE = """
lib.set_speed(0.3)
lib.open_gripper()
lib.move_above(apple, 0.08)
lib.move_linear(apple.x, apple.y, apple.z)
lib.close_gripper()
lib.move_up(0.15)
lib.move_to(0.3, 0.15, 0.2)
lib.move_down(0.12)
lib.open_gripper()
lib.move_up(0.1)
lib.home()
"""


@pytest.fixture(scope="module")
def breakfast():
    return Scene.builtin("breakfast")


@pytest.fixture(scope="module")
def lifted(breakfast):
    return simulate(LIFT_APPLE, breakfast)


def test_cupcake_falls_into_the_box_when_the_apple_is_lifted(breakfast, lifted):
    box = breakfast.entity("brown_box")
    cupcake = lifted.final_scene.entity("cupcake")
    assert lifted.resting_on["cupcake"] == "brown_box"
    assert lifted.object_on("cupcake", "brown_box")
    assert lifted.object_inside("cupcake", "brown_box")
    assert cupcake.bottom == pytest.approx(box.floor_top, abs=1e-9)
    assert cupcake.position[:2] == pytest.approx(breakfast.entity("cupcake").position[:2])
    fall = [e for e in lifted.events if e.kind == "fall"]
    assert len(fall) == 1 and "cupcake" in fall[0].detail and "brown_box" in fall[0].detail


def test_the_replay_poses_show_the_fall_at_the_lift(breakfast, lifted):
    poses = lifted.object_poses["cupcake"]
    assert poses.shape == (len(lifted.trajectory), 4, 4)
    z = poses[:, 2, 3]
    start = breakfast.entity("cupcake").position[2]
    end = lifted.final_scene.entity("cupcake").position[2]
    assert z[0] == pytest.approx(start) and z[-1] == pytest.approx(end)
    drop = int(np.flatnonzero(z < start - 1e-6)[0])
    # the fall happens when the apple starts to rise (the first sample of move_up), not before the grasp
    apple_z = lifted.object_poses["apple"][:, 2, 3]
    assert apple_z[drop - 1] == pytest.approx(breakfast.entity("apple").position[2], abs=1e-4)
    grasp = next(e for e in lifted.events if e.kind == "grasp")
    assert lifted.trajectory.time[drop] >= grasp.time_s
    step = lifted.trajectory.steps[int(lifted.trajectory.step[drop])]
    assert step.skill == "move_up"
    assert np.all(z[drop:] == pytest.approx(end))


def test_a_stack_falls_in_order_onto_the_table():
    # three boxes stacked on the table: lifting the bottom one drops the other two by its height, in order
    scene = Scene.model_validate(
        {
            "name": "stack",
            "objects": [
                {"id": "bottom", "shape": "box", "size": [0.04, 0.04, 0.04], "position": [0.3, 0.0, 0.02]},
                {"id": "middle", "shape": "box", "size": [0.04, 0.04, 0.03], "position": [0.3, 0.0, 0.055]},
                {"id": "top_box", "shape": "box", "size": [0.04, 0.04, 0.02], "position": [0.3, 0.0, 0.08]},
            ],
        }
    )
    program = """
lib.open_gripper()
lib.move_above(bottom, 0.12)
lib.move_linear(bottom.x, bottom.y, bottom.z)
lib.close_gripper()
lib.move_up(0.05)
lib.move_to(0.3, 0.2, 0.1)
lib.open_gripper()
lib.home()
"""
    execution = simulate(program, scene)
    final = execution.final_scene
    assert execution.resting_on["middle"] == "table"
    assert execution.resting_on["top_box"] == "middle"
    assert final.entity("middle").bottom == pytest.approx(0.0, abs=1e-9)
    assert final.entity("top_box").bottom == pytest.approx(final.entity("middle").top, abs=1e-9)


def test_releasing_before_lifting_leaves_what_rests_on_it(breakfast):
    program = """
lib.open_gripper()
lib.move_above(apple, 0.08)
lib.move_linear(apple.x, apple.y, apple.z)
lib.close_gripper()
lib.open_gripper()
lib.home()
"""
    execution = simulate(program, breakfast)
    assert not [e for e in execution.events if e.kind == "fall"]
    assert execution.final_scene.entity("cupcake").position == pytest.approx(breakfast.entity("cupcake").position)


def test_the_careful_breakfast_takes_the_cupcake_off_first_so_nothing_falls(breakfast):
    from pathlib import Path

    source = (Path(__file__).parent.parent / "examples/programs/breakfast_careful.py").read_text()
    execution = simulate(source, breakfast)
    assert not [e for e in execution.events if e.kind == "fall"]
    assert execution.object_on("cupcake", "plate") and execution.object_on("apple", "plate")


def test_the_grasp_takes_the_object_at_the_tcp_not_a_rounding_tie():
    # in a stack every centre lies on the finger axis: the lateral distances tie up to rounding, and the
    # grasped object must be the one whose centre is at the TCP (here the middle one), whatever the noise
    for x, y in ((0.3, 0.0), (0.27, -0.11), (0.21, 0.17)):
        scene = Scene.model_validate(
            {
                "name": "stack",
                "objects": [
                    {"id": "bottom", "shape": "box", "size": [0.04, 0.04, 0.04], "position": [x, y, 0.02]},
                    {"id": "middle", "shape": "box", "size": [0.04, 0.04, 0.03], "position": [x, y, 0.055]},
                    {"id": "top_box", "shape": "box", "size": [0.04, 0.04, 0.02], "position": [x, y, 0.08]},
                ],
            }
        )
        program = "lib.open_gripper()\nlib.move_above(middle, 0.12)\nlib.move_linear(middle.x, middle.y, middle.z)\n" \
                  "lib.close_gripper()\n"
        execution = simulate(program, scene)
        (grasp,) = [e for e in execution.events if e.kind == "grasp"]
        assert grasp.detail == "grasped middle", (x, y, grasp.detail)
