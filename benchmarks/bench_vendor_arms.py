"""Vendor arms from pip packages loaded as shipped: per arm the package, joints, load CPU, FK error against
Pinocchio on the raw file, and a pick-and-place scaled to its reach (score, CPU per program for simulate +
critique, warm), beside the built-in UR3e on the same program measured right after each arm (the ratio is
of those two, as the load of a shared machine drifts). CPU time (process_time), not wall time.

Needs the test extra (example-robot-data, rtb-data, airo-models, pybullet).
Run: .venv/bin/python benchmarks/bench_vendor_arms.py [REPEATS] [ARM ...]
(ARM: the rows whose arm name contains it, case-insensitive, e.g. ``iiwa14 xarm7``; default every row)
"""

from __future__ import annotations

import importlib.util
import math
import statistics
import sys
import sysconfig
import time
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin

from robocritics import Robot, Scene, critique, simulate
from robocritics.goals import parse_goals

PROGRAM = """lib.set_speed(0.3)
lib.open_gripper()
lib.move_above(apple, 0.1)
lib.move_linear(apple.x, apple.y, apple.z)
lib.close_gripper()
lib.move_linear(apple.x, apple.y, apple.z + 0.15)
lib.move_to(box.x, box.y, box.top + 0.12)
lib.open_gripper()
lib.home()
"""


def _site(package: str) -> Path | None:
    spec = importlib.util.find_spec(package)
    return Path(spec.origin).parent if spec and spec.origin else None


def arms() -> list[tuple[str, Path, dict]]:
    pb, rtb, airo = _site("pybullet_data"), _site("rtbdata"), _site("airo_models")
    erd = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
    rows = [
        ("pybullet_data", "KUKA iiwa", pb and pb / "kuka_iiwa/model.urdf", {}),
        ("pybullet_data", "xArm6", pb and pb / "xarm/xarm6_robot.urdf", {}),
        ("pybullet_data", "Panda", pb and pb / "franka_panda/panda.urdf", {"tip": "panda_link8", "tool": "franka_hand"}),
        ("example-robot-data", "UR5", erd / "ur_description/urdf/ur5_robot.urdf", {}),
        ("example-robot-data", "UR10", erd / "ur_description/urdf/ur10_robot.urdf", {}),
        ("example-robot-data", "xArm7", erd / "xarm_description/urdf/xarm7.urdf", {}),
        ("example-robot-data", "Kinova j2s6s200", erd / "kinova_description/robots/kinova.urdf", {}),
        # the flange: the Robotiq replaces the Z1's own gripper (its stator jaw, kept with tip="gripperStator", hits the apple)
        ("example-robot-data", "Unitree Z1", erd / "z1_description/urdf/z1.urdf", {"tip": "link06"}),
        ("example-robot-data", "Panda", erd / "panda_description/urdf/panda.urdf", {"tip": "panda_link8", "tool": "franka_hand"}),
        # its file faces -y and its shoulder pan turns +-2 rad: the apple at +27 deg is out of its range, so it
        # stands turned to face +x, as a cell would mount it
        ("example-robot-data", "SO-100", erd / "so_arm_description/urdf/so100.urdf",
         {"tip": "gripper", "base_pose": (0.0, 0.0, 0.0, 0.0, 0.0, math.pi / 2)}),
        ("rtb-data", "iiwa14 R820", rtb and rtb / "xacro/kuka_description/kuka_lbr_iiwa/urdf/lbr_iiwa_14_r820.urdf", {}),
        ("rtb-data", "KUKA KR16-2", rtb and rtb / "xacro/kuka_description/kuka_kr16/urdf/kr16_2.urdf", {}),
        ("rtb-data", "Puma560", rtb and rtb / "xacro/unimation_puma560_description/urdf/puma560_robot.urdf", {}),
        # the same file with speed limits given (it ships 0 rad/s; 1 rad/s assumed, not a datasheet value)
        ("rtb-data", "Puma560 +speeds", rtb and rtb / "xacro/unimation_puma560_description/urdf/puma560_robot.urdf",
         {"joint_limits": "file limits, 1 rad/s"}),
        ("airo-models", "UR3e", airo and airo / "arms/ur3e/ur3e.urdf", {}),
        ("airo-models", "UR5e", airo and airo / "arms/ur5e/ur5e.urdf", {}),
    ]
    return [(pkg, name, path, kw) for pkg, name, path, kw in rows]


def with_speeds(path: Path, speed_rad_s: float = 1.0) -> dict:
    """The file's own position limits with ``speed_rad_s`` as every moving joint's speed limit."""
    import xml.etree.ElementTree as ET

    out = {}
    for joint in ET.parse(path).getroot().iter("joint"):
        limit = joint.find("limit")
        if joint.get("type") in ("revolute", "prismatic") and limit is not None:
            out[joint.get("name")] = (float(limit.get("lower", 0)), float(limit.get("upper", 0)), speed_rad_s)
    return out


def scene_for(reach_m: float) -> Scene:
    s = reach_m / 0.6
    return Scene.model_validate({
        "name": "pick",
        "objects": [{"id": "apple", "shape": "sphere", "size": [0.035], "position": [0.35 * s, 0.1 * s, 0.035]}],
        # the box shrinks with a small arm (the SO-100's 0.35 m): at full size its corner is at the arm's base
        "containers": [{"id": "box", "size": [0.2 * min(s, 1.0), 0.2 * min(s, 1.0), 0.08], "position": [0.3 * s, -0.25 * s, 0.04]}],
    })


def fk_error(robot: Robot, path: Path, base_pose=None) -> float:
    """The largest entry of ``robot``'s tip pose minus Pinocchio's on the raw file, stood at ``base_pose``."""
    from robocritics.robot.vendor import base_pose_matrix

    base = np.eye(4) if base_pose is None else base_pose_matrix(base_pose)
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    tip = robot.frame_names.index(robot.tip_frame)
    worst = 0.0
    for q in np.random.default_rng(2).uniform(robot.lower, robot.upper, size=(20, robot.n)):
        x = pin.neutral(model)
        for name, value in zip(robot.joint_names, q):
            j = model.getJointId(name)
            i = model.idx_qs[j]
            if model.nqs[j] == 1:
                x[i] = value
            else:
                x[i : i + 2] = (math.cos(value), math.sin(value))
        pin.framesForwardKinematics(model, data, x)
        worst = max(worst, float(np.abs(robot.forward(q)[tip] - base @ data.oMf[model.getFrameId(robot.tip_frame, pin.FrameType.BODY)].homogeneous).max()))
    return worst


def program_cpu(robot: Robot, repeats: int) -> tuple[float, str, str]:
    scene = scene_for(robot.reach_m)
    goals = parse_goals(["apple in box"], scene)
    try:
        execution = simulate(PROGRAM, scene, robot)
    except Exception as exc:  # a program that cannot be planned on this arm: say why
        return math.nan, "-", f"{type(exc).__name__}: {str(exc)[:90]}"
    times = []
    for _ in range(repeats):
        t0 = time.process_time()
        execution = simulate(PROGRAM, scene, robot)
        report = critique(execution, goals=goals)
        times.append(time.process_time() - t0)
    errors = [v.critic for v in report.verdicts if v.flag.name == "ERROR"]
    return statistics.median(times), f"{report.score:.0f}/10", ("errors: " + ", ".join(errors)) if errors else ""


def main(repeats: int = 3, *only: str) -> None:
    warnings.simplefilter("ignore", DeprecationWarning)
    ur3e = Robot.ur3e()
    ref_cpu, ref_score, _ = program_cpu(ur3e, repeats)
    print(f"{'package':<19} {'arm':<16} {'DoF':>3} {'loads':>5} {'load CPU s':>10} {'FK error':>9} {'capsules':>8} "
          f"{'reach m':>7} {'score':>6} {'CPU/program s':>13} {'vs UR3e':>7}  notes")
    print(f"{'(built-in)':<19} {'UR3e':<16} {6:>3} {'yes':>5} {'-':>10} {'-':>9} {len(ur3e.capsules):>8} {ur3e.reach_m:>7.3f} "
          f"{ref_score:>6} {ref_cpu:>13.3f} {1.0:>7.2f}")
    for package, name, path, kwargs in arms():
        if only and not any(word.lower() in name.lower() for word in only):
            continue
        if path is None or not Path(path).is_file():
            print(f"{package:<19} {name:<16} {'':>3} {'no':>5}  (package not installed)")
            continue
        if kwargs.get("joint_limits") == "file limits, 1 rad/s":
            kwargs = {**kwargs, "joint_limits": with_speeds(path)}
        t0 = time.process_time()
        try:
            robot = Robot.from_urdf(path, **{"tool": "robotiq_2f85", **kwargs})
        except Exception as exc:
            print(f"{package:<19} {name:<16} {'':>3} {'no':>5}  {type(exc).__name__}: {str(exc)[-120:]}")
            continue
        load = time.process_time() - t0
        cpu, score, notes = program_cpu(robot, repeats)
        ref_cpu = program_cpu(ur3e, repeats)[0]  # beside each arm: the machine's load drifts between arms
        print(f"{package:<19} {name:<16} {robot.n:>3} {'yes':>5} {load:>10.2f} {fk_error(robot, path, kwargs.get('base_pose')):>9.1e} "
              f"{len(robot.capsules):>8} {robot.reach_m:>7.3f} {score:>6} {cpu:>13.3f} {cpu / ref_cpu:>7.2f}  {notes}")
    print(f"\nreproduce: .venv/bin/python benchmarks/bench_vendor_arms.py {repeats}", *(repr(w) for w in only))


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 3, *sys.argv[2:])
