"""The stored copies of what Pinocchio reads from the bundled URDFs, and the two computations of Pinocchio's done
without it (robot/kinematic_tables.py), against Pinocchio itself: bit for bit, sign of zero included."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics import Robot
from robocritics.errors import RobotModelError
from robocritics.robot import kinematic_tables as kt
from robocritics.robot.arms import ARMS, BUNDLED_ARM_NAMES
from robocritics.robot.ik import dh_forward

angles = st.floats(-2 * math.pi, 2 * math.pi, allow_nan=False)
#: angles a URDF writes (multiples of pi/4, zero of both signs) beside arbitrary ones
urdf_angles = st.one_of(angles, st.sampled_from([0.0, -0.0, math.pi, -math.pi, math.pi / 2, -math.pi / 2, math.pi / 4]))


def bits(a) -> bytes:
    return np.ascontiguousarray(a, dtype=float).tobytes()


def same_tables(a: kt.KinematicTables, b: kt.KinematicTables) -> None:
    for name in kt.KinematicTables.__slots__:
        x, y = getattr(a, name), getattr(b, name)
        if name == "joint_motion":
            assert [k for k, _ in x] == [k for k, _ in y]
            assert bits([v for _, v in x]) == bits([v for _, v in y])
        elif name in ("name", "joint_names", "frame_names", "joint_parents"):
            assert x == y, name
        else:
            assert bits(x) == bits(y), name


@pytest.mark.parametrize("name", BUNDLED_ARM_NAMES)
def test_each_stored_copy_is_what_pinocchio_reads_from_its_urdf_now(name):
    urdf, text = kt.bundled_text(name)
    stored = kt.stored_tables(urdf.with_name(f"{name}.tables.json"), text)
    assert stored is not None, f"{name}.tables.json is stale: run python -m robocritics.robot.kinematic_tables"
    same_tables(stored, kt.KinematicTables.of_model(pin.buildModelFromXML(text), urdf))


def test_a_stored_copy_of_another_text_or_layout_is_not_used(tmp_path):
    urdf, text = kt.bundled_text("ur3e")
    tables = kt.KinematicTables.of_model(pin.buildModelFromXML(text), urdf)
    path = tmp_path / "t.json"
    path.write_text(tables.to_json(kt.urdf_digest(text)))
    assert kt.stored_tables(path, text) is not None
    assert kt.stored_tables(path, text.replace("0.15185", "0.15186")) is None  # one length changed
    path.write_text(tables.to_json(kt.urdf_digest(text)).replace('"format": 1', '"format": 2'))
    assert kt.stored_tables(path, text) is None
    path.write_text("{not json")
    assert kt.stored_tables(path, text) is None
    assert kt.stored_tables(tmp_path / "missing.json", text) is None


@pytest.mark.parametrize("name", BUNDLED_ARM_NAMES)
def test_a_bundled_arm_from_its_stored_copy_is_the_arm_pinocchio_reads(name, tmp_path, monkeypatch):
    """The bundled robot (stored tables, no Pinocchio model yet) and the same file read by Pinocchio: the same
    frames and capsules to the bit, the same limits, pairs, home and hash; its Pinocchio model built on use."""
    import robocritics.robot.model as model_module

    # loaded afresh: the parsed arms are shared by their copies, and an earlier test may have used Pinocchio on one
    monkeypatch.setattr(model_module, "_BUNDLED", {})
    bundled = Robot.bundled(name)
    # not built by loading a UR arm (the Panda's home comes from numeric IK, which runs on Pinocchio)
    assert (bundled._pinocchio._model is None) == (bundled.dh is not None)
    read = Robot(bundled.urdf_path, name=bundled.name, dh=bundled.dh, reach_m=bundled.reach_m,
                 acceleration_limits=bundled.acceleration_limits, jerk_limits=bundled.jerk_limits,
                 fixed_links=bundled.fixed_links, home=bundled.home_q)  # fmt: skip
    assert read._pinocchio._model is not None
    q = np.random.default_rng(0).uniform(bundled.lower, bundled.upper, size=(50, bundled.n))
    for a, b in zip(bundled.forward_with_capsules(q, 0.03), read.forward_with_capsules(q, 0.03)):
        assert bits(a) == bits(b)
    assert bundled.self_pairs == read.self_pairs and bundled.kinematic_hash == read.kinematic_hash
    assert bits(bundled.lower) == bits(read.lower) and bits(bundled.velocity_limits) == bits(read.velocity_limits)
    assert bundled.model.nq == bundled.n and bundled.data is bundled.data
    assert bundled.copy().data is not bundled.data and bundled.copy().model is bundled.model


@settings(max_examples=300, deadline=None)
@given(roll=urdf_angles, pitch=urdf_angles, yaw=urdf_angles)
def test_rpy_is_pinocchios_rpy_to_matrix_bit_for_bit(roll, pitch, yaw):
    assert bits(kt.pinocchio_rpy(roll, pitch, yaw)) == bits(pin.rpy.rpyToMatrix(roll, pitch, yaw))


@pytest.fixture(scope="module", params=BUNDLED_ARM_NAMES)
def arm(request):
    return Robot.bundled(request.param)


@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_one_tcp_pose_is_pinocchios_bit_for_bit(arm, data):
    """tcp_pose of one configuration (the planner's) equals forwardKinematics + updateFramePlacement, sign of
    zero included: an IK target one ulp off moves every later sample of a hashed trajectory."""
    assert arm._tcp_chain_about_z  # every bundled arm takes the path without Pinocchio
    q = np.array([data.draw(st.one_of(st.floats(lo, hi), st.sampled_from([0.0, -0.0]))) for lo, hi in zip(arm.lower, arm.upper)])
    pin.forwardKinematics(arm.model, arm.data, q)
    reference = pin.updateFramePlacement(arm.model, arm.data, arm._tcp_frame_id).homogeneous
    assert bits(arm.tcp_pose(q)) == bits(reference)


@settings(max_examples=200, deadline=None)
@given(axis=st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda v: np.linalg.norm(v) > 1e-3), angle=st.floats(0, math.pi))
def test_rotation_angle_is_the_norm_of_log3(axis, angle):
    R = pin.exp3(np.asarray(axis) / np.linalg.norm(axis) * angle)
    assert kt.rotation_angle(R) == pytest.approx(float(np.linalg.norm(pin.log3(R))), abs=1e-7)
    assert kt.rotation_angle(R) == pytest.approx(angle, abs=1e-7)


def test_a_urdf_of_other_joint_axes_takes_pinocchios_tcp_pose(tmp_path):
    """An arm loaded from a URDF of its own (here a joint about x) is read and computed by Pinocchio."""
    text = Robot.ur3e().urdf_path.read_text()
    old = '<joint name="wrist_3_joint" type="revolute">'
    assert old in text
    # turn the wrist 3 axis to x: the chain is no longer about z
    start = text.index(old)
    end = text.index("</joint>", start)
    joint = text[start:end]
    turned = joint.replace('<axis xyz="0 0 1"/>', '<axis xyz="1 0 0"/>')
    assert turned != joint
    path = tmp_path / "x.urdf"
    path.write_text(text[:start] + turned + text[end:])
    robot = Robot(path)
    assert not robot._tcp_chain_about_z
    q = np.array([0.1, -1.0, 1.2, -0.3, 0.4, 0.7])
    pin.forwardKinematics(robot.model, robot.data, q)
    assert bits(robot.tcp_pose(q)) == bits(pin.updateFramePlacement(robot.model, robot.data, robot._tcp_frame_id).homogeneous)


def test_a_missing_tcp_link_is_named_with_the_links(tmp_path):
    with pytest.raises(RobotModelError, match=r"no link 'nowhere' for the TCP; links are base_link, shoulder_link"):
        Robot(Robot.ur3e().urdf_path, tcp_frame="nowhere")


@settings(max_examples=100, deadline=None)
@given(q=st.tuples(*[angles] * 6), name=st.sampled_from(sorted(ARMS)))
def test_the_dh_flange_pose_is_pinocchios_on_the_dh_chain(q, name):
    """DH.flange_pose, the plain product the DH cross-check accepts on, against Pinocchio's FK of the chain."""
    np.testing.assert_allclose(ARMS[name].dh.flange_pose(q), dh_forward(ARMS[name].dh, np.array(q)), rtol=0, atol=1e-12)
