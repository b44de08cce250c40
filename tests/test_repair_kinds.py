"""The repair kinds beyond speed and heights, each on a program built to show its fault (real simulations).

Each test checks the fault is there before, that the repaired program has no Error of
that critic, that no verdict scores lower than before (no new flag) and that the task
goal is still met.
"""

from __future__ import annotations

import ast
import re

import numpy as np
import pytest

from robocritics import Scene
from robocritics.critic import critique
from robocritics.pipeline import check
from robocritics.errors import PlanningError
from robocritics.repair import repair
from robocritics.repair.builtin import _nearest_reachable_dz
from robocritics.robot.model import Robot
from robocritics.pipeline import simulate
from robocritics.critic.verdict import Flag


def _scores(report):
    return {v.critic: v.score for v in report.verdicts}


def _no_new_flag(before, after):
    old, new = _scores(before), _scores(after)
    worse = {c: (old.get(c), s) for c, s in new.items() if c in old and s < old[c]}
    assert not worse, worse


# --- pinch point: the arm reaches back over its shoulder; posture="natural" ---------------------

BEHIND = Scene.model_validate(
    {
        "name": "behind",
        "description": "an apple behind-left of the robot, a box behind-right",
        "objects": [{"id": "apple", "shape": "sphere", "size": [0.035], "position": [-0.12, 0.3, 0.035]}],
        "containers": [{"id": "box", "size": [0.16, 0.16, 0.06], "position": [-0.12, -0.3, 0.03]}],
    }
)
BEHIND_PROGRAM = """move_above(apple, 0.1)
move_linear(apple)
close_gripper()
move_up(0.1)
move_above(box, 0.1)
open_gripper()
"""


def test_pinch_point_repair_asks_for_the_natural_posture():
    before = critique(simulate(BEHIND_PROGRAM, BEHIND), goals=["apple in box"])
    assert before.verdict("pinch_point").flag == Flag.ERROR  # the base is near its limit: the arm reaches back
    r = repair(BEHIND_PROGRAM, BEHIND, goal="apple in box")
    change = next(c for c in r.changes if c.critic == "pinch_point")
    assert 'move_above(box, 0.1, posture="natural")' in r.program
    assert f"line {change.line}" in change.what and change.why and change.cost_s == pytest.approx(change.cost_s)
    assert r.report.verdict("pinch_point").flag != Flag.ERROR
    assert r.errors == []
    _no_new_flag(before, r.report)
    assert r.execution.object_inside("apple", "box")


def test_natural_posture_faces_the_target_with_the_elbow_up():
    # posture="natural" ends in the home posture's branch (shoulder lift, elbow and wrist signs of home),
    # with the base at the target's heading; the default reaches back over the shoulder instead
    robot = Robot.ur3e()
    home = robot.home_q
    q = {}
    for posture in ("nearest", "natural"):
        e = simulate(f'move_to(-0.1, 0.3, 0.1)\nmove_to(-0.1, -0.3, 0.1, posture="{posture}")\n', BEHIND, robot=robot)
        q[posture] = e.trajectory.q[-1]
        assert np.allclose(e.trajectory.tcp[-1, :3, 3], [-0.1, -0.3, 0.1], atol=1e-6)
    assert np.all(np.sign(q["natural"][1:5]) == np.sign(home[1:5]))
    assert not np.all(np.sign(q["nearest"][1:5]) == np.sign(home[1:5]))


def test_bad_posture_is_a_program_error_naming_the_choices():
    _, report = check('move_to(0.3, 0.0, 0.2, posture="sideways")\n', BEHIND)
    v = report.verdict("runtime")
    assert v.flag == Flag.ERROR and "'nearest'" in v.message and "'natural'" in v.message


# --- unreachable target: the program does not run; the nearest reachable hover height -----------

UNREACHABLE = """move_above(green_apple, height=0.42)
move_linear(green_apple)
close_gripper()
move_up(0.12)
move_above(white_box, 0.1)
open_gripper()
home()
"""


def test_unreachable_hover_is_lowered_to_a_reachable_height():
    scene = Scene.resolve("sorting")
    _, before = check(UNREACHABLE, scene)
    assert [v.critic for v in before.verdicts] == ["runtime"] and before.verdicts[0].evidence.lines == [1]
    r = repair(UNREACHABLE, scene, goal="green_apple in white_box")
    assert r.execution is not None and r.errors == []
    change = r.changes[0]
    assert change.critic == "runtime" and change.line == 1 and "lowered" in change.what and change.cost_s == 0.0
    hover = next(line for line in r.program.splitlines() if line.startswith("move_above(green_apple"))
    new_height = float(hover.split("height=")[1].rstrip(")"))
    assert 0 < new_height < 0.42
    assert r.execution.object_inside("green_apple", "white_box")
    # the new hover point is reachable; the old one is not (the robot's own IK decides)
    robot = Robot.ur3e()
    apple = scene.entity("green_apple")
    with pytest.raises(PlanningError):
        robot.ik([apple.position[0], apple.position[1], apple.top + 0.42])
    robot.ik([apple.position[0], apple.position[1], apple.top + new_height])


def test_nearest_reachable_height_matches_a_plain_scan():
    robot = Robot.ur3e()
    target = (0.4, 0.0, 0.49)

    def ok(z):
        try:
            robot.ik([target[0], target[1], z])
            return True
        except PlanningError:
            return False

    dz = _nearest_reachable_dz(robot, target, 0.0, 0.0)
    # reference: the first 1 cm step (down first, then up) where the point and the one beyond it are reachable
    ref = next(
        s * k / 100 + s / 100 for k in range(1, 51) for s in (-1, 1) if ok(target[2] + s * k / 100) and ok(target[2] + s * (k + 1) / 100)
    )
    assert dz == pytest.approx(ref)
    assert ok(target[2] + dz) and not ok(target[2])


def test_a_program_that_never_runs_is_returned_unrepaired_with_its_runtime_error():
    r = repair("move_to(2.0, 0.0, 0.1)\n", "sorting")  # 2 m away: no height reaches it
    assert r.execution is None and r.changes == [] and r.program == r.original
    assert [v.critic for v in r.errors] == ["runtime"]


# --- spearing: a fast plunge along the fingers; only that move is slowed ------------------------

SPEARING = """move_to(food_container.x, food_container.y, food_container.top + 0.15)
move_down(0.18)
close_gripper()
move_up(0.2)
move_to(trash_bin.x, trash_bin.y, trash_bin.top + 0.15)
open_gripper()
home()
"""


def test_spearing_repair_slows_only_the_plunge():
    scene = Scene.resolve("recycling")
    before = critique(simulate(SPEARING, scene), goals=["food_container in trash_bin"])
    spear = before.verdict("end_effector_pose")
    assert spear.flag == Flag.ERROR and 2 in spear.evidence.lines
    r = repair(SPEARING, scene, goal="food_container in trash_bin")
    assert r.report.verdict("end_effector_pose").flag != Flag.ERROR
    _no_new_flag(before, r.report)
    change = next(c for c in r.changes if c.critic == "end_effector_pose")
    assert change.line == 2 and change.cost_s > 0
    f = float(change.what.split("-> ")[1].split(" ")[0].rstrip(";"))
    assert f == pytest.approx(round(0.85 * spear.threshold / spear.value, 2))  # the smallest slowdown, not a blanket one
    # only the plunge is slowed (the Warning that follows may slow it further, within the same wrapper)
    m = re.search(r"set_speed\(([0-9.]+)\)\nmove_down\(0.18\)\nset_speed\(1\)\n", r.program)
    assert m and float(m.group(1)) <= f
    assert r.program.count("move_down(0.18)") == 1 and r.program.count("set_speed(") % 2 == 0
    assert r.execution.object_inside("food_container", "trash_bin")


# --- release higher: the vertical overlap measured in the trace, per object of a loop ------------

RECYCLE_SPREAD = """release_spots = {'coffee_cup': (0.057, 0.0), 'food_container': (-0.029, 0.05), 'water_bottle': (-0.029, -0.05)}
release_raise = {'coffee_cup': 0.0, 'food_container': 0.0, 'water_bottle': 0.0}  # m
for item in [coffee_cup, food_container, water_bottle]:
    move_to(item.x, item.y, item.top + 0.15)
    move_down(0.18)
    close_gripper()
    move_to(trash_bin.x + release_spots[item.id][0], trash_bin.y + release_spots[item.id][1], trash_bin.top + release_raise[item.id])
    open_gripper()
home()
"""


def _reference_overlaps(execution, line):
    """Per carried object, max over counted collision samples of ``line`` of top(b) - bottom(a): one sample at a time."""
    from robocritics.critic.builtin.collision import counted_distances

    traj = execution.trajectory
    D = counted_distances(traj)
    objects = {o.id: o for o in execution.scene.objects}
    containers = {c.id: c for c in execution.scene.containers}
    out = {}
    for t in range(len(traj)):
        step = int(traj.step[t])
        if traj.steps[step].line != line:
            continue
        first = int(np.flatnonzero(traj.step == step)[0])
        load = str(traj.attached[first]) or (str(traj.attached[first - 1]) if first else "")
        for k, pair in enumerate(traj.pairs):
            if D[t, k] > 0 or pair.group_a not in ("gripper", "attached") or pair.group_b not in ("object", "container"):
                continue
            b = pair.b_entity
            if b in containers:
                top = containers[b].top
            elif b in execution.object_poses:
                top = execution.object_poses[b][t, 2, 3] + objects[b].half_height
            else:
                top = objects[b].top
            if pair.group_a == "attached":
                bottom = execution.object_poses[pair.a][t, 2, 3] - objects[pair.a].half_height
            else:
                bottom = traj.tcp[t, 2, 3]
            out[load] = max(out.get(load, 0.0), top - bottom, -D[t, k])
    return out


def test_vertical_overlaps_match_a_per_sample_reference():
    from robocritics.repair.builtin import _vertical_overlaps

    execution = simulate(RECYCLE_SPREAD, Scene.resolve("recycling"))
    fast = _vertical_overlaps(execution, 7)
    slow = _reference_overlaps(execution, 7)
    assert fast.keys() == slow.keys() and fast  # something is hit on the release move
    for key in slow:
        assert fast[key] == pytest.approx(slow[key], abs=1e-12)


def test_release_raise_table_is_updated_not_duplicated():
    from robocritics.repair.builtin import RELEASE_CLEARANCE_M, _raise_release, _vertical_overlaps
    from robocritics.repair import apply_edits

    scene = Scene.resolve("recycling")
    execution = simulate(RECYCLE_SPREAD, scene)
    verdict = critique(execution, critics=["collision"]).verdict("collision")
    assert verdict.flag == Flag.ERROR and 7 in verdict.evidence.lines
    [edit] = _raise_release(verdict, execution, RECYCLE_SPREAD)
    out = apply_edits(RECYCLE_SPREAD, edit.ops)
    assert out.count("release_raise = ") == 1 and out.count("release_raise[item.id]") == 1
    line = next(ln for ln in out.splitlines() if ln.startswith("release_raise = "))
    table = ast.literal_eval(line.split("=", 1)[1].split("#")[0].strip())
    need = _vertical_overlaps(execution, 7)
    for oid, raise_m in table.items():
        expected = 0.0 if oid not in need else np.ceil(round((need[oid] + RELEASE_CLEARANCE_M) * 100, 6)) / 100
        assert raise_m == pytest.approx(expected)
    assert max(table.values()) > 0


def test_an_unreachable_straight_lift_ends_where_the_line_is_still_reachable():
    src = UNREACHABLE.replace("height=0.42", "height=0.1").replace("move_up(0.12)", "move_up(0.4)")
    scene = Scene.resolve("sorting")
    _, before = check(src, scene)
    assert before.verdicts[0].critic == "runtime" and before.verdicts[0].evidence.lines == [4]
    r = repair(src, scene, goal="green_apple in white_box")
    assert r.errors == [] and r.execution.object_inside("green_apple", "white_box")
    [change] = [c for c in r.changes if c.critic == "runtime"]
    assert change.line == 4 and "move_up" in change.what
    lift = next(ln for ln in r.program.splitlines() if ln.startswith("move_up("))
    assert 0 < float(lift[len("move_up(") : -1]) < 0.4


# --- the in-line edits work on ast columns (UTF-8 bytes), also after non-ASCII text --------------

from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    label=st.text(alphabet=st.characters(blacklist_categories=("Cs", "Cc"), blacklist_characters='"\\'), max_size=8),
    z=st.floats(0.0, 0.5, allow_nan=False).map(lambda v: round(v, 3)),
    delta=st.floats(-0.2, 0.2, allow_nan=False).map(lambda v: round(v, 3)).filter(lambda v: v != 0),
)
def test_span_edits_replace_exactly_the_argument(label, z, delta):
    from robocritics.repair.builtin import _call_named, _shifted
    from robocritics.repair import apply_edits
    from robocritics.repair.edit import InsertText

    src = f'print("{label}"); move_to(0.3, 0.1, {z!r})  # ok\n'
    call = _call_named(ast.parse(src), 1, "move_to")
    ops = [InsertText(1, call.end_col_offset - 1, ', posture="natural"')]
    span = _shifted(src, call.args[2], delta)
    ops += [span] if span is not None else []
    out = apply_edits(src, ops)
    new = _call_named(ast.parse(out), 1, "move_to")
    assert [k.arg for k in new.keywords] == ["posture"] and new.keywords[0].value.value == "natural"
    assert ast.literal_eval(new.args[0]) == 0.3 and ast.literal_eval(new.args[1]) == 0.1
    # plain reference: the literal plus delta, rounded as the edit rounds it
    assert ast.literal_eval(new.args[2]) == pytest.approx(round(z + delta, 4))
    assert out.startswith(f'print("{label}"); ') and out.endswith("  # ok\n")
