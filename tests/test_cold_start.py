"""First-use work of a cold ``robocritics check``, made cheaper, against the plain computations it replaced."""

from __future__ import annotations

import numpy as np
import pytest

from robocritics import Robot
from robocritics.robot.arms import ARMS, UR3E
from robocritics.robot.ik import ur_reach
from robocritics.robot.model import _SAME_HOUSING_GAP_M
from robocritics.geometry.kernels import capsule_capsule

BUNDLED = [*ARMS, "panda"]


def robot_named(name: str) -> Robot:
    return Robot.panda() if name == "panda" else Robot.ur(name)


def self_pairs_one_by_one(robot: Robot) -> tuple[tuple[str, str], ...]:
    """The reference: every non-adjacent capsule pair not both on the gripper, one distance call per pair at
    q = 0, kept unless closer than the same-housing gap."""
    parent_of = {name: int(robot._frame_parent[i]) for i, name in enumerate(robot.frame_names)}
    parents = robot._joint_parents
    p0, p1 = robot.capsule_segments(robot.forward(np.zeros((1, robot.n))))
    pairs = []
    for i, ci in enumerate(robot.capsules):
        for j in range(i + 1, len(robot.capsules)):
            cj = robot.capsules[j]
            ji, jj = parent_of[ci.frame], parent_of[cj.frame]
            if (ci.group == cj.group == "gripper") or ji == jj or parents[ji] == jj or parents[jj] == ji:
                continue
            d = capsule_capsule(p0[:, i], p1[:, i], ci.radius_m, p0[:, j], p1[:, j], cj.radius_m)[0]
            if d >= _SAME_HOUSING_GAP_M:
                pairs.append((ci.name, cj.name))
    return tuple(pairs)


@pytest.mark.parametrize("name", BUNDLED)
def test_default_self_pairs_are_the_pairs_measured_one_by_one(name):
    robot = robot_named(name)
    reference = self_pairs_one_by_one(robot)
    assert reference  # every bundled arm has pinch-point pairs
    assert robot.self_pairs == reference


@pytest.mark.parametrize("name", list(ARMS))
def test_each_ur_arms_home_is_the_ur3e_home_scaled_by_reach(name):
    robot = Robot.ur(name)
    scale = ur_reach(ARMS[name].dh) / ur_reach(UR3E.dh)
    np.testing.assert_allclose(robot.tcp_pose(robot.home_q)[:3, 3], [0.25 * scale, 0.0, 0.25 * scale], atol=1e-9)
    assert (scale == 1.0) == (name == "ur3e")


def test_the_command_freezes_its_objects_at_exit_and_still_finishes_every_output(tmp_path):
    """Run as the process's command (argv None), main() ends with gc.freeze(): the report, the --html file,
    atexit handlers and a weakref.finalize callback all still complete, and the exit status is kept."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    out = tmp_path / "replay.html"
    script = f"""
import atexit, gc, sys, weakref
class Held: pass
held = Held()
weakref.finalize(held, print, "finalized", file=sys.stderr)
atexit.register(print, "atexit ran", file=sys.stderr)
sys.argv = ["robocritics", "check", {str(root / 'examples/programs/sorting_careful.py')!r}, "--scene", "sorting",
            "--html", {str(out)!r}]
from robocritics.cli import main
status = main()
print("frozen", gc.get_freeze_count() > 0, file=sys.stderr)
sys.exit(status)
"""
    done = subprocess.run([sys.executable, "-c", script], cwd=root, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("RoboCritics report: score 10/10")
    assert "frozen True" in done.stderr and "atexit ran" in done.stderr and "finalized" in done.stderr
    assert out.read_text().rstrip().endswith("</html>")


def test_main_with_an_argv_leaves_the_callers_garbage_collector_alone(capsys):
    import gc

    from robocritics.cli import main

    before = gc.get_freeze_count()
    assert main(["critics"]) == 0
    assert "space_usage" in capsys.readouterr().out
    assert gc.get_freeze_count() == before


def test_check_runs_with_the_collector_paused_and_restores_it():
    """In a fresh interpreter, a check's imports create tens of thousands of objects (a hundred collections
    with the collector on): paused, at most the one due when it is back on runs."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    script = f"""
import gc, sys
from robocritics.cli import main
collections = []
gc.callbacks.append(lambda phase, info: phase == "start" and collections.append(info["generation"]))
status = main(["check", {str(root / 'examples/programs/sorting_naive.py')!r}, "--scene", "sorting"])
print(status, gc.isenabled(), len(collections), file=sys.stderr)
gc.disable()
main(["check", {str(root / 'examples/programs/sorting_naive.py')!r}, "--scene", "sorting"])
print(gc.isenabled(), file=sys.stderr)
"""
    done = subprocess.run([sys.executable, "-c", script], cwd=root, capture_output=True, text=True, timeout=300)
    first, second = done.stderr.strip().splitlines()[-2:]
    status, enabled, collections = first.split()
    assert (status, enabled) == ("1", "True")  # sorting_naive has an Error; the collector is back on
    assert int(collections) <= 1
    assert second == "False"  # a caller that turned it off keeps it off
