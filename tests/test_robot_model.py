"""UR3e model: vectorised FK against an independent DH computation, URDF facts, IK round trip."""

import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from robocritics import PlanningError, Robot, RobotModelError

# UR3e e-series DH, typed in again here on purpose (independent of the package)
D = [0.15185, 0.0, 0.0, 0.13105, 0.08535, 0.0921]
A = [0.0, -0.24355, -0.2132, 0.0, 0.0, 0.0]
ALPHA = [math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0]


def dh_frames(q):
    """DH frames 0..6 by the textbook product T_i = Rz(theta) Tz(d) Tx(a) Rx(alpha)."""
    T = np.eye(4)
    out = [T.copy()]
    for i in range(6):
        ct, st_, ca, sa = math.cos(q[i]), math.sin(q[i]), math.cos(ALPHA[i]), math.sin(ALPHA[i])
        Ti = np.array(
            [
                [ct, -st_ * ca, st_ * sa, A[i] * ct],
                [st_, ct * ca, -ct * sa, A[i] * st_],
                [0, sa, ca, D[i]],
                [0, 0, 0, 1],
            ]
        )
        T = T @ Ti
        out.append(T.copy())
    return out


@pytest.fixture(scope="module")
def robot():
    return Robot.ur3e()


joint_samples = arrays(np.float64, (8, 6), elements=st.floats(-2 * math.pi, 2 * math.pi, allow_nan=False))


@settings(max_examples=200, deadline=None)
@given(q=joint_samples)
def test_forward_matches_independent_dh(robot, q):
    frames = robot.forward(q)
    assert frames.shape == (8, len(robot.frame_names), 4, 4)
    names = robot.frame_names
    links = ["shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link", "wrist_3_link"]
    for t in range(q.shape[0]):
        dh = dh_frames(q[t])
        # tool0 is DH frame 6 exactly (position and orientation)
        np.testing.assert_allclose(frames[t, names.index("tool0")], dh[6], atol=1e-9)
        # link k's origin is DH frame k-1's origin (the joint it turns about)
        for k, link in enumerate(links):
            np.testing.assert_allclose(frames[t, names.index(link), :3, 3], dh[k][:3, 3], atol=1e-9)
        # the TCP is 0.15 m out along the flange z axis, fingers along +z
        tcp = frames[t, names.index("tcp")]
        np.testing.assert_allclose(tcp[:3, 3], dh[6][:3, 3] + 0.15 * dh[6][:3, 2], atol=1e-9)
        np.testing.assert_allclose(tcp[:3, 2], dh[6][:3, 2], atol=1e-12)


@settings(max_examples=50, deadline=None)
@given(q=joint_samples)
def test_forward_matches_pinocchio(robot, q):
    frames = robot.forward(q)
    data = robot.model.createData()
    for t in range(q.shape[0]):
        pin.framesForwardKinematics(robot.model, data, q[t])
        for i, name in enumerate(robot.frame_names):
            np.testing.assert_allclose(frames[t, i], data.oMf[robot.model.getFrameId(name)].homogeneous, atol=1e-12)


def test_urdf_limits_and_masses(robot):
    assert robot.n == 6
    np.testing.assert_allclose(robot.velocity_limits, [math.pi] * 3 + [2 * math.pi] * 3)
    masses = [robot.model.inertias[j].mass for j in range(1, 7)]
    # Pinocchio lumps the fixed gripper (0.9 kg body, 2 x 0.05 kg fingers) into wrist 3
    np.testing.assert_allclose(masses, [1.98, 3.4445, 1.437, 0.871, 0.805, 0.261 + 1.0])
    assert robot.max_opening_m == pytest.approx(0.085)
    assert set(robot.capsule_groups) == {"arm", "gripper"}
    assert robot.limits.velocity_rad_s == tuple(robot.velocity_limits)


def test_fingers_follow_the_opening(robot):
    q = np.tile(robot.home_q, (3, 1))
    frames = robot.forward(q, np.array([0.085, 0.04, 0.0]))
    left = frames[:, robot.frame_names.index("left_finger"), :3, 3]
    right = frames[:, robot.frame_names.index("right_finger"), :3, 3]
    gap = np.linalg.norm(left - right, axis=1) - 2 * robot.capsule_radii[robot.capsule_names.index("left_finger")]
    np.testing.assert_allclose(gap, [0.085, 0.04, 0.0], atol=1e-12)


@settings(max_examples=300, deadline=None)
@given(
    x=st.floats(0.12, 0.40),
    y=st.floats(-0.35, 0.35),
    z=st.floats(0.02, 0.30),
    yaw=st.floats(-math.pi, math.pi),
)
def test_ik_round_trip_fingers_down(robot, x, y, z, yaw):
    target = np.array([x, y, z])
    try:
        q = robot.ik(target, yaw_rad=yaw)
    except PlanningError as exc:
        # only genuinely unreachable targets may fail, and they say where and why
        assert f"{x:.3f}" in str(exc)
        return
    tcp = robot.tcp_pose(q)
    np.testing.assert_allclose(tcp[:3, 3], target, atol=1e-6)
    np.testing.assert_allclose(tcp[:3, 2], [0, 0, -1], atol=1e-6)  # fingers straight down
    assert robot.in_limits(q)


def test_ik_unreachable_names_target(robot):
    with pytest.raises(PlanningError, match=r"\(0\.900, 0\.000, 0\.100\).*out of reach"):
        robot.ik([0.9, 0.0, 0.1])


def test_bad_inputs_are_typed(robot, tmp_path):
    with pytest.raises(RobotModelError, match=r"shape"):
        robot.forward(np.zeros((3, 5)))
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/></robot")
    with pytest.raises(RobotModelError, match="cannot load URDF"):
        Robot.from_urdf(bad)


def test_self_pairs_are_non_adjacent(robot):
    pairs = set(robot.self_pairs)
    assert pairs, "the UR3e must have pinch-point pairs"
    adjacent = {("shoulder_link", "upper_arm_link"), ("upper_arm_link", "forearm_link"), ("forearm_link", "wrist_1_link")}
    assert not pairs & adjacent
    groups = dict(zip(robot.capsule_names, robot.capsule_groups))
    assert all(not (groups[a] == "gripper" and groups[b] == "gripper") for a, b in pairs)
    assert any(groups[b] == "gripper" for a, b in pairs), "arm-vs-gripper pairs are pinch points too"
