"""Trajectory files (CSV, JointTrajectory JSON, MoveIt YAML, rosbag2) and export, each checked back."""

import json
from pathlib import Path

import numpy as np
import pytest

from robocritics import Robot, Scene, critique, simulate
from robocritics.cli import main
from robocritics.errors import TrajectoryError
from robocritics.formats import load_motion
from robocritics.formats.load import moving_span
from robocritics.formats.export import to_csv, to_joint_trajectory, to_urscript

ROOT = Path(__file__).resolve().parent.parent
PROGRAM = "set_speed(0.6)\nmove_to(0.28, 0.05, 0.22)\nmove_down(0.04)\nmove_to(0.2, -0.1, 0.25)\n"
SCENE = Scene.builtin("sorting")


@pytest.fixture(scope="module")
def program():
    return simulate(PROGRAM, SCENE)


def same_motion(a, b, atol_rad=2e-3, duration_rel=0.01, live=False):
    """``b`` follows ``a``'s joints within ``atol_rad`` at ``a``'s times and lasts as long within ``duration_rel``;
    ``live``: ``b`` was read as a recording of an arm, so ``a``'s still lead-in and tail are dropped as in ``b``."""
    if live:
        first, last = moving_span(a.q, a.gripper_opening_m)
        assert 0 < last - first < len(a)
        a = a.slice(first, last + 1)
    assert b.duration_s == pytest.approx(a.duration_s, rel=duration_rel)
    ta = a.time - a.time[0]
    tb = b.time - b.time[0]
    q = np.column_stack([np.interp(ta, tb, b.q[:, j]) for j in range(a.q.shape[1])])
    assert np.abs(q - a.q).max() < atol_rad


def test_generic_csv_matches_joints_by_name_in_any_column_order(tmp_path, program):
    traj = program.trajectory
    names = list(traj.limits.joint_names)
    order = names[::-1]
    rows = ["time," + ",".join(order)]
    for t, q in zip(traj.time, traj.q):
        rows.append(f"{t:.6f}," + ",".join(f"{q[names.index(n)]:.9f}" for n in order))
    path = tmp_path / "motion.csv"
    path.write_text("\n".join(rows) + "\n")
    execution = load_motion(path, scene=SCENE)
    same_motion(traj, execution.trajectory, atol_rad=1e-4)
    assert execution.source == "CSV motion.csv" and execution.plan is None
    assert critique(execution).score == critique(program).score


def test_ur_rtde_style_csv_and_its_errors(tmp_path, program):
    traj = program.trajectory
    header = "timestamp," + ",".join(f"target_q_{i}" for i in range(6)) + "," + ",".join(f"actual_q_{i}" for i in range(6))
    rows = [header] + [
        f"{1000 + t:.4f}," + ",".join("0" for _ in range(6)) + "," + ",".join(f"{v:.9f}" for v in q)
        for t, q in zip(traj.time, traj.q)
    ]
    path = tmp_path / "rec.csv"
    path.write_text("\n".join(rows) + "\n")
    execution = load_motion(path, scene=SCENE)
    assert execution.source == "ur_rtde recording rec.csv"
    same_motion(traj, execution.trajectory, atol_rad=1e-4, live=True)
    bad = tmp_path / "bad.csv"
    bad.write_text(rows[0] + "\n" + rows[1] + "\n" + rows[2] + "x\n")  # columns not read may hold anything
    with pytest.raises(TrajectoryError, match=r"row 3, column 'actual_q_5': not a number"):
        load_motion(bad)
    backwards = tmp_path / "back.csv"
    backwards.write_text("\n".join([rows[0], rows[2], rows[1]]) + "\n")
    with pytest.raises(TrajectoryError, match="time goes backwards at sample 1"):
        load_motion(backwards)
    other = tmp_path / "other.csv"
    other.write_text("time,shoulder_pan_joint,elbow\n0,0,0\n")
    with pytest.raises(TrajectoryError, match="no values for the ur3e's joint.*shoulder_lift_joint"):
        load_motion(other)


def test_joint_trajectory_json_and_moveit_yaml(tmp_path, program):
    import yaml

    text = to_joint_trajectory(program.trajectory)
    path = tmp_path / "traj.json"
    path.write_text(text)
    execution = load_motion(path, scene=SCENE)
    same_motion(program.trajectory, execution.trajectory)
    assert execution.source == "JointTrajectory JSON traj.json"
    message = json.loads(text)
    moveit = tmp_path / "plan.yaml"
    moveit.write_text(yaml.safe_dump({"joint_trajectory": message, "multi_dof_joint_trajectory": {"points": []}}))
    same_motion(program.trajectory, load_motion(moveit, scene=SCENE).trajectory)
    message["points"][3]["time_from_start"] = {"sec": "x"}
    path.write_text(json.dumps(message))
    with pytest.raises(TrajectoryError, match=r"points\[3\].time_from_start"):
        load_motion(path)


def test_sparse_waypoints_with_velocities_are_interpolated_smoothly(tmp_path):
    names = list(Robot.ur3e().joint_names)
    home = Robot.ur3e().home_q
    points = [
        {"positions": (home + [0.5 * s, 0, 0, 0, 0, 0]).tolist(), "velocities": [v, 0, 0, 0, 0, 0],
         "time_from_start": {"sec": int(t), "nanosec": int((t % 1) * 1e9)}}
        for s, v, t in ((0, 0, 0.0), (0.5, 0.375, 1.0), (1, 0, 2.0))
    ]  # fmt: skip
    path = tmp_path / "sparse.json"
    path.write_text(json.dumps({"joint_names": names, "points": points}))
    traj = load_motion(path).trajectory
    speed = np.diff(traj.q[:, 0]) / np.diff(traj.time)
    assert traj.duration_s == pytest.approx(2.0) and speed.max() == pytest.approx(0.375, rel=0.02)
    assert np.abs(np.diff(speed)).max() < 0.02  # no corner at the middle waypoint


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
@pytest.mark.parametrize("kind", ["JointState", "JointTrajectory"])
def test_rosbag2_written_with_rosbags_own_writer(tmp_path, program, storage, kind):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    traj = program.trajectory
    names = list(traj.limits.joint_names) + ["gripper_opening_m"]
    Time = store.types["builtin_interfaces/msg/Time"]
    Duration = store.types["builtin_interfaces/msg/Duration"]
    Header = store.types["std_msgs/msg/Header"]
    bag = tmp_path / "bag"
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(bag, version=9, storage_plugin=plugin) as writer:
        writer.add_connection("/chatter", "std_msgs/msg/String", typestore=store)  # another topic, ignored
        if kind == "JointState":
            JointState = store.types["sensor_msgs/msg/JointState"]
            conn = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=store)
            for t, q, g in zip(traj.time, traj.q, traj.gripper_opening_m):
                ns = int(round((100 + t) * 1e9))
                stamp = Time(sec=ns // 10**9, nanosec=ns % 10**9)
                msg = JointState(
                    header=Header(stamp=stamp, frame_id=""), name=names, position=np.append(q, g),
                    velocity=np.zeros(0), effort=np.zeros(0),
                )  # fmt: skip
                writer.write(conn, ns, store.serialize_cdr(msg, "sensor_msgs/msg/JointState"))
        else:
            JT = store.types["trajectory_msgs/msg/JointTrajectory"]
            Point = store.types["trajectory_msgs/msg/JointTrajectoryPoint"]
            message = json.loads(to_joint_trajectory(traj))
            points = [
                Point(positions=np.array(p["positions"]), velocities=np.array(p["velocities"]), accelerations=np.zeros(0),
                      effort=np.zeros(0), time_from_start=Duration(**p["time_from_start"]))
                for p in message["points"]
            ]  # fmt: skip
            conn = writer.add_connection("/arm/joint_trajectory", "trajectory_msgs/msg/JointTrajectory", typestore=store)
            msg = JT(header=Header(stamp=Time(sec=0, nanosec=0), frame_id=""), joint_names=message["joint_names"], points=points)
            writer.write(conn, 1, store.serialize_cdr(msg, "trajectory_msgs/msg/JointTrajectory"))
    storage_file = next(p for p in bag.iterdir() if p.suffix in (".mcap", ".db3"))
    execution = load_motion(storage_file, scene=SCENE)
    same_motion(traj, execution.trajectory, atol_rad=2e-3 if kind == "JointTrajectory" else 1e-4, live=kind == "JointState")
    assert execution.source.startswith(f"rosbag2 {storage_file.name}")
    if kind == "JointState":
        start = traj.time[moving_span(traj.q, traj.gripper_opening_m)[0]]
        got = execution.trajectory
        np.testing.assert_allclose(
            got.gripper_opening_m, np.interp(got.time + start, traj.time, traj.gripper_opening_m), atol=1e-9
        )
    with pytest.raises(TrajectoryError, match="no topic '/nope'"):
        load_motion(storage_file, topic="/nope")


def test_export_urscript_round_trip_gives_the_same_trajectory(program):
    script = to_urscript(program.trajectory)
    assert script.count("servoj(") == round(program.duration_s / 0.008)  # one per 8 ms, the planned timing
    from robocritics.formats.urscript import run_urscript

    back = run_urscript(script, program.robot, program.scene)
    same_motion(program.trajectory, back.trajectory, atol_rad=5e-3)
    assert critique(back).score == critique(program).score


def test_export_cli_writes_each_format_that_check_reads_back(tmp_path, capsys):
    source = tmp_path / "sorting_short.py"
    source.write_text(PROGRAM)
    expected = simulate(PROGRAM, SCENE)
    for fmt, suffix in (("urscript", ".script"), ("jointtrajectory", ".json"), ("csv", ".csv")):
        out = tmp_path / f"exported{suffix}"
        assert main(["export", str(source), "--to", fmt, "-o", str(out)]) == 0
        assert "score 10/10" in capsys.readouterr().err
        back = load_motion(out, scene=SCENE)
        same_motion(expected.trajectory, back.trajectory, atol_rad=5e-3)
        assert main(["check", str(out), "--scene", "sorting"]) == 0
        assert "score 10/10" in capsys.readouterr().out
    assert main(["export", str(source), "--to", "pdf"]) == 2


def test_grasps_are_inferred_from_the_finger_gap_for_imported_motion(tmp_path):
    """A pick-and-place program exported to CSV (joints and finger gap, nothing about objects) and read back: the
    objects the fingers closed on are the ones the program carried, each left where the program left it, and the
    grasps are not judged as collisions."""
    careful = (ROOT / "examples" / "programs" / "sorting_careful.py").read_text()
    program = simulate(careful, SCENE)
    path = tmp_path / "sorting.csv"
    path.write_text(to_csv(program.trajectory))
    imported = load_motion(path, scene=SCENE)
    carried = lambda e: [a for a in dict.fromkeys(e.trajectory.attached.tolist()) if a]  # noqa: E731
    assert carried(imported) == carried(program) and len(carried(program)) == 3
    for oid in carried(program):
        np.testing.assert_allclose(imported.object_poses[oid][-1, :3, 3], program.object_poses[oid][-1, :3, 3], atol=0.01)
        assert imported.final_scene.container_holding(oid) == program.final_scene.container_holding(oid)
    assert critique(imported).score == critique(program).score == 10
    empty_hand = load_motion(path, scene=Scene())  # nothing to grasp: the fingers close on air
    assert not carried(empty_hand)
