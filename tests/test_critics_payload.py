"""payload: the carried mass against the UR3e's rated payload curve, and RNEA joint torques against their limits."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from robocritics.critic import Flag, critique
from robocritics.critic.builtin.payload import allowed_payload_kg, joint_torques
from robocritics.errors import CriticError, SceneError
from robocritics.robot.arms import UR3E
from robocritics.scene import Scene
from robocritics.pipeline import simulate

PROGRAM = """
lib.set_speed(0.3)
lib.open_gripper()
lib.move_above(red_apple_1, 0.1)
lib.move_linear(red_apple_1.x, red_apple_1.y, red_apple_1.z)
lib.close_gripper()
lib.move_up(0.15)
lib.move_to(0.25, -0.2, 0.2)
lib.move_to(0.3, 0.2, 0.2)
"""


def _sorting_with(mass_kg):
    scene = Scene.builtin("sorting")
    apple = scene.objects[0]
    return scene.with_object(apple.model_copy(update={"attributes": {**apple.attributes, "mass_kg": mass_kg}}))


@pytest.fixture(scope="module")
def runs():
    return {m: simulate(PROGRAM, _sorting_with(m)) for m in (0.3, 5.0)}


def _payload(report):
    return next(v for v in report.verdicts if v.critic == "payload")


def test_5_kg_on_a_ur3e_is_an_error_and_0_3_kg_is_fine(runs):
    light, heavy = critique(runs[0.3]), critique(runs[5.0])
    assert "payload" in light.critics  # asked for: the scene states masses
    ok, err = _payload(light), _payload(heavy)
    assert ok.flag is Flag.OK, ok.message
    assert err.flag is Flag.ERROR and "red_apple_1" in err.message
    assert err.details["payload_kg"] == pytest.approx(6.0)  # 1.0 kg gripper + 5 kg
    assert err.details["payload_kg"] > err.details["allowed_payload_kg"] and err.evidence.objects == ["red_apple_1"]
    assert not heavy.passed and heavy.score == light.score  # beside the score, counted in pass/fail


def test_the_payload_curve_is_flat_then_a_constant_moment():
    rated, knee = UR3E.rated_payload_kg, UR3E.payload_full_offset_m
    assert rated == 3.0
    got = allowed_payload_kg(rated, knee, np.array([0.0, knee, 2 * knee, 3 * knee]))
    assert got.tolist() == pytest.approx([3.0, 3.0, 1.5, 1.0])


def test_rnea_at_rest_is_the_weight_times_its_lever_about_the_shoulder(runs):
    """Static check of the torques against hand-computed gravity moments: tau_shoulder = sum m g x (lever)."""
    run = runs[5.0]
    t = run.trajectory
    held = np.flatnonzero(t.attached == "red_apple_1")
    tau = joint_torques(run)
    robot = run.robot
    # the sample where the arm moves least while holding the apple: dynamics are near zero there
    speed = np.abs(np.gradient(t.q, t.time, axis=0)).sum(axis=1)
    i = int(held[np.argmin(speed[held])])
    assert speed[i] < 1e-4  # it rests (the planner starts each move from standstill)
    model, data = robot.model, robot.model.createData()
    pin.forwardKinematics(model, data, t.q[i])
    axis_point = data.oMi[2].translation  # shoulder_lift joint origin
    axis = data.oMi[2].rotation[:, 2]
    moment = np.zeros(3)
    for j in range(2, model.njoints):
        com = data.oMi[j].act(model.inertias[j].lever)
        moment += np.cross(com - axis_point, model.inertias[j].mass * np.array([0, 0, -9.81]))
    apple = run.object_poses["red_apple_1"][i, :3, 3]
    moment += np.cross(apple - axis_point, 5.0 * np.array([0, 0, -9.81]))
    # the joint holds the weight: its torque balances the moment of gravity about its axis
    assert tau[i, 1] == pytest.approx(-moment @ axis, abs=0.02)


def test_no_masses_in_the_scene_is_not_asked_for_and_nothing_held_is_fine():
    run = simulate("home()\n", Scene.builtin("sorting"))
    assert "payload" not in critique(run).critics
    verdict = _payload(critique(run, critics=["payload"]))
    assert verdict.flag is Flag.OK and verdict.details["payload_kg"] == pytest.approx(1.0)


def test_a_mass_that_is_not_a_number_is_an_error_naming_the_field():
    with pytest.raises((SceneError, CriticError), match=r"objects\[0\]\.attributes\.mass_kg"):
        critique(simulate(PROGRAM, _sorting_with("heavy")), critics=["payload"])
