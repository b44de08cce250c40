"""The UR e-series family (Robot.ur3e/ur5e/ur10e/ur16e) and the URDF contract (docs/robots.md).

The DH tables, speed limits and reaches below are typed here from UR's published
numbers, independently of robocritics/robot/arms.py, so a typo there fails here.
"""

from __future__ import annotations

import importlib.util
import math
import re
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from robocritics import critique, simulate
from robocritics.errors import RobotModelError
from robocritics.robot.arms import ARMS
from robocritics.robot.model import Robot
from robocritics.scene import Scene, Workspace
from robocritics.robot.model import default_workspace

ROOT = Path(__file__).resolve().parents[1]
MODELS = resources.files("robocritics.robot") / "models"

# UR's e-series DH tables: d1, a2, a3, d4, d5, d6 [m] (alpha = pi/2, 0, 0, pi/2, -pi/2, 0)
UR_DH = {
    "ur3e": (0.15185, -0.24355, -0.2132, 0.13105, 0.08535, 0.0921),
    "ur5e": (0.1625, -0.425, -0.3922, 0.1333, 0.0997, 0.0996),
    "ur10e": (0.1807, -0.6127, -0.57155, 0.17415, 0.11985, 0.11655),
    "ur16e": (0.1807, -0.4784, -0.36, 0.17415, 0.11985, 0.11655),
}
# joint speed limits [deg/s], base first (UR technical specifications)
UR_SPEED_DEG_S = {
    "ur3e": (180, 180, 180, 360, 360, 360),
    "ur5e": (180, 180, 180, 180, 180, 180),
    "ur10e": (120, 120, 180, 180, 180, 180),
    "ur16e": (120, 120, 180, 180, 180, 180),
}
UR_REACH_M = {"ur3e": 0.5, "ur5e": 0.85, "ur10e": 1.3, "ur16e": 0.9}
TCP_FROM_FLANGE_M = 0.15  # the Robotiq 2F-85-sized gripper's fingertip centre
ARM_NAMES = tuple(UR_DH)


def dh_flange(name: str, q: np.ndarray) -> np.ndarray:
    """T_06(q) by the standard DH product A_i = Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i)."""
    d1, a2, a3, d4, d5, d6 = UR_DH[name]
    d = (d1, 0, 0, d4, d5, d6)
    a = (0, a2, a3, 0, 0, 0)
    alpha = (math.pi / 2, 0, 0, math.pi / 2, -math.pi / 2, 0)
    T = np.eye(4)
    for qi, di, ai, al in zip(q, d, a, alpha):
        ct, st, ca, sa = math.cos(qi), math.sin(qi), math.cos(al), math.sin(al)
        T = T @ np.array([[ct, -st * ca, st * sa, ai * ct], [st, ct * ca, -ct * sa, ai * st], [0, sa, ca, di], [0, 0, 0, 1]])
    return T


@pytest.fixture(scope="module", params=ARM_NAMES)
def arm(request) -> Robot:
    return Robot.ur(request.param)


def test_each_arm_has_its_own_constructor():
    for name in ARM_NAMES:
        robot = getattr(Robot, name)()
        assert robot.name == name
        assert robot.n == 6
        assert robot.tcp_frame == "tcp"
    assert Robot.ur5e() is not Robot.ur5e()  # independent copies


def test_unknown_arm_names_the_bundled_ones():
    with pytest.raises(RobotModelError, match=r"no bundled UR arm .ur7e.*ur3e, ur5e, ur10e, ur16e \(and Robot.panda\(\)\)"):
        Robot.ur("ur7e")


def test_forward_kinematics_follow_the_published_dh_table(arm):
    rng = np.random.default_rng(7)
    q = rng.uniform(-math.pi, math.pi, size=(20, 6))
    frames = arm.forward(q)
    flange = frames[:, arm.frame_names.index("tool0")]
    tcp = frames[:, arm.tcp_index]
    for k in range(len(q)):
        expected = dh_flange(arm.name, q[k])
        np.testing.assert_allclose(flange[k], expected, atol=1e-9)
        # the TCP is 0.15 m along the flange's z axis, fingers along tcp +z
        np.testing.assert_allclose(tcp[k][:3, 3], expected[:3, 3] + TCP_FROM_FLANGE_M * expected[:3, 2], atol=1e-9)
        np.testing.assert_allclose(tcp[k][:3, 2], expected[:3, 2], atol=1e-9)


def test_speed_limits_and_reach_are_the_published_ones(arm):
    np.testing.assert_allclose(np.degrees(arm.velocity_limits), UR_SPEED_DEG_S[arm.name], rtol=1e-9)
    np.testing.assert_allclose(arm.limits.velocity_rad_s, np.radians(UR_SPEED_DEG_S[arm.name]), rtol=1e-9)
    assert arm.reach_m == UR_REACH_M[arm.name]
    # the elbow is limited to +-180 deg by its cable, the others turn +-360 deg
    np.testing.assert_allclose(np.degrees(arm.upper), (360, 360, 180, 360, 360, 360))
    np.testing.assert_allclose(arm.lower, -arm.upper)


def test_link_masses_and_capsules_grow_with_the_arm():
    masses = {n: sum(ARMS[n].link_masses_kg) for n in ARM_NAMES}
    assert masses["ur3e"] < masses["ur5e"] < masses["ur16e"] < masses["ur10e"] + 1.0
    radii = {n: Robot.ur(n).capsule_radii for n in ARM_NAMES}
    upper_arm = {n: dict(zip(Robot.ur(n).capsule_names, radii[n]))["upper_arm_link"] for n in ARM_NAMES}
    assert upper_arm["ur3e"] < upper_arm["ur5e"] < upper_arm["ur10e"] == upper_arm["ur16e"]
    # every arm carries the same gripper
    for n in ARM_NAMES:
        robot = Robot.ur(n)
        assert robot.max_opening_m == 0.085
        assert robot.finger_links == ("left_finger", "right_finger")


def test_ik_round_trips(arm):
    rng = np.random.default_rng(3)
    checked = 0
    while checked < 25:
        q = rng.uniform(-math.pi, math.pi, size=6)
        q[2] = rng.uniform(-2.6, 2.6)  # away from the stretched-out elbow singularity
        q[4] = rng.uniform(0.3, 2.8) * rng.choice((-1, 1))  # away from the wrist singularity
        pose = arm.tcp_pose(q)
        solution = arm.ik(pose[:3, 3], pose[:3, :3], seed=q + 0.05)
        np.testing.assert_allclose(arm.tcp_pose(solution), pose, atol=1e-8)
        checked += 1


def test_home_is_in_front_fingers_down_scaled_by_reach(arm):
    tcp = arm.tcp_pose(arm.home_q)
    assert tcp[0, 3] > 0.2 and abs(tcp[1, 3]) < 1e-9 and tcp[2, 3] > 0.2
    np.testing.assert_allclose(tcp[:3, 2], (0, 0, -1), atol=1e-9)
    assert tcp[0, 3] < arm.reach_m


def test_the_bundled_urdfs_are_what_the_generator_writes():
    spec = importlib.util.spec_from_file_location("make_ur3e_urdf", ROOT / "tools" / "make_ur3e_urdf.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)  # defines urdf_text; writes nothing unless run as a script
    for name in ARM_NAMES:
        assert tool.urdf_text(name) == (MODELS / f"{name}.urdf").read_text(), name
    assert tool.panda_urdf_text() == (MODELS / "panda.urdf").read_text()


# --- scenes follow the robot -------------------------------------------------------------


def test_the_ur3e_workspace_is_the_default_workspace():
    assert Robot.ur3e().workspace == default_workspace()
    scene = Scene.builtin("sorting")
    assert scene.workspace is None  # a scene knows no arm: it follows its robot
    assert Robot.ur3e().scene_for(scene).workspace == default_workspace()


def test_a_larger_arm_brings_its_reach_sphere_unless_the_scene_gives_one():
    ur10e = Robot.ur10e()
    scene = ur10e.scene_for(Scene.builtin("sorting"))
    assert scene.workspace.radius_m == 1.3
    assert scene.workspace.center == (0.0, 0.0, 0.1807)
    own = Scene.builtin("sorting").model_copy(update={"workspace": Workspace(center=(0.0, 0.0, 0.1807), radius_m=0.7)})
    own = Scene.model_validate(own.model_dump())  # as a scene file that gives a workspace
    assert ur10e.scene_for(own).workspace.radius_m == 0.7


def scaled_sorting(robot: Robot) -> Scene:
    """The sorting scene with every table position scaled by the arm's reach over the UR3e's."""
    scene = Scene.builtin("sorting")
    k = robot.reach_m / UR_REACH_M["ur3e"]

    def moved(entity):
        x, y, z = entity.position
        return entity.model_copy(update={"position": (x * k, y * k, z)})

    table = scene.table.model_copy(update={"size": tuple(v * k for v in scene.table.size),
                                           "center_xy": tuple(v * k for v in scene.table.center_xy)})
    return robot.scene_for(scene.model_copy(update={
        "objects": [moved(o) for o in scene.objects],
        "containers": [moved(c) for c in scene.containers],
        "table": table,
    }))


def ends_in(position, box) -> bool:
    (x, y, z), (bx, by, bz) = position, box.position
    sx, sy, sz = box.size
    return abs(x - bx) < sx / 2 and abs(y - by) < sy / 2 and z < bz + sz / 2


CAREFUL = (ROOT / "examples" / "programs" / "sorting_careful.py").read_text()


def test_a_scaled_pick_and_place_puts_every_apple_in_its_box(arm):
    scene = scaled_sorting(arm)
    execution = simulate(CAREFUL, scene, robot=arm)
    boxes = {c.id: c for c in scene.containers}
    final = {o.id: o.position for o in execution.final_scene.objects}
    for apple in scene.objects:
        box = boxes["brown_box"] if apple.attributes["ripeness"] == "ripe" else boxes["white_box"]
        assert ends_in(final[apple.id], box), (arm.name, apple.id, final[apple.id])
    report = critique(execution)
    assert report.score is not None and report.score >= 6, (arm.name, report.score)


# --- the URDF contract -----------------------------------------------------------------


def variant(tmp_path: Path, edit, name: str = "variant.urdf", arm: str = "ur5e") -> Path:
    path = tmp_path / name
    path.write_text(edit((MODELS / f"{arm}.urdf").read_text()))
    return path


def test_a_missing_mesh_is_refused_naming_the_link_file_and_line(tmp_path):
    def meshed(text):
        return re.sub(
            r'<geometry><cylinder radius="0.057" length="[^"]+"/></geometry>',
            '<geometry><mesh filename="package://ur_description/meshes/ur5e/collision/upperarm.stl"/></geometry>',
            text,
        )

    path = variant(tmp_path, meshed)
    assert "upperarm.stl" in path.read_text()
    with pytest.raises(RobotModelError, match=r"line \d+: <mesh filename='package://.*upperarm\.stl'> of link 'upper_arm_link': no such file"):
        Robot.from_urdf(path)


def test_sphere_collisions_are_capsules_of_zero_length(tmp_path):
    def sphered(text):
        return re.sub(r'<cylinder radius="0.04" length="[^"]+"/>', '<sphere radius="0.05"/>', text, count=1)

    robot = Robot.from_urdf(variant(tmp_path, sphered))
    body = robot.capsules[robot.capsule_names.index("gripper_body")]
    assert body.radius_m == 0.05 and body.p0 == body.p1


def test_continuous_joints_are_revolute_one_turn_each_way(tmp_path):
    def continuous(text):
        return text.replace('<joint name="wrist_3_joint" type="revolute">', '<joint name="wrist_3_joint" type="continuous">')

    path = variant(tmp_path, continuous)
    assert 'type="continuous"' in path.read_text()
    robot = Robot.from_urdf(path, dh=ARMS["ur5e"].dh)
    assert robot.n == 6
    assert robot.upper[5] == pytest.approx(2 * math.pi) and robot.lower[5] == pytest.approx(-2 * math.pi)
    pose = robot.tcp_pose(Robot.ur5e().home_q)
    np.testing.assert_allclose(pose, Robot.ur5e().tcp_pose(Robot.ur5e().home_q), atol=1e-12)


def test_dh_matching_the_urdf_is_accepted(tmp_path):
    robot = Robot.from_urdf(variant(tmp_path, lambda t: t), dh=ARMS["ur5e"].dh)
    assert robot.dh is ARMS["ur5e"].dh


def test_dh_mismatch_is_refused_ros_base_convention(tmp_path):
    # ROS's UR description turns the base 180 deg about z against UR's DH base frame
    def ros_base(text):
        old = '<joint name="shoulder_pan_joint" type="revolute">\n    <parent link="base_link"/>\n    <child link="shoulder_link"/>\n    <origin xyz="0 0 0" rpy="0 0 0"/>'
        assert old in text
        return text.replace(old, old.replace('rpy="0 0 0"', f'rpy="0 0 {math.pi}"'))

    path = variant(tmp_path, ros_base)
    with pytest.raises(RobotModelError, match=r"does not follow dh='ur5e'.*0\.\d+ m.*base convention"):
        Robot.from_urdf(path, dh=ARMS["ur5e"].dh)
    # without dh= it loads (numeric IK), and its flange really is elsewhere
    robot = Robot.from_urdf(path)
    assert np.linalg.norm(robot.tcp_pose(np.zeros(6))[:3, 3] - Robot.ur5e().tcp_pose(np.zeros(6))[:3, 3]) > 0.5


def test_dh_of_another_arm_is_refused(tmp_path):
    with pytest.raises(RobotModelError, match="does not follow dh='ur10e'"):
        Robot.from_urdf(variant(tmp_path, lambda t: t), dh=ARMS["ur10e"].dh)


def test_dh_needs_a_flange_frame(tmp_path):
    def no_tool0(text):
        return text.replace('"tool0"', '"flange"')

    with pytest.raises(RobotModelError, match=r"no link 'tool0' for the flange that dh= describes; links are .*flange"):
        Robot.from_urdf(variant(tmp_path, no_tool0), dh=ARMS["ur5e"].dh)


def test_a_missing_tcp_frame_is_named(tmp_path):
    with pytest.raises(RobotModelError, match=r"no link 'fingertip' for the TCP; links are base_link, .*tcp"):
        Robot.from_urdf(variant(tmp_path, lambda t: t), tcp_frame="fingertip")


def test_the_tcp_frame_is_recorded_in_the_robot(tmp_path):
    def renamed(text):
        return text.replace('"tcp"', '"fingertip"').replace('tcp="tcp"', 'tcp="fingertip"')

    robot = Robot.from_urdf(variant(tmp_path, renamed), tcp_frame="fingertip")
    assert robot.tcp_frame == "fingertip"
    assert robot.frame_names[robot.tcp_index] == "fingertip"


def test_a_generic_urdf_gets_a_reach_from_its_chain(tmp_path):
    robot = Robot.from_urdf(variant(tmp_path, lambda t: t))
    # stretched out: upper arm + forearm + wrist offsets + gripper; more than the published 0.85 m reach
    assert 0.85 < robot.reach_m < 1.4
    np.testing.assert_allclose(robot.shoulder_m, (0, 0, 0.1625), atol=1e-12)


# --- the Franka Emika Panda ------------------------------------------------------------------

# Franka's published modified-DH table (Craig): a, d [m], alpha [rad]; T_i = Rx(alpha) Tx(a) Rz(q) Tz(d)
PANDA_MDH = [
    (0.0, 0.333, 0.0),
    (0.0, 0.0, -math.pi / 2),
    (0.0, 0.316, math.pi / 2),
    (0.0825, 0.0, math.pi / 2),
    (-0.0825, 0.384, -math.pi / 2),
    (0.0, 0.0, math.pi / 2),
    (0.088, 0.0, math.pi / 2),
]
PANDA_FLANGE_D_M = 0.107
PANDA_Q_MIN = (-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973)
PANDA_Q_MAX = (2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973)
PANDA_DQ_MAX = (2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61)
HAND_TCP_M = 0.1034


def panda_flange(q) -> np.ndarray:
    T = np.eye(4)
    for qi, (a, d, alpha) in zip(q, PANDA_MDH):
        ca, sa, cq, sq = math.cos(alpha), math.sin(alpha), math.cos(qi), math.sin(qi)
        Rx = np.array([[1, 0, 0, 0], [0, ca, -sa, 0], [0, sa, ca, 0], [0, 0, 0, 1]])
        Tx = np.eye(4)
        Tx[0, 3] = a
        Rz = np.array([[cq, -sq, 0, 0], [sq, cq, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
        Tz = np.eye(4)
        Tz[2, 3] = d
        T = T @ Rx @ Tx @ Rz @ Tz
    flange = np.eye(4)
    flange[2, 3] = PANDA_FLANGE_D_M
    return T @ flange


@pytest.fixture(scope="module")
def panda() -> Robot:
    return Robot.panda()


def test_panda_forward_kinematics_follow_franka_s_table(panda):
    rng = np.random.default_rng(11)
    q = rng.uniform(PANDA_Q_MIN, PANDA_Q_MAX, size=(20, 7))
    frames = panda.forward(q)
    for k in range(len(q)):
        flange = panda_flange(q[k])
        np.testing.assert_allclose(frames[k, panda.frame_names.index("link8")], flange, atol=1e-9)
        tcp = frames[k, panda.tcp_index]
        np.testing.assert_allclose(tcp[:3, 3], flange[:3, 3] + HAND_TCP_M * flange[:3, 2], atol=1e-9)
        # the hand is turned -45 deg about the flange z: its closing (y) axis is between the flange's x and y
        np.testing.assert_allclose(tcp[:3, 1], (flange[:3, 0] + flange[:3, 1]) / math.sqrt(2), atol=1e-9)


def test_panda_ready_pose_is_where_franka_says(panda):
    # Franka's "ready" posture puts the flange 0.307 m in front of the base, 0.59 m up, pointing down
    ready = (0, -math.pi / 4, 0, -3 * math.pi / 4, 0, math.pi / 2, math.pi / 4)
    np.testing.assert_allclose(panda_flange(ready)[:3, 3], (0.30689, 0, 0.59028), atol=1e-4)
    np.testing.assert_allclose(panda.tcp_pose(np.array(ready))[:3, 3], (0.30689, 0, 0.59028 - HAND_TCP_M), atol=1e-4)


def test_panda_limits_are_franka_s(panda):
    assert panda.n == 7
    np.testing.assert_allclose(panda.lower, PANDA_Q_MIN)
    np.testing.assert_allclose(panda.upper, PANDA_Q_MAX)
    np.testing.assert_allclose(panda.velocity_limits, PANDA_DQ_MAX)
    assert panda.reach_m == 0.855
    assert panda.max_opening_m == 0.08
    np.testing.assert_allclose(panda.workspace.center, (0, 0, 0.333))


def test_panda_ik_round_trips_near_the_seed(panda):
    rng = np.random.default_rng(5)
    for _ in range(15):
        q = np.clip(panda.home_q + rng.uniform(-0.6, 0.6, size=7), panda.lower + 0.05, panda.upper - 0.05)
        pose = panda.tcp_pose(q)
        solution = panda.ik(pose[:3, 3], pose[:3, :3], seed=np.clip(q + 0.05, panda.lower, panda.upper))
        np.testing.assert_allclose(panda.tcp_pose(solution), pose, atol=1e-7)
        assert panda.in_limits(solution)


def test_panda_home_is_in_front_fingers_down_elbow_up(panda):
    tcp = panda.tcp_pose(panda.home_q)
    np.testing.assert_allclose(tcp[:3, 3], (0.25 * 0.855 / 0.5, 0, 0.25 * 0.855 / 0.5), atol=1e-7)
    np.testing.assert_allclose(tcp[:3, 2], (0, 0, -1), atol=1e-7)
    elbow = panda.forward(panda.home_q)[panda.frame_names.index("link4")][:3, 3]
    assert elbow[2] > tcp[2, 3] + 0.1  # the elbow stands above the hand


def test_panda_scaled_pick_and_place_puts_every_apple_in_its_box(panda):
    scene = scaled_sorting(panda)
    execution = simulate(CAREFUL, scene, robot=panda)
    boxes = {c.id: c for c in scene.containers}
    final = {o.id: o.position for o in execution.final_scene.objects}
    for apple in scene.objects:
        box = boxes["brown_box"] if apple.attributes["ripeness"] == "ripe" else boxes["white_box"]
        assert ends_in(final[apple.id], box), (apple.id, final[apple.id])
    report = critique(execution)
    assert not report.has_errors, report.summary()
    naive = critique(simulate((ROOT / "examples" / "programs" / "sorting_naive.py").read_text(), scene, robot=panda))
    assert naive.score < report.score


def test_panda_is_not_deployable_to_a_ur_controller(panda):
    from robocritics.deploy.gate import check_model

    trajectory = simulate("move_above(red_apple_1, 0.12)\n", scaled_sorting(panda), robot=panda).trajectory
    [(cause, text)] = check_model(trajectory, "UR5")
    assert cause == "arm_model" and "'panda'" in text


def test_simulate_judges_a_scene_without_its_own_workspace_by_the_robots_reach():
    big = Robot.ur10e()
    plain = Scene()  # no workspace given
    execution = simulate("move_to(0.5, 0.2, 0.4)\n", plain, robot=big)
    assert execution.scene.workspace == big.workspace
    assert big.workspace.radius_m > Robot.ur3e().workspace.radius_m
    # a scene that states its workspace keeps it
    own = Scene(workspace={"center": (0, 0, 0.2), "radius_m": 2.0})
    assert simulate("move_to(0.5, 0.2, 0.4)\n", own, robot=big).scene.workspace.radius_m == 2.0


def test_a_scene_made_for_one_arm_is_refused_on_another_naming_both():
    scene = Scene(robot="ur10e")
    assert simulate("move_to(0.5, 0.2, 0.4)\n", scene, robot=Robot.ur10e()).scene.robot == "ur10e"
    with pytest.raises(Exception) as refused:
        simulate("move_to(0.3, 0.1, 0.3)\n", scene)  # the default UR3e
    assert type(refused.value).__name__ == "SceneError"
    assert "made for the ur10e, not the ur3e" in str(refused.value) and "robot" in str(refused.value)
    # a scene that names no robot works on any
    assert Scene().robot == "" and Scene.builtin("sorting").robot == ""
