"""The public API named in the design is importable from the package root, lazily, and nothing more."""

import subprocess
import sys

import pytest

import robocritics
from robocritics import errors

ROOT_NAMES = {
    "Robot",
    "Scene",
    "Trajectory",
    "Execution",
    "simulate",
    "check",
    "critique",
    "repair",
    "Report",
    "Verdict",
    "Flag",
    "Critic",
    "CriticParams",
    "Loop",
    "hookimpl",
}
ERROR_NAMES = {
    "RoboCriticsError",
    "SceneError",
    "ProgramError",
    "PlanningError",
    "TrajectoryError",
    "RobotModelError",
    "CriticError",
    "LLMError",
    "DeployError",
    "RTDEError",
}


def test_the_root_exports_exactly_the_designed_names():
    assert set(robocritics.__all__) == ROOT_NAMES | ERROR_NAMES
    assert len(robocritics.__all__) == len(set(robocritics.__all__))
    assert set(dir(robocritics)) >= ROOT_NAMES | ERROR_NAMES


def test_each_root_name_is_the_object_its_module_defines():
    from robocritics.critic import Critic, CriticParams, critique
    from robocritics.execution import Execution
    from robocritics.critic.hookspecs import hookimpl
    from robocritics.llm.loop import Loop
    from robocritics.critic.report import Report
    from robocritics.robot.model import Robot
    from robocritics.scene import Scene
    from robocritics.trajectory import Trajectory
    from robocritics.critic.verdict import Flag, Verdict

    from robocritics.repair import builtin  # noqa: F401  (submodules import under the function's name)
    from robocritics.pipeline import check, simulate
    repair_package = sys.modules["robocritics.repair"]
    expected = {
        "Robot": Robot,
        "Scene": Scene,
        "Trajectory": Trajectory,
        "Execution": Execution,
        "simulate": simulate,
        "check": check,
        "repair": repair_package.repair,
        "critique": critique,
        "Report": Report,
        "Verdict": Verdict,
        "Flag": Flag,
        "Critic": Critic,
        "CriticParams": CriticParams,
        "Loop": Loop,
        "hookimpl": hookimpl,
    }
    for name, obj in expected.items():
        assert getattr(robocritics, name) is obj, name
    assert callable(robocritics.simulate) and robocritics.simulate.__module__ == "robocritics.pipeline"
    assert callable(robocritics.repair) and "Repair" in robocritics.repair.__doc__
    assert repair_package.Repair is sys.modules["robocritics.repair.search"].Repair  # the package's lazy names
    for name in ERROR_NAMES:
        cls = getattr(robocritics, name)
        assert cls is getattr(errors, name), name
        assert issubclass(cls, errors.RoboCriticsError)


@pytest.mark.parametrize(
    "name, module",
    [
        ("State", "robocritics.trajectory"),
        ("Evidence", "robocritics.critic"),
        ("get_critics", "robocritics.critic"),
        ("critic_sources", "robocritics.critic"),
        ("URArm", "robocritics.deploy"),
        ("Attempt", "robocritics.llm"),
        ("OpenAICompatible", "robocritics.llm"),
    ],
)
def test_names_that_left_the_root_say_where_they_live(name, module):
    with pytest.raises(AttributeError, match=f"use `from {module} import {name}`"):
        getattr(robocritics, name)
    done = subprocess.run(
        [sys.executable, "-c", f"from {module} import {name}; print({name}.__name__)"], capture_output=True, text=True
    )
    assert done.returncode == 0 and done.stdout.strip() == name, done.stderr


def test_a_mistyped_root_name_suggests_the_right_one():
    with pytest.raises(AttributeError, match=r"no attribute 'Scen'; did you mean 'Scene'\?"):
        robocritics.Scen  # noqa: B018


def test_hookimpl_has_one_import_path():
    import robocritics.critic

    assert not hasattr(robocritics.critic, "hookimpl")
    assert "hookimpl" not in robocritics.critic.__all__


def test_import_is_lazy():
    code = "import sys, robocritics; print('pinocchio' in sys.modules, 'httpx' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "False"]


def test_python_dash_m_runs_the_cli():
    out = subprocess.run([sys.executable, "-m", "robocritics", "critics"], capture_output=True, text=True)
    assert out.returncode == 0
    for name in ("joint_speed", "space_usage", "collision", "end_effector_pose", "pinch_point"):
        assert name in out.stdout
