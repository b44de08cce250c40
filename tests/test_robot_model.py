"""UR3e model: vectorised FK against an independent DH computation, URDF facts, IK round trip,
independent robots, frames looked up by type."""

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
            frame = robot.model.getFrameId(name, pin.FrameType.BODY)
            np.testing.assert_allclose(frames[t, i], data.oMf[frame].homogeneous, atol=1e-12)


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


@settings(max_examples=300)
@given(
    radius=st.floats(0.16, 0.34),
    heading=st.floats(-math.pi, math.pi),
    z=st.floats(0.02, 0.25),
    yaw=st.floats(-math.pi, math.pi),
)
def test_ik_round_trip_fingers_down(robot, radius, heading, z, yaw):
    # the whole working annulus around the base is reachable with the fingers down:
    # outside the d4 + TCP-offset cylinder at the base axis, inside the arm's reach
    target = np.array([radius * math.cos(heading), radius * math.sin(heading), z])
    q = robot.ik(target, yaw_rad=yaw)
    tcp = robot.tcp_pose(q)
    np.testing.assert_allclose(tcp[:3, 3], target, atol=1e-6)
    np.testing.assert_allclose(tcp[:3, 2], [0, 0, -1], atol=1e-6)  # fingers straight down
    np.testing.assert_allclose(tcp[:3, 0], [math.cos(yaw), math.sin(yaw), 0], atol=1e-6)  # turned by yaw
    assert robot.in_limits(q)


@pytest.mark.parametrize(
    "unreachable, neighbour, reason",
    [
        ((0.9, 0.0, 0.1), (0.3, 0.0, 0.1), "out of reach"),
        ((0.0, 0.0, 0.1), (0.2, 0.0, 0.1), "too close to the base axis"),
    ],
)
def test_ik_unreachable_names_target(robot, unreachable, neighbour, reason):
    x, y, z = unreachable
    with pytest.raises(PlanningError, match=rf"\({x:.3f}, {y:.3f}, {z:.3f}\) m with the fingers down: .*{reason}"):
        robot.ik(unreachable)
    # the same direction, within reach, is solved: the failure is the target's, not the solver's
    q = robot.ik(neighbour)
    np.testing.assert_allclose(robot.tcp_pose(q)[:3, 3], neighbour, atol=1e-9)


def test_each_ur3e_is_independent():
    a, b = Robot.ur3e(), Robot.ur3e()
    home = Robot.ur3e().home_q.copy()
    for arr in (a.home_q, a.lower, a.upper, a.velocity_limits, a.acceleration_limits, a.jerk_limits,
                a.capsule_radii, a.tcp_in_flange):
        with pytest.raises(ValueError, match="read-only"):
            arr[0] += 1.0
    assert isinstance(a.self_pairs, tuple)
    # a new home pose changes that robot only
    a.home_q = home + 0.1
    np.testing.assert_array_equal(b.home_q, home)
    np.testing.assert_array_equal(Robot.ur3e().home_q, home)
    np.testing.assert_allclose(a.home_q, home + 0.1)
    # each robot has its own Pinocchio scratch data
    pa, pb = a.tcp_pose(a.home_q), b.tcp_pose(b.home_q)
    np.testing.assert_allclose(a.tcp_pose(a.home_q), pa)
    assert not np.allclose(pa, pb)


def test_home_q_is_checked(robot):
    other = robot.copy()
    with pytest.raises(RobotModelError, match="6 joint angles"):
        other.home_q = [0.0, 0.0]
    with pytest.raises(RobotModelError, match=r"joint 2 \(elbow_joint\) = 4.0000 rad is outside its limits"):
        other.home_q = [0.0, 0.0, 4.0, 0.0, 0.0, 0.0]
    np.testing.assert_array_equal(other.home_q, robot.home_q)


# A two-joint arm whose names collide: the joint that turns link "upper" is called
# "forearm", and the fixed joint that carries the TCP is called "tcp", like the links.
_SHARED_NAMES_URDF = """<?xml version="1.0"?>
<robot name="shared_names">
  <link name="base"/>
  <link name="upper"><collision><origin xyz="0.15 0 0" rpy="0 1.5707963267948966 0"/>
    <geometry><cylinder radius="0.03" length="0.3"/></geometry></collision></link>
  <link name="forearm"><collision><origin xyz="0.1 0 0" rpy="0 1.5707963267948966 0"/>
    <geometry><cylinder radius="0.02" length="0.2"/></geometry></collision></link>
  <link name="tcp"/>
  <joint name="forearm" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="2"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="forearm"/>
    <origin xyz="0.3 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="2"/></joint>
  <joint name="tcp" type="fixed"><parent link="forearm"/><child link="tcp"/><origin xyz="0.2 0 0" rpy="0 0 0"/></joint>
</robot>
"""


def test_links_are_found_when_joints_share_their_names(tmp_path):
    path = tmp_path / "shared_names.urdf"
    path.write_text(_SHARED_NAMES_URDF)
    arm = Robot.from_urdf(path)
    assert arm.frame_names == ("base", "upper", "forearm", "tcp")
    a, b = 0.7, -0.4
    frames = arm.forward(np.array([a, b]))
    # link "forearm" sits at the elbow, 0.3 m out along the turned x axis (the joint
    # called "forearm" is at the base: picking its frame would put it at (0, 0, 0.1))
    np.testing.assert_allclose(frames[2, :3, 3], [0.3 * math.cos(a), 0.3 * math.sin(a), 0.1], atol=1e-12)
    # the TCP 0.2 m further along the forearm, pitched by the elbow
    reach = 0.3 + 0.2 * math.cos(b)
    expected = [reach * math.cos(a), reach * math.sin(a), 0.1 - 0.2 * math.sin(b)]
    np.testing.assert_allclose(arm.tcp_pose(np.array([a, b]))[:3, 3], expected, atol=1e-12)
    np.testing.assert_allclose(frames[3], arm.tcp_pose(np.array([a, b])), atol=1e-12)
    # numeric IK targets the tcp link too
    target = arm.tcp_pose(np.array([a, b]))
    q = arm.ik(target[:3, 3], target[:3, :3], seed=np.array([0.5, -0.2]))
    np.testing.assert_allclose(arm.tcp_pose(q), target, atol=1e-8)


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
