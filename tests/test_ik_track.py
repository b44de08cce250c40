"""Tracking IK (robot/ik_track.py) against the general solver it stands in for on lines (robot/ik_numeric.py)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from ik_reference import descent_reference

from robocritics import Robot
from robocritics.robot import ik_numeric
from robocritics.robot.ik_track import track_pose

PANDA = Robot.panda()


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_tracking_a_nearby_target_finds_the_general_solvers_solution(seed_value):
    rng = np.random.default_rng(seed_value)
    robot = PANDA
    span = robot.upper - robot.lower
    seed = rng.uniform(robot.lower + 0.2 * span, robot.upper - 0.2 * span)
    target = robot.tcp_pose(np.clip(seed + rng.normal(0.0, 0.01, robot.n), robot.lower, robot.upper))
    q = track_pose(robot.model, robot.data, robot._tcp_frame_id, target[:3, :3], target[:3, 3], seed,
                   robot.lower, robot.upper)
    reference = descent_reference(robot, target, seed)
    assert q is not None
    assert np.abs(robot.tcp_pose(q) - target).max() < 1e-9
    # the 7-joint solution nearest the seed: the general solver's slide stops within ~1e-7 rad of it
    assert np.abs(q - reference).max() < 1e-6
    assert np.linalg.norm(q - seed) <= np.linalg.norm(reference - seed) + 1e-9


def test_a_line_on_the_panda_is_what_point_by_point_ik_gives():
    robot = Robot.panda()
    start = robot.tcp_pose(robot.home_q)[:3, 3]
    points = start + np.linspace(0.0, 0.1, 21)[:, None] * np.array([0.0, 0.3, -0.95])
    q, err = robot.ik_line(points)
    assert err is None
    seed = robot.home_q
    for row, point in zip(q, points):
        seed = robot.ik(point, seed=seed)
        assert np.abs(row - seed).max() < 1e-6


def test_newton_from_a_far_seed_lands_no_farther_than_the_descent():
    """Numeric IK's first try: Newton from a seed 0.3 rad (s.d. per joint) from the posture that made the target,
    steps shortened to ``ik_track._TRUST_RAD``, up to ``NEWTON_FIRST_STEPS``. Where it settles (at least 35 of
    40 here), the pose is exact and the answer is no farther from the seed than the damped descent's."""
    rng = np.random.default_rng(3)
    robot = PANDA
    span = robot.upper - robot.lower
    settled = 0
    for _ in range(40):
        seed = rng.uniform(robot.lower + 0.2 * span, robot.upper - 0.2 * span)
        made = np.clip(seed + rng.normal(0.0, 0.3, robot.n), robot.lower, robot.upper)
        target = robot.tcp_pose(made)
        q = track_pose(robot.model, robot.data, robot._tcp_frame_id, target[:3, :3], target[:3, 3], seed,
                       robot.lower, robot.upper, max_move_rad=ik_numeric.NEAR_SEED_RAD,
                       max_steps=ik_numeric.NEWTON_FIRST_STEPS)
        if q is None:
            continue  # numeric IK's descents answer instead
        settled += 1
        assert np.abs(robot.tcp_pose(q) - target).max() < 1e-9
        assert np.linalg.norm(q - seed) <= np.linalg.norm(descent_reference(robot, target, seed, made) - seed) + 1e-6
    assert settled >= 35
