"""Vendor URDFs as shipped (from pip packages, found inside the installed packages, never copied here), fitted
capsules against the meshes, and hostile URDFs ending in typed errors (issues 22 and 24)."""

from __future__ import annotations

import importlib.util
import math
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings, strategies as st

from robocritics import Robot
from robocritics.errors import RobotModelError
from robocritics.robot import fit
from robocritics.robot.tools import TOOLS


def _site(package: str) -> Path | None:
    spec = importlib.util.find_spec(package)
    return Path(spec.origin).parent if spec and spec.origin else None


def _erd() -> Path | None:
    import sysconfig

    robots = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
    return robots if robots.is_dir() else None


def _arms():
    pb, rtb, airo, erd = _site("pybullet_data"), _site("rtbdata"), _site("airo_models"), _erd()
    rows = [
        ("pybullet iiwa", pb, "kuka_iiwa/model.urdf", {}),
        ("pybullet xarm6", pb, "xarm/xarm6_robot.urdf", {}),
        ("pybullet panda", pb, "franka_panda/panda.urdf", {"tip": "panda_link8", "tool": "franka_hand"}),
        ("erd ur5", erd, "ur_description/urdf/ur5_robot.urdf", {}),
        ("erd ur10", erd, "ur_description/urdf/ur10_robot.urdf", {}),
        ("erd xarm7", erd, "xarm_description/urdf/xarm7.urdf", {}),
        ("erd kinova", erd, "kinova_description/robots/kinova.urdf", {}),
        ("erd panda", erd, "panda_description/urdf/panda.urdf", {"tip": "panda_link8", "tool": "franka_hand"}),
        ("rtb kr16", rtb, "xacro/kuka_description/kuka_kr16/urdf/kr16_2.urdf", {}),
        ("airo ur3e", airo, "arms/ur3e/ur3e.urdf", {}),
        ("airo ur5e", airo, "arms/ur5e/ur5e.urdf", {}),
    ]
    return [pytest.param(base / rel if base else None, kw, id=name) for name, base, rel, kw in rows]


def _raw_tip_pose(path: Path, joint_names, q, tip: str, *, wrist: bool = False):
    """The tip's pose from Pinocchio on the raw vendor file (every other joint at zero); with ``wrist``, also the
    position of the last moving joint before it (m, world)."""
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    x = pin.neutral(model)
    for name, value in zip(joint_names, q):
        j = model.getJointId(name)
        idx, nq = model.idx_qs[j], model.nqs[j]
        if nq == 1:
            x[idx] = value
        else:  # continuous: (cos, sin)
            x[idx : idx + 2] = (math.cos(value), math.sin(value))
    pin.framesForwardKinematics(model, data, x)
    frame = model.frames[model.getFrameId(tip, pin.FrameType.BODY)]
    pose = data.oMf[model.getFrameId(tip, pin.FrameType.BODY)].homogeneous
    return (pose, data.oMi[frame.parentJoint].translation.copy()) if wrist else pose


@pytest.mark.parametrize("path, kwargs", _arms())
def test_a_vendor_arm_loads_as_shipped_and_its_fk_is_pinocchios_on_the_raw_file(path, kwargs):
    if path is None or not path.is_file():
        pytest.skip("the package with this URDF is not installed (pip install '.[test]')")
    kwargs = {"tool": "robotiq_2f85", **kwargs}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        robot = Robot.from_urdf(path, **kwargs)
    assert robot.capsules and all(c.radius_m > 0 for c in robot.capsules)
    assert robot.in_limits(robot.home_q)
    assert robot.capsule_groups.count("gripper") == 3  # the tool's body and fingers, whatever the links are called
    rng = np.random.default_rng(1)
    tip = robot.frame_names.index(robot.tip_frame)
    for q in rng.uniform(robot.lower, robot.upper, size=(5, robot.n)):
        ours = robot.forward(q)[tip]
        np.testing.assert_allclose(ours, _raw_tip_pose(path, robot.joint_names, q, robot.tip_frame), atol=1e-12)
    # the TCP is the tool's, along one of the flange's axes and out of the wrist (the Kinova's and the Z1's
    # flanges face out along x, not z): farther from the last moving joint than the flange is
    pose = robot.forward(robot.home_q)
    offset = (np.linalg.inv(pose[tip]) @ pose[robot.tcp_index][:, 3])[:3]
    length = TOOLS[kwargs["tool"]].tcp_from_flange_m
    assert np.sort(np.abs(offset)) == pytest.approx((0, 0, length), abs=1e-12)
    raw_tip, wrist = _raw_tip_pose(path, robot.joint_names, robot.home_q, robot.tip_frame, wrist=True)
    tcp = pose[robot.tcp_index][:3, 3]
    assert np.linalg.norm(tcp - wrist) > np.linalg.norm(raw_tip[:3, 3] - wrist) + 0.5 * length
    # the reach is sampled, not the stretched chain: no farther than the chain, and the home is in front of it
    assert 0.2 < robot.reach_m < 3.0


# --- fitted capsules against the mesh -----------------------------------------------------------------


def _capsule_distance(p, c: fit.FittedCapsule) -> float:
    a, b = np.array(c.p0), np.array(c.p1)
    d = b - a
    t = 0.0 if not d.any() else float(np.clip((p - a) @ d / (d @ d), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * d))) - c.radius_m


def _mesh_distance(p, mesh: fit.Mesh) -> float:
    """Point-to-triangle distance, brute force over every triangle (Ericson's closest point, per triangle)."""
    best = math.inf
    for tri in mesh.vertices[mesh.triangles]:
        best = min(best, float(np.linalg.norm(p - _closest_on_triangle(p, *tri))))
    return best


def _closest_on_triangle(p, a, b, c):
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = ab @ ap, ac @ ap
    if d1 <= 0 and d2 <= 0:
        return a
    bp = p - b
    d3, d4 = ab @ bp, ac @ bp
    if d3 >= 0 and d4 <= d3:
        return b
    vc = d1 * d4 - d3 * d2
    if vc <= 0 and d1 >= 0 and d3 <= 0:
        return a + d1 / (d1 - d3) * ab
    cp = p - c
    d5, d6 = ab @ cp, ac @ cp
    if d6 >= 0 and d5 <= d6:
        return c
    vb = d5 * d2 - d1 * d6
    if vb <= 0 and d2 >= 0 and d6 <= 0:
        return a + d2 / (d2 - d6) * ac
    va = d3 * d6 - d5 * d4
    if va <= 0 and (d4 - d3) >= 0 and (d5 - d6) >= 0:
        return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b)
    denom = 1.0 / (va + vb + vc)
    return a + ab * (vb * denom) + ac * (vc * denom)


def _l_shaped_mesh() -> fit.Mesh:
    """A tube with a housing across it at one end (an upper arm), as boxes: 24 triangles."""
    tube = fit.box_mesh((0.08, 0.08, 0.4)).transformed(_translation(0, 0, 0.2))
    housing = fit.box_mesh((0.14, 0.2, 0.14))
    return fit.Mesh.union([tube, housing])


def _translation(x, y, z):
    pose = np.eye(4)
    pose[:3, 3] = (x, y, z)
    return pose


_MESH = _l_shaped_mesh()
_CAPSULES = fit.fit_capsules(_MESH)


def test_a_tube_with_a_housing_gets_more_than_one_capsule_and_a_thin_one_on_the_tube():
    assert len(_CAPSULES) >= 2
    assert min(c.radius_m for c in _CAPSULES) < 0.07  # the tube: half-diagonal 0.057 m, not the housing's 0.12 m


@settings(max_examples=60, deadline=None)
@given(st.tuples(*(st.floats(-0.5, 0.7) for _ in range(3))))
def test_fitted_capsules_enclose_the_mesh_within_their_slack(point):
    p = np.array(point)
    d_caps = min(_capsule_distance(p, c) for c in _CAPSULES)
    d_mesh = _mesh_distance(p, _MESH)
    # never farther than the mesh (no contact missed) ...
    assert d_caps <= d_mesh + 1e-9
    # ... and outside the capsules, at most the nearest capsule's slack nearer
    if d_caps > 0:
        nearest = min(_CAPSULES, key=lambda c: _capsule_distance(p, c))
        assert d_mesh - d_caps <= max(c.slack_m for c in _CAPSULES) + 1e-9
        assert nearest.slack_m > 0


@settings(max_examples=40, deadline=None)
@given(st.tuples(*(st.floats(-0.5, 0.7) for _ in range(3))))
def test_each_fitted_capsule_encloses_its_piece_of_the_mesh_within_its_own_slack(point):
    """Per capsule, against the piece it encloses (what the exact path measures near contact):
    d(p, piece) - slack <= d(p, capsule) <= d(p, piece); the pieces together are the mesh."""
    p = np.array(point)
    for c in _CAPSULES:
        d_piece, d_capsule = _mesh_distance(p, c.mesh), _capsule_distance(p, c)
        assert d_capsule <= d_piece + 1e-9
        if d_capsule > 0:
            assert d_piece - d_capsule <= c.slack_m + 1e-9
    assert min(_mesh_distance(p, c.mesh) for c in _CAPSULES) == pytest.approx(_mesh_distance(p, _MESH), abs=1e-12)


def test_every_piece_lies_inside_its_capsule():
    for c in _CAPSULES:
        assert max(_capsule_distance(v, c) for v in c.mesh.vertices) <= 1e-9


# --- hostile URDFs ------------------------------------------------------------------------------------

_ARM = """<?xml version="1.0"?>
<robot name="two" xmlns:drake="http://drake.mit.edu">
  <link name="base"><collision><geometry><cylinder radius="0.05" length="0.1"/></geometry></collision></link>
  <link name="upper"><collision><origin xyz="0.15 0 0" rpy="0 1.5707963 0"/><geometry><cylinder radius="{radius}" length="{length}"/></geometry></collision></link>
  <link name="tool0"/>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="{origin}" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="{lower}" upper="1" effort="1" velocity="{velocity}" drake:acceleration="3"/></joint>
  <joint name="flange" type="fixed"><parent link="upper"/><child link="tool0"/><origin xyz="0.3 0 0" rpy="0 1.5707963267948966 0"/></joint>
</robot>
"""


def _arm(tmp_path, **changes) -> Path:
    values = {"radius": "0.04", "length": "0.3", "origin": "0 0 0.1", "lower": "-1", "velocity": "2", **changes}
    path = tmp_path / "arm.urdf"
    path.write_text(_ARM.format(**values))
    return path


def test_a_well_formed_arm_with_a_foreign_namespace_loads(tmp_path):
    robot = Robot.from_urdf(_arm(tmp_path), tool="robotiq_2f85")
    assert robot.n == 1 and robot.tip_frame == "tool0"


@pytest.mark.parametrize("changes, message", [
    ({"lower": "-1e308"}, r"line 7: <limit lower='-1e308'> of joint 'shoulder': .* not a finite number"),
    ({"lower": "nan"}, r"line 7: <limit lower='nan'> of joint 'shoulder'"),
    ({"length": ""}, r"line 4: <cylinder length=''> of link 'upper': length needs 1 number"),
    ({"radius": "wide"}, r"line 4: <cylinder radius='wide'> of link 'upper': not a number"),
    ({"radius": "-0.04"}, r"line 4: <cylinder radius=\"-0.04\"> of link 'upper': radius must be positive"),
    ({"origin": "0 0.1"}, r"line 7: <origin xyz='0 0.1'> of joint 'shoulder': xyz needs 3 numbers, got 2"),
    ({"velocity": "0"}, r"line 7: <limit velocity=\"0\"> of joint 'shoulder': velocity must be positive"),
])
def test_bad_numbers_are_typed_errors_naming_element_joint_and_line(tmp_path, changes, message):
    with pytest.raises(RobotModelError, match=message):
        Robot.from_urdf(_arm(tmp_path, **changes))


def test_a_cylinder_without_length_names_link_and_line(tmp_path):
    path = _arm(tmp_path)
    path.write_text(path.read_text().replace(' length="0.3"', ""))
    with pytest.raises(RobotModelError, match=r"line 4: <cylinder> of link 'upper' needs length="):
        Robot.from_urdf(path)


def test_only_a_base_and_a_tcp_is_not_an_arm(tmp_path):
    path = tmp_path / "still.urdf"
    path.write_text('<robot name="s"><link name="base"/><link name="tcp"/>'
                    '<joint name="j" type="fixed"><parent link="base"/><child link="tcp"/></joint></robot>')
    with pytest.raises(RobotModelError, match="no moving joint"):
        Robot.from_urdf(path)


@pytest.mark.parametrize("doctype", [
    '<!DOCTYPE r [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">]>',
    '<!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]>',
    '<!DOCTYPE robot SYSTEM "http://127.0.0.1:9/robot.dtd">',
])
def test_entities_and_doctypes_are_refused_before_expansion(tmp_path, doctype):
    path = tmp_path / "bomb.urdf"
    path.write_text(f'<?xml version="1.0"?>\n{doctype}\n<robot name="r"><link name="a"/></robot>')
    with pytest.raises(RobotModelError, match="DOCTYPE or ENTITY"):
        Robot.from_urdf(path)


def test_a_huge_file_is_refused_before_it_is_read(tmp_path):
    path = tmp_path / "huge.urdf"
    with open(path, "wb") as f:
        f.truncate(50_000_000)
    with pytest.raises(RobotModelError, match=r"50,000,000 bytes is more than"):
        Robot.from_urdf(path)


def test_an_800_joint_urdf_is_a_typed_error_not_a_memory_error(tmp_path):
    links = "".join(f'<link name="l{i}"/>' for i in range(801))
    joints = "".join(f'<joint name="j{i}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/><axis xyz="0 0 1"/>'
                     f'<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>' for i in range(800))
    path = tmp_path / "long.urdf"
    path.write_text(f'<robot name="long">{links}{joints}</robot>')
    with pytest.raises(RobotModelError, match=r"801 <link> elements; robocritics reads at most 256"):
        Robot.from_urdf(path)


def test_a_cycle_and_a_second_parent_are_named(tmp_path):
    path = _arm(tmp_path)
    text = path.read_text().replace("</robot>", '<joint name="back" type="fixed"><parent link="tool0"/><child link="base"/></joint></robot>')
    path.write_text(text)
    with pytest.raises(RobotModelError, match="no root link: the joints form a cycle"):
        Robot.from_urdf(path)
    text = _ARM.format(radius="0.04", length="0.3", origin="0 0 0.1", lower="-1", velocity="2").replace(
        "</robot>", '<joint name="again" type="fixed"><parent link="base"/><child link="tool0"/></joint></robot>')
    path.write_text(text)
    with pytest.raises(RobotModelError, match=r"line \d+: joint 'again': link 'tool0' already has a parent \(joint 'flange'"):
        Robot.from_urdf(path)


def test_a_branching_chain_is_refused_unless_tip_names_the_branch(tmp_path):
    path = _arm(tmp_path)
    finger = ('<link name="finger"/><joint name="finger_joint" type="prismatic"><parent link="upper"/><child link="finger"/>'
              '<axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="1" velocity="0.1"/></joint>'
              '<link name="finger2"/><joint name="finger2_joint" type="prismatic"><parent link="upper"/><child link="finger2"/>'
              '<axis xyz="0 -1 0"/><limit lower="0" upper="0.04" effort="1" velocity="0.1"/></joint>')
    path.write_text(path.read_text().replace("</robot>", finger + "</robot>"))
    with pytest.raises(RobotModelError, match="the chain branches.*tip="):
        Robot.from_urdf(path)
    robot = Robot.from_urdf(path, tip="tool0", tool="robotiq_hande")
    assert robot.n == 1 and robot.max_opening_m == TOOLS["robotiq_hande"].max_opening_m


def test_missing_and_oversized_meshes_are_named(tmp_path):
    path = _arm(tmp_path)
    meshed = path.read_text().replace('<cylinder radius="0.04" length="0.3"/>', '<mesh filename="meshes/upper.stl"/>')
    path.write_text(meshed)
    with pytest.raises(RobotModelError, match=r"line 4: <mesh filename='meshes/upper.stl'> of link 'upper': no such file"):
        Robot.from_urdf(path)
    (tmp_path / "meshes").mkdir()
    with open(tmp_path / "meshes" / "upper.stl", "wb") as f:
        f.truncate(40_000_000)
    with pytest.raises(RobotModelError, match=r"line 4: .*upper.stl.*40,000,000 bytes is more than"):
        Robot.from_urdf(path)
    (tmp_path / "meshes" / "upper.stl").write_bytes(b"solid junk\nthis is not an stl\n")
    with pytest.raises(RobotModelError, match=r"line 4: <mesh> of link 'upper': mesh .*upper.stl"):
        Robot.from_urdf(path)
    # a COLLADA file is XML: an entity bomb never reaches assimp
    path.write_text(meshed.replace("upper.stl", "upper.dae"))
    (tmp_path / "meshes" / "upper.dae").write_text(
        '<?xml version="1.0"?><!DOCTYPE C [<!ENTITY a "aaaa"><!ENTITY b "&a;&a;&a;&a;">]><COLLADA>&b;</COLLADA>')
    with pytest.raises(RobotModelError, match=r"line 4: <mesh> of link 'upper': .*upper.dae.* DOCTYPE or ENTITY"):
        Robot.from_urdf(path)


def test_base_pose_mounts_the_arm_in_the_world(tmp_path):
    path = _arm(tmp_path)
    flat = Robot.from_urdf(path, tool="robotiq_2f85", home_q=[0.3])
    raised = Robot.from_urdf(path, tool="robotiq_2f85", home_q=[0.3], base_pose=(0.1, 0.2, 0.5, 0, 0, math.pi / 2))
    a, b = flat.tcp_pose(np.array([0.3])), raised.tcp_pose(np.array([0.3]))
    mount = np.eye(4)
    mount[:3, :3] = pin.rpy.rpyToMatrix(0, 0, math.pi / 2)
    mount[:3, 3] = (0.1, 0.2, 0.5)
    np.testing.assert_allclose(b, mount @ a, atol=1e-12)


# --- through the CLI ------------------------------------------------------------------------------------

_PICK = """lib.set_speed(0.3)
lib.open_gripper()
lib.move_above(apple, 0.1)
lib.move_linear(apple.x, apple.y, apple.z)
lib.close_gripper()
lib.move_linear(apple.x, apple.y, apple.z + 0.15)
lib.move_to(box.x, box.y, box.top + 0.12)
lib.open_gripper()
lib.home()
"""


def _pick_scene(path: Path, reach_m: float) -> Path:
    """An apple and a box laid out as for the UR3e, scaled to the arm's reach (0.6 m for the UR3e's layout)."""
    import json

    s = reach_m / 0.6
    scene = {"name": "pick", "objects": [{"id": "apple", "shape": "sphere", "size": [0.035], "position": [0.35 * s, 0.1 * s, 0.035]}],
             "containers": [{"id": "box", "size": [0.2, 0.2, 0.08], "position": [0.3 * s, -0.25 * s, 0.04]}]}
    path.write_text(json.dumps(scene))
    return path


_CLI_ARMS = [p for p in _arms() if p.id in ("airo ur5e", "pybullet xarm6", "erd panda", "erd ur5", "erd ur10", "pybullet iiwa")]


@pytest.mark.parametrize("path, kwargs", _CLI_ARMS)
def test_a_pick_and_place_through_the_cli_on_a_vendor_arm(tmp_path, capsys, path, kwargs):
    import json

    from robocritics import cli

    if path is None or not path.is_file():
        pytest.skip("the package with this URDF is not installed (pip install '.[test]')")
    tool = kwargs.get("tool", "robotiq_2f85")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        robot = Robot.from_urdf(path, tool=tool, tip=kwargs.get("tip"))
        program = tmp_path / "pick.py"
        program.write_text(_PICK)
        scene = _pick_scene(tmp_path / "scene.json", robot.reach_m)
        argv = ["check", str(program), "--scene", str(scene), "--robot", str(path), "--tool", tool, "--json",
                "--goal", "apple in box"] + (["--tip", kwargs["tip"]] if "tip" in kwargs else [])
        status = cli.main(argv)
    report = json.loads(capsys.readouterr().out)
    verdicts = {v["critic"]: v for v in report["verdicts"]}
    assert status == 0, [(v["critic"], v["message"]) for v in report["verdicts"] if v["flag"] == "ERROR"]
    assert verdicts["task_outcome"]["flag"] == "OK"  # the apple ended in the box
    # space usage is judged against this arm's own reach: half its reach sphere, as the UR3e's is against 0.5 m
    assert verdicts["space_usage"]["threshold"] == pytest.approx(2 / 3 * math.pi * robot.reach_m**3, rel=1e-9)


def test_a_scene_that_names_a_bundled_arm_is_run_on_it(tmp_path, capsys):
    import json

    from robocritics import cli

    program = tmp_path / "pick.py"
    program.write_text(_PICK)
    scene = _pick_scene(tmp_path / "scene.json", 0.95)
    scene.write_text(json.dumps({**json.loads(scene.read_text()), "robot": "ur5e"}))
    assert cli.main(["check", str(program), "--scene", str(scene), "--json"]) in (0, 1)  # not 2: the CLI follows the scene
    report = json.loads(capsys.readouterr().out)
    assert report["verdicts"][0]["critic"] != "runtime"


@pytest.mark.parametrize("argv, message", [
    (["--tool", "robotiq_2f85"], "--tool and --tip need --robot PATH.urdf"),
    (["--robot", "ur5e", "--tool", "robotiq_2f85"], "carries its own gripper"),
    (["--robot", "kuka"], "not a bundled arm"),
    (["--base-pose", "0,0,0.1,0,0,0"], "--base-pose needs --robot PATH.urdf"),
    (["--robot", "ur5e", "--base-pose", "0,0,0.1,0,0,0"], "--base-pose is for --robot PATH.urdf"),
    (["--robot", "arm.urdf", "--base-pose", "0,0,nan,0,0,0"], "every number must be finite"),
    (["--robot", "arm.urdf", "--base-pose", "0,0,inf,0,0,0"], "every number must be finite"),
    (["--robot", "arm.urdf", "--base-pose", "0,0,0.1"], "is not six numbers"),
    (["--robot", "arm.urdf", "--base-pose", "0,0,0.1,0,0,x"], "is not six numbers"),
])
def test_robot_options_refuse_what_they_cannot_do(tmp_path, capsys, argv, message):
    from robocritics import cli

    program = tmp_path / "pick.py"
    program.write_text(_PICK)
    assert cli.main(["check", str(program), *argv]) == 2
    assert message in capsys.readouterr().err


def test_base_pose_stands_a_urdf_arm_where_it_says_through_the_cli(tmp_path, capsys):
    """``--base-pose`` reaches ``Robot.from_urdf(base_pose=...)``: the CLI's report is the library's for the
    same pose, and a raised, turned base measures differently from one at the origin."""
    import json

    from robocritics import cli
    from robocritics.pipeline import check
    from robocritics.scene import Scene

    urdf = Path(__file__).resolve().parents[1] / "src" / "robocritics" / "robot" / "models" / "ur3e.urdf"
    program = tmp_path / "p.py"
    program.write_text("lib.home()\n")
    pose = (0.02, -0.01, 0.05, 0.0, 0.0, 0.4)

    def cli_report(*extra):
        assert cli.main(["check", str(program), "--json", "--robot", str(urdf), *extra]) == 0
        return json.loads(capsys.readouterr().out)

    moved = cli_report("--base-pose", ",".join(map(str, pose)))
    at_origin = cli_report()
    _, library = check("lib.home()\n", Scene(), robot=Robot.from_urdf(urdf, base_pose=pose))
    assert moved["verdicts"][1]["critic"] == library.verdicts[1].critic == "collision"
    assert moved["verdicts"][1]["value"] == pytest.approx(library.verdicts[1].value, rel=1e-9)
    assert moved["trajectory_hash"] == library.trajectory_hash != at_origin["trajectory_hash"]
    assert abs(moved["verdicts"][1]["value"] - at_origin["verdicts"][1]["value"]) > 1e-3


@pytest.mark.parametrize("command", ["fix", "deploy", "batch", "studio", "run"])
def test_every_command_takes_robot_and_names_a_bad_urdf(tmp_path, capsys, command):
    from robocritics import cli

    bad = tmp_path / "arm.urdf"
    bad.write_text('<robot name="a"><link name="base"/></robot>')
    program = tmp_path / "pick.py"
    program.write_text(_PICK)
    rows = tmp_path / "in.jsonl"
    rows.write_text('{"id": "a", "scene": "sorting", "program": "lib.home()"}\n')
    argv = {"fix": ["fix", str(program)], "deploy": ["deploy", str(program), "--dry-run"],
            "batch": ["batch", str(rows), "-o", str(tmp_path / "out.jsonl")],
            "studio": ["studio", "--program", str(program), "--no-browser", "--port", "0"],
            "run": ["run", "put the apple in the box", "--scene", "sorting", "--base-url", "http://127.0.0.1:9/v1", "--model", "m"]}[command]
    assert cli.main([*argv, "--robot", str(bad)]) == 2
    assert "no moving joint" in capsys.readouterr().err


def test_a_five_joint_arm_points_its_fingers_with_the_yaw_free():
    """SO-100 (5 joints): pointing IK reaches a position with the finger axis along a direction (five
    constraints), from configurations the arm can take."""
    from robocritics.robot.ik_numeric import pointing_ik

    path = _erd() / "so_arm_description/urdf/so100.urdf" if _erd() else None
    if path is None or not path.is_file():
        pytest.skip("example-robot-data is not installed")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        robot = Robot.from_urdf(path, tip="gripper", tool="none")
    assert robot.n == 5
    rng = np.random.default_rng(3)
    for made in rng.uniform(robot.lower, robot.upper, size=(10, robot.n)):
        pose = robot.tcp_pose(made)
        seed = np.clip(made + rng.normal(0, 0.2, robot.n), robot.lower, robot.upper)
        q = pointing_ik(robot.model, robot.data, robot._tcp_frame_id, pose[:3, 3], pose[:3, 2], seed, robot.lower, robot.upper)
        reached = robot.tcp_pose(q)
        np.testing.assert_allclose(reached[:3, 3], pose[:3, 3], atol=1e-8)
        np.testing.assert_allclose(reached[:3, 2], pose[:3, 2], atol=1e-8)
        assert robot.in_limits(q)


def test_a_tool_urdf_brings_its_tcp_fingers_and_gripper_links(tmp_path):
    tool = tmp_path / "suction_cup_gripper.urdf"
    tool.write_text("""<robot name="my_gripper">
  <link name="adapter"><collision><geometry><box size="0.06 0.06 0.04"/></geometry></collision></link>
  <link name="jaw_a"><collision><origin xyz="0 0 0.02"/><geometry><cylinder radius="0.008" length="0.04"/></geometry></collision></link>
  <link name="jaw_b"><collision><origin xyz="0 0 0.02"/><geometry><cylinder radius="0.008" length="0.04"/></geometry></collision></link>
  <link name="tcp"/>
  <joint name="a" type="fixed"><parent link="adapter"/><child link="jaw_a"/><origin xyz="0 0.03 0.05"/></joint>
  <joint name="b" type="fixed"><parent link="adapter"/><child link="jaw_b"/><origin xyz="0 -0.03 0.05"/></joint>
  <joint name="t" type="fixed"><parent link="adapter"/><child link="tcp"/><origin xyz="0 0 0.12"/></joint>
  <gripper max_opening="0.044" fingers="jaw_a jaw_b"/>
</robot>""")
    robot = Robot.from_urdf(_arm(tmp_path), tool=str(tool))
    assert robot.max_opening_m == 0.044 and robot.finger_links == ("jaw_a", "jaw_b")
    assert {c.frame for c in robot.capsules if c.group == "gripper"} == {"adapter", "jaw_a", "jaw_b"}
    assert {c.frame for c in robot.capsules if c.group == "arm"} == {"base", "upper"}
    pose = robot.forward(np.array([0.2]))
    flange = pose[robot.frame_names.index("tool0")]
    np.testing.assert_allclose(np.linalg.inv(flange) @ pose[robot.tcp_index][:, 3], (0, 0, 0.12, 1), atol=1e-12)
    # a tool whose joint moves is refused, naming it
    tool.write_text(tool.read_text().replace('<joint name="a" type="fixed">', '<joint name="a" type="prismatic">'
                                             ).replace('<origin xyz="0 0.03 0.05"/></joint>',
                                                       '<origin xyz="0 0.03 0.05"/><limit lower="0" upper="0.02" velocity="0.1"/></joint>'))
    with pytest.raises(RobotModelError, match=r"line \d+: tool joint 'a' is prismatic"):
        Robot.from_urdf(_arm(tmp_path), tool=str(tool))


def test_inferred_facts_can_be_overridden(tmp_path):
    path = _arm(tmp_path)
    robot = Robot.from_urdf(path, tool="none", fixed_links=("base",), reach_m=0.4, home_q=[0.5],
                            joint_limits={"shoulder": (-0.5, 0.8)}, name="mine")
    assert robot.fixed_links == ("base",) and robot.reach_m == 0.4 and robot.home_q.tolist() == [0.5]
    assert robot.lower.tolist() == [-0.5] and robot.upper.tolist() == [0.8] and robot.name == "mine"
    assert robot.max_opening_m == 0.0  # tool "none": the TCP is the flange and nothing grasps
    np.testing.assert_allclose(robot.tcp_pose(np.array([0.1])), robot.forward(np.array([0.1]))[robot.frame_names.index("tool0")])
    with pytest.raises(RobotModelError, match="joint_limits names 'elbow', not a moving joint"):
        Robot.from_urdf(path, joint_limits={"elbow": (0, 1)})
    with pytest.raises(RobotModelError, match=r"joint_limits\['shoulder'\]"):
        Robot.from_urdf(path, joint_limits={"shoulder": (0, float("nan"))})
    with pytest.raises(RobotModelError, match="no bundled tool 'vacuum'"):
        Robot.from_urdf(path, tool="vacuum")
    # a zero speed limit as shipped is refused naming the joint; given here, the arm loads with it
    slow = _arm(tmp_path, velocity="0")
    with pytest.raises(RobotModelError, match="joint 'shoulder': velocity must be positive"):
        Robot.from_urdf(slow)
    assert Robot.from_urdf(slow, joint_limits={"shoulder": (-1, 1, 0.7)}).velocity_limits.tolist() == [0.7]


def test_fitted_capsules_of_a_vendor_mesh_hold_the_bound():
    """The UR5's upper arm as example-robot-data ships it: three capsules (a 0.057 m tube between two housings),
    and the capsule distance against a brute-force point-to-triangle distance within the slack."""
    robots = _erd()
    if robots is None:
        pytest.skip("example-robot-data is not installed")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        mesh = fit.load_mesh(robots / "ur_description/meshes/ur5/collision/upperarm.stl")
    capsules = fit.fit_capsules(mesh)
    assert len(capsules) == 3 and min(c.radius_m for c in capsules) < 0.06
    rng = np.random.default_rng(4)
    lo, hi = mesh.vertices.min(axis=0) - 0.1, mesh.vertices.max(axis=0) + 0.1
    for p in rng.uniform(lo, hi, size=(25, 3)):
        d_caps = min(_capsule_distance(p, c) for c in capsules)
        d_mesh = _mesh_distance(p, mesh)
        assert d_caps <= d_mesh + 1e-9
        if d_caps > 0:
            assert d_mesh - d_caps <= max(c.slack_m for c in capsules) + 1e-9
