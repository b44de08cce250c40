"""Approach directions (robot/approach.py), the tool mount out of the wrist (robot/vendor.py) and tilted
pick-and-place on 5- and 6-joint vendor arms through the CLI (issue 24)."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings, strategies as st

from robocritics import Robot
from robocritics.robot.approach import TILT_LADDER_RAD, approach_rotation, fingers_down, infer_tilts
from robocritics.robot.ik_numeric import pointing_ik
from test_robot_vendor import _PICK, _erd, _pick_scene

SHOULDER = np.array([0.02, -0.03, 0.15])


@given(st.floats(-math.pi, math.pi), st.floats(0.0, math.pi / 2), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0),
       st.floats(0.0, 0.5))
@settings(max_examples=200, deadline=None)
def test_the_tilt_is_the_angle_from_down_and_leans_outwards(yaw, tilt, x, y, z):
    p = np.array([x, y, z])
    u = p[:2] - SHOULDER[:2]
    R = approach_rotation(p, yaw, tilt, SHOULDER)
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-12) and np.linalg.det(R) == pytest.approx(1.0)
    f = R[:, 2]  # the finger axis
    if np.linalg.norm(u) < 1e-6:
        return
    assert math.acos(np.clip(-f[2], -1, 1)) == pytest.approx(tilt, abs=1e-7)  # the angle from straight down
    # in the vertical plane through the shoulder and the point, leaning away from the shoulder
    u /= np.linalg.norm(u)
    assert f[:2] @ np.array([-u[1], u[0]]) == pytest.approx(0.0, abs=1e-9)
    assert f[:2] @ u == pytest.approx(math.sin(tilt), abs=1e-9)
    # the fingers still close along the yaw's direction turned about the same horizontal axis: tilt 0 is fingers_down
    np.testing.assert_allclose(approach_rotation(p, yaw, 0.0, SHOULDER), fingers_down(yaw), atol=0)
    assert fingers_down(yaw)[:, 2] == pytest.approx((0, 0, -1))


def _erd_arm(rel: str, **kwargs) -> Robot:
    erd = _erd()
    if erd is None or not (erd / rel).is_file():
        pytest.skip("example-robot-data is not installed (pip install '.[test]')")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        return Robot.from_urdf(erd / rel, tool="robotiq_2f85", **kwargs)


SO100 = ("so_arm_description/urdf/so100.urdf", {"tip": "gripper", "base_pose": (0, 0, 0, 0, 0, math.pi / 2)})
Z1 = ("z1_description/urdf/z1.urdf", {"tip": "link06"})


@pytest.mark.parametrize("rel, kwargs", [SO100, Z1, ("kinova_description/robots/kinova.urdf", {})], ids=["so100", "z1", "kinova"])
def test_the_tool_stands_out_of_the_wrist(rel, kwargs):
    robot = _erd_arm(rel, **kwargs)
    # the TCP is farther from the joint before the last (the wrist's bend) than the flange is, by most of the tool
    pin.forwardKinematics(robot.model, robot.data, robot.home_q)
    pin.updateFramePlacements(robot.model, robot.data)
    bend = robot.data.oMi[robot.model.njoints - 2].translation
    tip = robot.forward(robot.home_q)[robot.frame_names.index(robot.tip_frame)][:3, 3]
    tcp = robot.tcp_pose(robot.home_q)[:3, 3]
    assert np.linalg.norm(tcp - bend) > np.linalg.norm(tip - bend) + 0.1


def test_a_rep199_tool0_needs_no_turn():
    from robocritics.robot import urdf as U
    from robocritics.robot.vendor import flange_mount_rpy

    erd = _erd()
    if erd is None:
        pytest.skip("example-robot-data is not installed")
    doc = U.read_urdf(erd / "ur_description/urdf/ur5_robot.urdf")
    joints, tip = U.chain(U.kinematic_tree(doc), "tool0")
    assert flange_mount_rpy(doc, joints) is None
    doc = U.read_urdf(erd / "z1_description/urdf/z1.urdf")
    joints, _ = U.chain(U.kinematic_tree(doc), "link06")
    assert flange_mount_rpy(doc, joints) == pytest.approx((0.0, math.pi / 2, 0.0))  # its flange faces x


def test_inferred_tilts_are_the_ladder_from_the_least_that_reaches_the_probes():
    robot = _erd_arm(*Z1[:1], **Z1[1])
    tilts = infer_tilts(robot)
    assert sorted(tilts) == sorted(TILT_LADDER_RAD)
    k = TILT_LADDER_RAD.index(tilts[0])
    assert tilts == TILT_LADDER_RAD[k:] + TILT_LADDER_RAD[:k][::-1]
    assert robot.approach_tilts_rad == tilts


@pytest.mark.parametrize("turn_deg", [-8.0, 0.0, 8.0])
def test_pointing_ik_with_a_cone_hits_the_cone_angle(turn_deg):
    robot = _erd_arm(*SO100[:1], **SO100[1])
    home = robot.tcp_pose(robot.home_q)
    target = home[:3, 3] + np.array([0.01, 0.0, -0.01])
    cone_deg = math.degrees(math.acos(-home[2, 2])) + turn_deg  # near the home's own lean: reachable
    q = pointing_ik(robot.model, robot.data, robot._tcp_frame_id, target, (0, 0, -1), robot.home_q, robot.lower,
                    robot.upper, cone_rad=math.radians(cone_deg))
    assert robot.in_limits(q)
    # Pinocchio's own FK, fresh data: the position and the angle between the finger axis and straight down
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    pose = data.oMf[robot._tcp_frame_id]
    np.testing.assert_allclose(pose.translation, target, atol=1e-6)
    assert math.degrees(math.acos(-pose.rotation[2, 2])) == pytest.approx(cone_deg, abs=1e-4)


@pytest.mark.parametrize("rel, kwargs", [SO100, Z1], ids=["so100", "z1"])
def test_a_pick_and_place_through_the_cli_on_a_tilting_arm(tmp_path, capsys, rel, kwargs):
    from robocritics import cli

    robot = _erd_arm(rel, **kwargs)
    program = tmp_path / "pick.py"
    program.write_text(_PICK)
    scene = _pick_scene(tmp_path / "scene.json", robot.reach_m)
    argv = ["check", str(program), "--scene", str(scene), "--robot", str(_erd() / rel), "--tool", "robotiq_2f85",
            "--tip", kwargs["tip"], "--json", "--goal", "apple in box"]
    if "base_pose" in kwargs:
        argv += ["--base-pose", ",".join(repr(float(v)) for v in kwargs["base_pose"])]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        status = cli.main(argv)
    report = json.loads(capsys.readouterr().out)
    errors = [(v["critic"], v["message"]) for v in report["verdicts"] if v["flag"] == "ERROR"]
    assert status == 0 and not errors, errors
    assert {v["critic"]: v for v in report["verdicts"]}["task_outcome"]["flag"] == "OK"
