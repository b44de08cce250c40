"""A vendor arm's inferred home (inside the limits, free of collision, elbow up, the TCP above the table) and the
UR chain recognised in a vendor UR file (closed-form IK in its own base convention), from the pip packages'
URDFs as shipped (issue 24)."""

from __future__ import annotations

import importlib.util
import sysconfig
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from robocritics import Robot
from robocritics.robot.ik import ur_ik_all
from robocritics.robot.vendor import elbow_heights


def _site(package: str) -> Path | None:
    spec = importlib.util.find_spec(package)
    return Path(spec.origin).parent if spec and spec.origin else None


_ERD = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
_FILES = {
    "pybullet iiwa": (_site("pybullet_data"), "kuka_iiwa/model.urdf", {}),
    "pybullet xarm6": (_site("pybullet_data"), "xarm/xarm6_robot.urdf", {}),
    "erd ur5": (_ERD, "ur_description/urdf/ur5_robot.urdf", {}),
    "erd ur10": (_ERD, "ur_description/urdf/ur10_robot.urdf", {}),
    "erd panda": (_ERD, "panda_description/urdf/panda.urdf", {"tip": "panda_link8", "tool": "franka_hand"}),
    "rtb iiwa14": (_site("rtbdata"), "xacro/kuka_description/kuka_lbr_iiwa/urdf/lbr_iiwa_14_r820.urdf", {}),
    "rtb kr16": (_site("rtbdata"), "xacro/kuka_description/kuka_kr16/urdf/kr16_2.urdf", {}),
    "airo ur3e": (_site("airo_models"), "arms/ur3e/ur3e.urdf", {}),
    "airo ur5e": (_site("airo_models"), "arms/ur5e/ur5e.urdf", {}),
}
_ROBOTS: dict[str, Robot] = {}


def _robot(name: str) -> Robot:
    base, rel, kwargs = _FILES[name]
    path = base / rel if base else None
    if path is None or not path.is_file():
        pytest.skip("the package with this URDF is not installed (pip install '.[test]')")
    if name not in _ROBOTS:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            _ROBOTS[name] = Robot.from_urdf(path, **{"tool": "robotiq_2f85", **kwargs})
    return _ROBOTS[name].copy()


def _elbow_height_reference(robot: Robot, q) -> float:
    """elbow_heights for one configuration, from Pinocchio's joint placements, one joint at a time."""
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, np.asarray(q, float))
    origins = [data.oMi[j].translation.copy() for j in range(1, robot.model.njoints)]
    # the elbow and the wrist picked as the docstring says, on Pinocchio's placements at the clipped zero
    zero_data = robot.model.createData()
    pin.forwardKinematics(robot.model, zero_data, np.clip(np.zeros(robot.n), robot.lower, robot.upper))
    zero = [zero_data.oMi[j].translation.copy() for j in range(1, robot.model.njoints)]
    n = len(zero)
    elbow = max(range(2, n - 1), key=lambda k: (min(np.linalg.norm(zero[k] - zero[1]), np.linalg.norm(zero[k] - zero[-1])), -k))
    wrist = n - 1
    for k in range(elbow + 1, n):
        if np.linalg.norm(zero[k] - zero[elbow]) >= 0.01:
            wrist = k
            break
    s, w, e = origins[1], origins[wrist], origins[elbow]
    t = (e - s) @ (w - s) / ((w - s) @ (w - s))
    height = e[2] - (s + t * (w - s))[2]
    return float(height)


@pytest.mark.parametrize("name", list(_FILES))
def test_the_inferred_home_is_inside_the_limits_clear_and_elbow_up_with_the_tcp_above_the_table(name):
    from robocritics.geometry.kernels import capsule_capsule

    robot = _robot(name)
    q = robot.home_q
    assert robot.in_limits(q)
    frames, p0, p1 = robot.forward_with_capsules(q[None])
    assert elbow_heights(robot, frames)[0] > 0.0
    assert elbow_heights(robot, frames)[0] == pytest.approx(_elbow_height_reference(robot, q), abs=1e-9)
    tcp = frames[0, robot.tcp_index]
    assert tcp[2, 3] > 0.25 * robot.reach_m  # well above the table (half the reach is asked)
    assert tcp[2, 2] < -0.9  # fingers down
    # free of collision: no moving capsule touches the table, no pinch pair touches
    standing = set(robot.table_fixed_capsules) | {c.name for c in robot.capsules if c.frame in robot.fixed_links}
    lowest = np.minimum(p0[0, :, 2], p1[0, :, 2]) - robot.capsule_radii
    assert all(low > 0 for c, low in zip(robot.capsule_names, lowest) if c not in standing)
    names = robot.capsule_names
    for a, b in robot.self_pairs:
        i, j = names.index(a), names.index(b)
        assert capsule_capsule(p0[:, i], p1[:, i], robot.capsule_radii[i], p0[:, j], p1[:, j], robot.capsule_radii[j])[0] > 0


def test_elbow_heights_tell_the_elbow_up_branch_from_the_elbow_down_one_of_the_same_tcp_pose():
    robot = Robot.ur3e()
    flange = robot.forward(robot.home_q)[robot.frame_names.index("tool0")]
    branches = ur_ik_all(robot.dh, flange)
    heights = elbow_heights(robot, robot.forward(branches))
    # same TCP, both signs among the branches; the bundled home is an elbow-up one
    assert (heights > 0.01).any() and (heights < -0.01).any()
    assert elbow_heights(robot, robot.forward(robot.home_q[None]))[0] > 0.01
    for q, h in zip(branches, heights):
        assert h == pytest.approx(_elbow_height_reference(robot, q), abs=1e-9)


@pytest.mark.parametrize("name", ["erd ur5", "erd ur10", "airo ur3e", "airo ur5e"])
def test_a_vendor_ur_file_is_recognised_as_its_dh_chain_and_gets_the_nearest_closed_form_branch(name):
    robot = _robot(name)
    assert robot.dh is not None and robot.dh.is_ur_like
    # its base is ROS's, turned 180 deg about z against UR's DH base
    np.testing.assert_allclose(robot.dh_base_inverse[:3, :3], np.diag([-1.0, -1.0, 1.0]), atol=1e-9)
    rng = np.random.default_rng(5)
    for _ in range(20):
        q = rng.uniform(-np.pi, np.pi, 6)
        target = robot.tcp_pose(q)
        seed = q + rng.normal(0, 0.2, 6)
        solved = robot.ik(target[:3, 3], target[:3, :3], seed=seed)
        np.testing.assert_allclose(robot.tcp_pose(solved), target, atol=1e-7)  # the URDF's own FK
        # the nearest to the seed of every branch (the slow reference: all branches, each 2 pi shift in limits)
        flange = robot.dh_base_inverse @ target @ np.linalg.inv(robot.tcp_in_flange)
        best = np.inf
        for branch in ur_ik_all(robot.dh, flange):
            shifted = [[v + k * 2 * np.pi for k in (-2, -1, 0, 1, 2) if lo <= v + k * 2 * np.pi <= hi]
                       for v, lo, hi in zip(branch, robot.lower, robot.upper)]
            best = min(best, sum(min((c - s) ** 2 for c in cs) for cs, s in zip(shifted, seed)))
        assert np.sum((solved - seed) ** 2) == pytest.approx(best, abs=1e-9)


@pytest.mark.parametrize("name", ["pybullet iiwa", "pybullet xarm6", "rtb kr16", "erd panda"])
def test_an_arm_that_is_not_a_ur_chain_keeps_numeric_ik(name):
    assert _robot(name).dh is None


def test_a_wrist_with_less_than_a_turn_each_way_keeps_the_arms_branch():
    """The iiwa14's last joint stops at +-175 deg. A pick, then a place whose yaw puts the planner's posture seed
    for that wrist past -175 deg: the seed is taken at its in-limit equivalent (+ 2 pi), so numeric IK converges
    beside it, not after random restarts on another branch of the whole arm (a flipped elbow and wrist: joints 3
    and 6 turning by about 3 rad during a simple place)."""
    from robocritics import Scene, simulate

    robot = _robot("rtb iiwa14")
    s = robot.reach_m / 0.6
    scene = Scene.model_validate({
        "name": "pick",
        "objects": [{"id": "apple", "shape": "sphere", "size": [0.035], "position": [0.35 * s, 0.1 * s, 0.035]}],
        "containers": [{"id": "box", "size": [0.2, 0.2, 0.08], "position": [0.3 * s, -0.25 * s, 0.04]}],
    })
    program = ("lib.open_gripper()\nlib.move_above(apple, 0.1)\nlib.move_linear(apple.x, apple.y, apple.z)\n"
               "lib.close_gripper()\nlib.move_linear(apple.x, apple.y, apple.z + 0.15)\n"
               "lib.move_to(box.x, box.y, box.top + 0.12)\nlib.open_gripper()\n")
    q = simulate(program, scene, robot).trajectory.q
    travel = q.max(axis=0) - q.min(axis=0)  # rad each joint sweeps over the program
    assert travel[2] < 1.0 and travel[5] < 1.0, travel
    assert np.all(q[:, -1] <= robot.upper[-1] + 1e-12)
