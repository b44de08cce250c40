"""collision: environment proximity, minus intended contacts."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from critic_asserts import assert_matches_reference, assert_well_formed, critic, run, execution_of
from critic_reference import ref_collision
from robocritics.critic import Flag
from robocritics.critic.builtin.collision import counted_distances
from robocritics.trajectory import Step
from strategies import trajectories
from synth import env_pair, make_trajectory, self_pair

T = 50
TIME = np.arange(T) / 125.0


def traj_with(pairs, distances, steps=None, step=None, attached=None):
    prox = np.ones((T, len(pairs)))
    for k, d in distances.items():
        prox[:, k] = d
    return make_trajectory(TIME, np.zeros((T, 1, 3)), pairs=pairs, proximity=prox, steps=steps, step=step, attached=attached)


def dip(depth, at=slice(20, 30)):
    d = np.full(T, 0.2)
    d[at] = depth
    return d


def test_gripper_tip_inside_a_box_errs_naming_part_object_time_and_line():
    pairs = [env_pair("left_finger", "white_box.wall_x+", group_b="container", entity="white_box")]
    steps = [Step(skill="move_to", line=3), Step(skill="move_down", line=7)]
    step = (np.arange(T) >= 15).astype(int)
    v = run("collision", traj_with(pairs, {0: dip(-0.01)}, steps=steps, step=step))
    assert v.flag is Flag.ERROR
    assert v.value == pytest.approx(-0.01) and v.threshold == 0.0 and v.unit == "m"
    assert "left_finger" in v.message and "white_box" in v.message and "penetrates" in v.message
    assert "1.0 cm" in v.message and f"{TIME[20]:.2f} s" in v.message
    assert v.evidence.lines == [7] and v.evidence.skills == ["move_down"]
    assert v.evidence.objects == ["white_box"] and v.evidence.links == ["left_finger"]
    assert (v.evidence.first_sample, v.evidence.last_sample) == (20, 29)
    assert "avoid_collision(white_box)" in v.hint and "line 7" in v.hint
    assert_well_formed(v, "collision")


def test_close_pass_warns_far_is_ok():
    pairs = [env_pair("forearm_link", "brown_box", group_a="arm", group_b="container")]
    v = run("collision", traj_with(pairs, {0: dip(0.03)}))
    assert v.flag is Flag.WARNING and v.value == pytest.approx(0.03) and v.threshold == 0.05
    assert "forearm_link" in v.message and "brown_box" in v.message
    assert_well_formed(v, "collision")
    v = run("collision", traj_with(pairs, {0: dip(0.08)}))
    assert v.flag is Flag.OK and v.value == pytest.approx(0.08)


def test_intended_contacts_do_not_count():
    pairs = [
        env_pair("left_finger", "apple", entity="apple"),  # the grasp target
        env_pair("gripper_body", "table", group_b="table", entity="table"),  # set-down surface
        env_pair("left_finger", "box", group_b="container", entity="box"),
    ]
    steps = [Step(skill="move_down", line=4), Step(skill="close_gripper", line=5, contacts=("apple",)), Step(skill="open_gripper", line=9, contacts=("table",))]
    step = np.zeros(T, dtype=int)
    step[20:30] = 1
    step[30:] = 2
    attached = [""] * 30 + ["apple"] * 10 + [""] * 10
    prox = {0: np.full(T, 0.2), 1: np.full(T, 0.2), 2: np.full(T, 0.2)}
    prox[0][20:40] = -0.002  # fingers on the apple while grasping (step 1) and holding it (attached)
    prox[1][30:50] = 0.0  # gripper at the table while setting down (step 2)
    traj = traj_with(pairs, prox, steps=steps, step=step, attached=attached)
    v = run("collision", traj)
    assert v.flag is Flag.OK, v.message
    # the same apple contact outside its grasp and while not held is a collision
    prox[0][10] = -0.002
    v = run("collision", traj_with(pairs, prox, steps=steps, step=step, attached=attached))
    assert v.flag is Flag.ERROR and v.evidence.worst_sample == 10 and v.evidence.samples_flagged == 1


def test_arm_links_always_count_even_against_the_grasp_target():
    pairs = [env_pair("wrist_3_link", "apple", group_a="arm", entity="apple")]
    steps = [Step(skill="close_gripper", line=5, contacts=("apple",))]
    v = run("collision", traj_with(pairs, {0: dip(-0.001)}, steps=steps, attached=["apple"] * T))
    assert v.flag is Flag.ERROR


def test_carried_object_hitting_a_container_errs():
    pairs = [env_pair("apple", "box", group_a="attached", group_b="container", entity="box")]
    v = run("collision", traj_with(pairs, {0: dip(-0.005)}, attached=["apple"] * T))
    assert v.flag is Flag.ERROR and "carried apple" in v.message


def test_carried_object_pairs_count_only_while_it_is_held():
    # the apple rests on the table (distance 0) before the grasp and after the release:
    # not the robot's collision; the same contact while carried is
    pairs = [env_pair("apple", "table", group_a="attached", group_b="table", entity="table")]
    d = np.zeros(T)
    held = [""] * 10 + ["apple"] * 30 + ["box"] * 10
    d[10:40] = 0.1
    assert run("collision", traj_with(pairs, {0: d}, attached=held)).flag is Flag.OK
    d[25] = -0.003
    v = run("collision", traj_with(pairs, {0: d}, attached=held))
    assert v.flag is Flag.ERROR and v.evidence.worst_sample == 25 and v.evidence.samples_flagged == 1


def test_self_pairs_are_not_collisions_and_ignored_pairs_do_not_count():
    pairs = [self_pair("forearm_link", "wrist_3_link"), env_pair("forearm_link", "plate", group_a="arm")]
    traj = traj_with(pairs, {0: dip(-0.01), 1: dip(0.0)})
    assert run("collision", traj).flag is Flag.ERROR
    v = run("collision", traj, ignore_pairs=("forearm_link|plate",))
    assert v.flag is Flag.OK and v.value is None


def test_counted_distances_masks_what_does_not_count():
    pairs = [self_pair("a", "b"), env_pair("left_finger", "apple")]
    steps = [Step(skill="close_gripper", line=2, contacts=("apple",))]
    D = counted_distances(traj_with(pairs, {0: 0.01, 1: 0.01}, steps=steps))
    assert np.isinf(D).all()


@st.composite
def params(draw):
    return {
        "d_warn_m": draw(st.sampled_from([0.01, 0.05, 0.1])),
        "penetration_m": draw(st.sampled_from([0.0, -0.01])),
        "contact_tolerance_m": draw(st.sampled_from([0.0, 0.003, 0.02])),
    }


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(traj=trajectories(), overrides=params())
def test_agrees_with_the_per_sample_reference(traj, overrides):
    c = critic("collision")
    p = c.Params(**overrides)
    v = c.check(execution_of(traj), p)
    assert_matches_reference(v, ref_collision(traj, p))
    assert_well_formed(v, "collision")


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(traj=trajectories())
def test_closest_is_the_row_minimum_of_the_counted_distances(traj):
    from robocritics.critic.builtin.collision import Counted

    want = counted_distances(traj).min(axis=1) if traj.proximity.shape[1] else np.full(len(traj), np.inf)
    got = Counted(traj).closest()
    np.testing.assert_array_equal(got, want)


def test_closest_with_intended_contacts_and_nothing_always_counted():
    pairs = [env_pair("left_finger", "apple.body", entity="apple"), env_pair("right_finger", "table.top", entity="table")]
    steps = [Step(skill="move_to", line=1), Step(skill="close_gripper", line=2, contacts=("apple",))]
    step = (np.arange(T) >= 25).astype(int)
    trajectory = traj_with(pairs, {0: dip(-0.002, slice(20, 40)), 1: 0.3}, steps=steps, step=step)
    from robocritics.critic.builtin.collision import Counted

    got = Counted(trajectory).closest()
    want = np.where(np.arange(T) >= 25, 0.3, dip(-0.002, slice(20, 40)))  # the apple counts until the grasp step
    want = np.minimum(want, 0.3)
    np.testing.assert_array_equal(got, want)


# --- intended contacts are touching, never a penetration (issue 26) --------------------------------------------


@settings(max_examples=80, deadline=None)
@given(
    depth=st.floats(0.0, 0.08),
    end=st.integers(1, T),
    start=st.integers(0, T - 1),
    placed_on=st.booleans(),
)
def test_a_carried_object_sunk_into_an_object_is_an_error_wherever_the_move_ends(depth, end, start, placed_on):
    """The carried apple dips ``depth`` m into the pear during samples start..end (possibly the last one, where
    the move ends). Whether or not the pear is listed as the step's contact (the apple set down on it), any
    overlap deeper than the tolerance is an Error; within it, only the intended contact is excused."""
    start = min(start, end - 1)
    tolerance = critic("collision").Params().contact_tolerance_m
    pairs = [env_pair("apple", "pear", group_a="attached", entity="pear")]
    steps = [Step(skill="move_linear", line=6, contacts=("pear", "table") if placed_on else ("table",))]
    d = np.full(T, 0.2)
    d[start:end] = -depth
    v = run("collision", traj_with(pairs, {0: d}, steps=steps, attached=["apple"] * T))
    if depth >= tolerance or not placed_on:
        assert v.flag is Flag.ERROR and v.value == pytest.approx(-depth), (depth, v.message)
        assert "carried apple" in v.message and "pear" in v.message
    else:
        assert v.flag is Flag.OK, v.message


def test_stacking_touch_within_the_tolerance_is_ok_and_deeper_is_an_error():
    pairs = [env_pair("apple", "plate", group_a="attached", entity="plate")]
    steps = [Step(skill="open_gripper", line=9, contacts=("plate",))]
    tolerance = critic("collision").Params().contact_tolerance_m
    assert run("collision", traj_with(pairs, {0: dip(-0.5 * tolerance)}, steps=steps, attached=["apple"] * T)).flag is Flag.OK
    v = run("collision", traj_with(pairs, {0: dip(-2 * tolerance)}, steps=steps, attached=["apple"] * T))
    assert v.flag is Flag.ERROR and v.threshold == 0.0
    # the tolerance is a Param: 0 makes any overlap of an intended contact an Error
    v = run("collision", traj_with(pairs, {0: dip(-0.5 * tolerance)}, steps=steps, attached=["apple"] * T), contact_tolerance_m=0.0)
    assert v.flag is Flag.ERROR


CARRY_GREEN_APPLE = """move_to(green_apple.x, green_apple.y, green_apple.z + 0.1)
move_down(0.1)
close_gripper()
move_up(0.1)
move_to(red_apple_1.x + {dx}, red_apple_1.y + {dy}, 0.15)
move_linear(red_apple_1.x + {dx}, red_apple_1.y + {dy}, {z})
"""


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    dx=st.sampled_from([0.0, 0.02, -0.03]),
    dy=st.sampled_from([0.0, 0.025]),
    z=st.sampled_from([0.045, 0.07, 0.09, 0.11]),
    continues=st.booleans(),
)
@example(dx=0.0, dy=0.0, z=0.045, continues=False)  # the case
@example(dx=0.0, dy=0.0, z=0.045, continues=True)
def test_simulated_carried_apple_driven_into_another_is_an_error_where_the_move_ends(dx, dy, z, continues):
    """The sorting scene (issue 26): the green apple carried down onto red_apple_1; the move ends there or goes
    on up. Wherever the trajectory's own proximity has the carried apple deeper than the tolerance in an object it
    is not released on, the collision verdict is an Error naming the carried apple."""
    from robocritics import Scene, critique, simulate

    program = CARRY_GREEN_APPLE.format(dx=dx, dy=dy, z=z) + ("move_up(0.1)\n" if continues else "")
    execution = simulate(program, Scene.builtin("sorting"))
    traj = execution.trajectory
    tolerance = critic("collision").Params().contact_tolerance_m
    carried = [k for k, p in enumerate(traj.pairs) if p.group_a == "attached" and p.a == "green_apple" and p.b_entity not in ("table", "")]
    held = traj.attached == "green_apple"
    deepest = min(float(traj.proximity[held, k].min()) for k in carried)
    verdict = critique(execution, critics=["collision"]).verdicts[0]
    if deepest < -tolerance:
        assert verdict.flag is Flag.ERROR and verdict.value <= deepest + 1e-12, (program, verdict.message)
    if z == 0.045 and dx == 0.0 and dy == 0.0:  # the case: 6 cm deep into red_apple_1
        assert deepest == pytest.approx(-0.06, abs=1e-3)
        assert "green_apple" in verdict.message and "red_apple_1" in verdict.message
