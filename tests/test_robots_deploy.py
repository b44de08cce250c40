"""Deploying the e-series arms: each streams to a loopback controller of its model; the gate's arm-model rule.

Real parts: the loopback UR controller (``robocritics.testing.ursim``, stepped clock on
127.0.0.1) and the real RTDE/dashboard clients. The arm-model rule is the gate's
:func:`check_model` on the dashboard's ``get robot model`` answer.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

import pytest

import robocritics as rc
from robocritics.critic import BUILTIN_CRITICS
from robocritics.deploy import URArm
from robocritics.deploy.dashboard import DashboardClient
from robocritics.deploy.gate import DeployRefused, check_model
from robocritics.errors import DeployError
from robocritics.robot.model import Robot
from robocritics.testing.ursim import URSim
from test_robots import scaled_sorting
from ur_support import controller_process, stepped

SHORT_PROGRAM = """
lib.set_speed(0.3)  # a fraction of each arm's joint speeds: the UR10e's TCP is 2.6x the UR3e's
move_above(red_apple_1, 0.12)
move_above(green_apple, 0.12)
"""
DASHBOARD_ANSWER = {"ur3e": "UR3", "ur5e": "UR5", "ur10e": "UR10", "ur16e": "UR16"}


@pytest.mark.parametrize("name", list(DASHBOARD_ANSWER))
def test_the_loopback_controller_answers_its_model(name):
    with URSim(**stepped(model=name)) as sim:
        with DashboardClient("127.0.0.1", sim.dashboard_port, timeout_s=1.0) as dash:
            assert dash.command("get robot model").strip() == DASHBOARD_ANSWER[name]
        robot = Robot.ur(name)
        assert sim.snapshot().q == pytest.approx(tuple(robot.home_q), abs=1e-12)
        assert sim.speed_limits == pytest.approx(tuple(robot.velocity_limits))


def test_the_controller_process_takes_a_model():
    with controller_process("--model", "ur16e") as ctl:
        with DashboardClient("127.0.0.1", ctl.dashboard_port, timeout_s=2.0) as dash:
            assert dash.command("get robot model").strip() == "UR16"


def test_the_loopback_controller_refuses_an_unknown_model():
    with pytest.raises(DeployError, match="URSim model must be one of ur3e, ur5e, ur10e, ur16e, got 'ur7e'"):
        URSim(**stepped(model="ur7e"))


@pytest.mark.parametrize("name", ["ur5e", "ur10e", "ur16e"])
def test_each_arm_deploys_to_a_controller_of_its_model(name):
    robot = Robot.ur(name)
    execution = rc.simulate(SHORT_PROGRAM, scaled_sorting(robot), robot=robot)
    report = rc.critique(execution, critics=BUILTIN_CRITICS)
    assert not report.has_errors, report.summary()
    traj = execution.trajectory
    assert traj.robot_name == name
    with URSim(**stepped(model=name, idle_after_s=0.05)) as sim:
        with URArm("127.0.0.1", rtde_port=sim.rtde_port, dashboard_port=sim.dashboard_port,
                   secondary_port=sim.secondary_port, timeout_s=1.0) as arm:
            result = arm.deploy(execution, report)
        snap = sim.snapshot()
    assert max(abs(a - b) for a, b in zip(snap.q, traj.q[-1])) < 1e-3
    assert result.final_error_rad < 1e-3


def test_deploy_refuses_a_controller_of_another_arm_before_anything_moves():
    robot = Robot.ur3e()
    execution = rc.simulate(SHORT_PROGRAM, rc.Scene.builtin("sorting"), robot=robot)
    report = rc.critique(execution, critics=BUILTIN_CRITICS)
    assert not report.has_errors, report.summary()
    # a UR10e controller: whatever else the gate finds, the model rule names both arms
    with URSim(**stepped(model="ur10e", idle_after_s=0.05)) as sim:
        before = sim.snapshot().q
        with URArm("127.0.0.1", rtde_port=sim.rtde_port, dashboard_port=sim.dashboard_port,
                   secondary_port=sim.secondary_port, timeout_s=1.0) as arm:
            with pytest.raises(DeployRefused) as refused:
                arm.deploy(execution, report)
        snap = sim.snapshot()
    assert "arm_model" in refused.value.causes
    assert "ur3e" in str(refused.value) and "'UR10'" in str(refused.value)
    assert list(snap.q) == list(before)  # nothing moved


@pytest.fixture(scope="module")
def ur10e_trajectory():
    robot = Robot.ur10e()
    return rc.simulate(SHORT_PROGRAM, scaled_sorting(robot), robot=robot).trajectory


def test_the_model_rule_passes_for_the_arm_it_was_planned_for(ur10e_trajectory):
    assert check_model(ur10e_trajectory, "UR10") == []
    assert check_model(ur10e_trajectory, " ur10\n") == []  # as the dashboard line arrives


def test_the_model_rule_refuses_another_arm_naming_both(ur10e_trajectory):
    [(cause, text)] = check_model(ur10e_trajectory, "UR5")
    assert cause == "arm_model"
    assert "planned for a ur10e but the controller reports 'UR5'" in text
    assert "robot=Robot.ur5e()" in text
    [(_, text)] = check_model(ur10e_trajectory, "UR20")
    assert "reports 'UR20'" in text and "no bundled arm is this one" in text


def test_the_model_rule_refuses_when_the_dashboard_cannot_say(ur10e_trajectory):
    [(cause, text)] = check_model(ur10e_trajectory, None, dashboard_error="connection reset")
    assert cause == "arm_model" and "connection reset" in text


def test_the_model_rule_keys_on_kinematics_not_names(ur10e_trajectory):
    data = ur10e_trajectory.to_dict()
    # a name is only a label: the UR10e's motion called "panda" is still the UR10e's
    assert check_model(rc.Trajectory.from_dict({**data, "robot_name": "panda"}), "UR10") == []
    # the Panda's kinematics are no UR's, whatever the trajectory is called
    foreign = rc.Trajectory.from_dict({**data, "kinematic_hash": rc.Robot.panda().kinematic_hash})
    [(cause, text)] = check_model(foreign, "UR10")
    assert cause == "arm_model" and "none of the UR arms deploy knows" in text
    # a trajectory that does not say what it was planned for fails closed
    [(cause, text)] = check_model(rc.Trajectory.from_dict({**data, "kinematic_hash": ""}), "UR10")
    assert cause == "arm_model" and "no kinematic_hash" in text


def test_a_ros_convention_urdf_that_calls_itself_ur3e_is_refused(tmp_path):
    from robocritics.robot.model import Robot

    text = (Path(rc.__file__).parent / "robot" / "models" / "ur3e.urdf").read_text()
    old = '<joint name="shoulder_pan_joint" type="revolute">\n    <parent link="base_link"/>\n    <child link="shoulder_link"/>\n    <origin xyz="0 0 0" rpy="0 0 0"/>'
    assert old in text
    path = tmp_path / "ur3e_ros.urdf"
    path.write_text(text.replace(old, old.replace('rpy="0 0 0"', f'rpy="0 0 {math.pi}"')))
    ros = Robot.from_urdf(path, name="ur3e")
    ur3e = Robot.ur3e()
    q = np.array([0.0, -1.2, 1.1, -0.7, 0.9, 0.4])
    # the same joints put the TCP on the other side of the base
    np.testing.assert_allclose(ros.tcp_pose(q)[:2, 3], -ur3e.tcp_pose(q)[:2, 3], atol=1e-9)
    assert ros.name == "ur3e" and ros.kinematic_hash != ur3e.kinematic_hash
    # the bundled file loaded as a URDF is the same chain: same hash
    assert Robot.from_urdf(Path(rc.__file__).parent / "robot" / "models" / "ur3e.urdf").kinematic_hash == ur3e.kinematic_hash
