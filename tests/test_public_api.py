"""The public API named in the design is importable from the package root, lazily."""

import subprocess
import sys

import robocritics


def test_every_public_name_resolves():
    for name in robocritics.__all__:
        assert getattr(robocritics, name) is not None, name
    assert issubclass(robocritics.PlanningError, robocritics.RoboCriticsError)
    assert issubclass(robocritics.DeployError, robocritics.RoboCriticsError)


def test_import_is_lazy():
    code = "import sys, robocritics; print('pinocchio' in sys.modules, 'httpx' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "False"]


def test_python_dash_m_runs_the_cli():
    out = subprocess.run([sys.executable, "-m", "robocritics", "critics"], capture_output=True, text=True)
    assert out.returncode == 0
    for name in ("joint_speed", "space_usage", "collision", "end_effector_pose", "pinch_point"):
        assert name in out.stdout
