"""Planner semantics of the skills: obstacle routing, gripper yaw, grasp and release, speed events."""

import math

import numpy as np
import pytest

from robocritics import Flag, PlanningError, Scene, critique, simulate

SCENE = Scene.builtin("sorting")
# low pass straight across the green apple, from one side of it to the other
CROSSING = "set_speed(0.3)\nmove_to(0.40, 0.14, 0.09)\n{avoid}move_to(0.40, -0.14, 0.09)\n"


def tcp_path(execution, line):
    traj = execution.trajectory
    lines = np.array([s.line for s in traj.steps])[traj.step]
    return traj.tcp[lines == line, :3, 3]


def test_avoid_collision_routes_above_the_obstacle():
    blind = simulate(CROSSING.format(avoid=""), SCENE)
    careful = simulate(CROSSING.format(avoid="avoid_collision(green_apple)\n"), SCENE)
    apple = SCENE.entity("green_apple")
    # without it the gripper sweeps over the apple too low; with it, it crosses high above
    assert critique(blind.trajectory, SCENE, critics=["collision"]).flag_of("collision") != Flag.OK
    assert critique(careful.trajectory, SCENE, critics=["collision"]).flag_of("collision") == Flag.OK
    path = tcp_path(careful, 4)
    over = np.abs(path[:, 1] - apple.position[1]) < 0.02
    assert over.any() and path[over, 2].min() >= apple.top + 0.08 - 1e-6
    # and it still ends where it was asked to
    np.testing.assert_allclose(careful.trajectory.tcp[-1, :3, 3], [0.40, -0.14, 0.09], atol=1e-6)
    assert any(e.kind == "obstacle" and e.line == 3 for e in careful.events)


def test_rotate_gripper_turns_the_closing_axis_not_the_fingers():
    execution = simulate("move_to(0.3, 0.0, 0.2)\nrotate_gripper(math.pi / 2)\n", SCENE)
    start, end = execution.trajectory.tcp[0], execution.trajectory.tcp[-1]
    np.testing.assert_allclose(end[:3, 2], [0, 0, -1], atol=1e-9)  # fingers still straight down
    assert abs(abs(float(np.dot(start[:3, 1], end[:3, 1]))) - 0.0) < 1e-6  # closing axis turned 90 degrees
    np.testing.assert_allclose(end[:3, 3], [0.3, 0.0, 0.2], atol=1e-6)


def test_grasped_object_follows_the_gripper_and_settles_where_released():
    program = (
        "set_speed(0.4)\nmove_above(green_apple, 0.05)\nmove_to(green_apple)\nclose_gripper()\n"
        "move_up(0.1)\nmove_to(0.30, 0.15, 0.12)\nopen_gripper()\n"
    )
    execution = simulate(program, SCENE)
    traj = execution.trajectory
    held = traj.attached == "green_apple"
    assert held.any() and not held[0] and not held[-1]
    assert np.all(traj.gripper_opening_m[held] == pytest.approx(0.07))
    final = execution.final_scene.entity("green_apple")
    assert final.position[:2] == pytest.approx((0.30, 0.15), abs=1e-6)
    assert final.bottom == pytest.approx(SCENE.table.top_z)  # dropped onto the table
    assert execution.object_on("green_apple", "table")
    kinds = [e.kind for e in execution.events]
    assert kinds.index("grasp") < kinds.index("release")


def test_closing_on_nothing_is_an_event_not_a_grasp():
    execution = simulate("move_to(0.25, 0.2, 0.15)\nclose_gripper()\n", SCENE)
    assert [e.kind for e in execution.events] == ["grasp_missed"]
    assert execution.trajectory.gripper_opening_m[-1] == 0.0
    assert not any(execution.trajectory.attached)


def test_a_line_that_leaves_the_reachable_region_midway_is_refused_at_its_line():
    # both ends are reachable, but the straight line passes too close to the base axis
    program = "move_to(0.2, 0.1, 0.2)\nmove_linear(-0.2, 0.1, 0.2)\n"
    with pytest.raises(PlanningError) as info:
        simulate(program, SCENE)
    assert info.value.line == 2
    assert "move_linear" in str(info.value) and "too close to the base axis" in str(info.value)
    # the same line farther from the axis is fine
    simulate(program.replace("0.1,", "0.16,"), SCENE)


def test_speed_events_and_step_speed_fractions():
    execution = simulate("reduce_speed(25)\nmove_to(0.3, 0.1, 0.2)\nset_speed(1)\nmove_to(0.3, -0.1, 0.2)\n", SCENE)
    fractions = {s.line: s.speed_fraction for s in execution.trajectory.steps}
    assert fractions[2] == 0.25 and fractions[4] == 1.0
    assert [e.detail for e in execution.events if e.kind == "speed"] == [
        "speed set to 25 % of full speed",
        "speed set to 100 % of full speed",
    ]
    assert math.isclose(execution.duration_s, execution.trajectory.time[-1] - execution.trajectory.time[0])


# --- the planner's cheap paths against the obvious computation ---------------------------------------------------


def _planner(scene=SCENE):
    from robocritics import Robot
    from robocritics.planning.planner import Planner, PlannerSettings

    robot = Robot.ur3e()
    return Planner(robot.scene_for(scene), robot, 125.0, PlannerSettings())


def test_current_tcp_is_the_fk_of_the_current_joints_and_a_fresh_copy():
    planner = _planner()
    first = planner.tcp()
    np.testing.assert_array_equal(first, planner.robot.tcp_pose(planner.q))
    first[:] = 0.0  # the caller's copy: the planner's pose is untouched
    np.testing.assert_array_equal(planner.tcp(), planner.robot.tcp_pose(planner.q))
    planner.q = planner.robot.ik(np.array([0.3, 0.1, 0.2]), seed=planner.q)  # a new configuration: a new pose
    np.testing.assert_array_equal(planner.tcp(), planner.robot.tcp_pose(planner.q))
    np.testing.assert_allclose(planner.tcp()[:3, 3], [0.3, 0.1, 0.2], atol=1e-9)


def _grasp_reference(planner, tcp):
    """grasp_candidate by the general 4x4 inverse and numpy (the slow obvious rule)."""
    best, best_d = None, math.inf
    inv = np.linalg.inv(tcp)
    for oid, o in planner.world.objects.items():
        if oid == planner.world.attached or not o.graspable:
            continue
        local = (inv @ np.append(np.asarray(o.position, float), 1.0))[:3]
        s = planner.settings
        if abs(local[0]) > s.grasp_region_m or abs(local[1]) > planner.robot.max_opening_m / 2:
            continue
        if not (-s.grasp_depth_m <= local[2] <= o.half_height + s.grasp_tip_gap_m):
            continue
        if np.linalg.norm(local) < best_d:
            best, best_d = oid, float(np.linalg.norm(local))
    return best


@pytest.mark.parametrize("scene_name", ["sorting", "recycling", "breakfast"])
def test_grasp_candidate_is_the_rigid_inverse_rule_at_every_object(scene_name):
    from robocritics.robot.model import fingers_down

    planner = _planner(Scene.builtin(scene_name))
    rng = np.random.default_rng(3)
    found = 0
    for o in list(planner.world.objects.values()):
        for _ in range(20):  # around each object's centre, at any yaw: inside and just outside the grasp region
            tcp = np.eye(4)
            tcp[:3, :3] = fingers_down(rng.uniform(-math.pi, math.pi))
            tcp[:3, 3] = np.asarray(o.position) + rng.normal(0.0, 0.03, 3)
            expected = _grasp_reference(planner, tcp)
            assert planner.world.grasp_candidate(tcp) == expected
            found += expected is not None
    assert found > 0  # some poses do grasp


def test_support_below_is_the_highest_surface_under_the_object():
    # the reorder of its tests keeps the rule: every container whose floor is under the point and reachable
    planner = _planner(Scene.builtin("sorting"))
    for c in planner.scene.containers:
        above_floor = np.array([c.position[0], c.position[1], c.floor_top + 0.05])
        assert planner.world.support_below("x", above_floor, 0.05, 0.02) == (c.id, c.floor_top)
        below_floor = np.array([c.position[0], c.position[1], c.floor_top - 0.01])
        assert planner.world.support_below("x", below_floor, 0.0, 0.02)[0] != c.id
