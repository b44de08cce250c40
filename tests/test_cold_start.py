"""First-use work of a cold ``robocritics check``, made cheaper, against the plain computations it replaced."""

from __future__ import annotations

import numpy as np
import pytest

from robocritics import Robot
from robocritics.robot.arms import ARMS, UR3E
from robocritics.robot.ik import ur_reach
from robocritics.robot.model import _SAME_HOUSING_GAP_M
from robocritics.robot.proximity import capsule_capsule

BUNDLED = [*ARMS, "panda"]


def robot_named(name: str) -> Robot:
    return Robot.panda() if name == "panda" else Robot.ur(name)


def self_pairs_one_by_one(robot: Robot) -> tuple[tuple[str, str], ...]:
    """The reference: every non-adjacent capsule pair not both on the gripper, one distance call per pair at
    q = 0, kept unless closer than the same-housing gap."""
    parent_of = {name: int(robot._frame_parent[i]) for i, name in enumerate(robot.frame_names)}
    parents = robot._joint_parents
    p0, p1 = robot.capsule_segments(robot.forward(np.zeros((1, robot.n))))
    pairs = []
    for i, ci in enumerate(robot.capsules):
        for j in range(i + 1, len(robot.capsules)):
            cj = robot.capsules[j]
            ji, jj = parent_of[ci.frame], parent_of[cj.frame]
            if (ci.group == cj.group == "gripper") or ji == jj or parents[ji] == jj or parents[jj] == ji:
                continue
            d = capsule_capsule(p0[:, i], p1[:, i], ci.radius_m, p0[:, j], p1[:, j], cj.radius_m)[0]
            if d >= _SAME_HOUSING_GAP_M:
                pairs.append((ci.name, cj.name))
    return tuple(pairs)


@pytest.mark.parametrize("name", BUNDLED)
def test_default_self_pairs_are_the_pairs_measured_one_by_one(name):
    robot = robot_named(name)
    reference = self_pairs_one_by_one(robot)
    assert reference  # every bundled arm has pinch-point pairs
    assert robot.self_pairs == reference


@pytest.mark.parametrize("name", list(ARMS))
def test_each_ur_arms_home_is_the_ur3e_home_scaled_by_reach(name):
    robot = Robot.ur(name)
    scale = ur_reach(ARMS[name].dh) / ur_reach(UR3E.dh)
    np.testing.assert_allclose(robot.tcp_pose(robot.home_q)[:3, 3], [0.25 * scale, 0.0, 0.25 * scale], atol=1e-9)
    assert (scale == 1.0) == (name == "ur3e")
