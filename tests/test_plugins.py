"""Plugins: entry-point discovery, a separately installed third-party critic, a broken plugin.

The example package ``examples/plugins/robocritics-cycle-time`` and a tiny broken
package (its module raises ImportError) are pip-installed into a temporary
directory; subprocesses with ``PYTHONPATH`` pointing there must discover the
first, skip the second with a warning naming it, and still run every critic.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import textwrap
import types
import warnings
from pathlib import Path

import pytest

import robocritics.critic
from robocritics import hookimpl
from robocritics.critic import plugins
from robocritics.critic import BUILTIN_CRITICS, CriticParams, Flag, Verdict, critique, get_critics
from robocritics.errors import CriticError
from robocritics.critic.plugins import PluginWarning, critic_sources, pm
from robocritics.scene import Scene
from synth import line_motion, make_trajectory

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "plugins" / "robocritics-cycle-time"
TESTS = Path(__file__).resolve().parent

BROKEN_PYPROJECT = """\
[build-system]
requires = ["setuptools>=61"]
build-backend = "setuptools.build_meta"

[project]
name = "robocritics-broken-example"
version = "0.0.1"

[project.entry-points.robocritics]
broken_critic = "robocritics_broken_example"

[tool.setuptools]
py-modules = ["robocritics_broken_example"]
"""

BROKEN_MODULE = 'raise ImportError("robocritics_broken_example needs the missing package not_installed_anywhere")\n'


def _offline_build_possible() -> bool:
    """setuptools can build a wheel without downloading anything (wheel installed, or setuptools >= 70.1)."""
    if importlib.util.find_spec("wheel") is not None:
        return True
    try:
        import setuptools

        major, minor = (int(x) for x in setuptools.__version__.split(".")[:2])
        return (major, minor) >= (70, 1)
    except Exception:
        return False


@pytest.fixture(scope="module")
def plugin_site(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("plugins")
    cycle = root / "robocritics-cycle-time"
    shutil.copytree(EXAMPLE, cycle, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    broken = root / "robocritics-broken-example"
    broken.mkdir()
    (broken / "pyproject.toml").write_text(BROKEN_PYPROJECT)
    (broken / "robocritics_broken_example.py").write_text(BROKEN_MODULE)
    site = root / "site"
    cmd = [sys.executable, "-m", "pip", "install", "--no-deps", "--quiet", "--disable-pip-version-check", "--target", str(site)]
    if _offline_build_possible():
        cmd.append("--no-build-isolation")  # fast, offline; otherwise pip fetches setuptools + wheel to build
    cmd += [str(cycle), str(broken)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    if done.returncode != 0:
        pytest.fail(f"pip could not install the example plugins:\n{done.stdout}\n{done.stderr}")
    assert any(p.name.startswith("robocritics_cycle_time") for p in site.iterdir())
    return site


def run_python(site: Path, code: str) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), str(TESTS)])
    env.pop("PYTHONWARNINGS", None)
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=env, timeout=300, cwd=str(site.parent))


def test_third_party_critic_is_discovered_and_the_broken_plugin_is_skipped_by_name(plugin_site):
    done = run_python(
        plugin_site,
        """
        import json
        from robocritics.critic import get_critics, critic_sources, plugin_errors
        critics = get_critics()
        print(json.dumps({"critics": list(critics), "sources": critic_sources(),
                          "errors": [[e.name, e.distribution, e.error] for e in plugin_errors]}))
        """,
    )
    assert done.returncode == 0, done.stderr
    import json

    data = json.loads(done.stdout)
    assert data["critics"][:5] == list(BUILTIN_CRITICS)
    assert "cycle_time" in data["critics"]
    assert data["sources"]["cycle_time"] == "robocritics-cycle-time"
    assert [e[0] for e in data["errors"]] == ["broken_critic"]
    assert data["errors"][0][1] == "robocritics-broken-example 0.0.1"
    assert "ImportError" in data["errors"][0][2] and "not_installed_anywhere" in data["errors"][0][2]
    assert "broken_critic" in done.stderr and "PluginWarning" in done.stderr


def test_cli_lists_the_plugin_critic_and_the_failed_plugin(plugin_site):
    done = run_python(plugin_site, "import sys; from robocritics.cli import main; sys.exit(main(['critics']))")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    row = next(l for l in lines if l.startswith("cycle_time"))
    assert "robocritics-cycle-time 0.1.0" in row and "cycle time" in row
    for name in BUILTIN_CRITICS:
        assert any(l.startswith(name) for l in lines)
    failed = done.stdout.split("Failed plugins")[1]
    assert "broken_critic from robocritics-broken-example 0.0.1: ImportError" in failed
    # and the same through `python -m robocritics.cli`
    env = dict(os.environ, PYTHONPATH=str(plugin_site))
    done = subprocess.run([sys.executable, "-m", "robocritics.cli", "critics"], capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0 and "cycle_time" in done.stdout and "broken_critic" in done.stdout


def test_critique_runs_the_plugin_critic_alongside_the_builtins(plugin_site):
    done = run_python(
        plugin_site,
        """
        import json
        import numpy as np
        from robocritics.critic import critique
        from robocritics.scene import Scene
        from synth import make_trajectory
        time = np.linspace(0.0, 50.0, 501)   # a 50 s program: over the 45 s target
        pos = np.zeros((501, 1, 3)) + [0.2, 0.0, 0.2]
        traj = make_trajectory(time, pos)
        report = critique(traj, Scene())
        print(json.dumps({"critics": report.critics, "flag": report.flag_of("cycle_time").value,
                          "message": report.verdict("cycle_time").message, "score": report.score,
                          "beside": [v.critic for v in report.other_verdicts], "passed": report.passed}))
        report = critique(traj, Scene(), critics=["cycle_time"], params={"cycle_time": {"max_cycle_time_s": 40, "target_cycle_time_s": 30}})
        print(report.flag_of("cycle_time").value)
        """,
    )
    assert done.returncode == 0, done.stderr
    import json

    first, second = done.stdout.strip().splitlines()
    data = json.loads(first)
    assert data["critics"] == list(BUILTIN_CRITICS) + ["cycle_time"]
    assert data["flag"] == "WARNING" and "50.0 s" in data["message"]
    assert data["score"] == 10  # the five motion critics' index; the plugin's warning stands beside it
    assert data["beside"] == ["cycle_time"] and data["passed"] is False
    assert second == "ERROR"


# --- in-process registration ------------------------------------------------------------


class _Echo:
    description = "test critic"

    class Params(CriticParams):
        pass

    def __init__(self, name):
        self.name = name

    def check(self, trajectory, scene, params):
        return Verdict(critic=self.name, flag=Flag.OK, message="fine")


def _plugin(register_body):
    mod = types.ModuleType("fake_plugin")
    mod.register_critics = hookimpl(register_body)
    return mod


@pytest.fixture
def registered():
    added = []

    def add(name, body):
        mod = _plugin(body)
        pm.register(mod, name=name)
        added.append(mod)
        return mod

    yield add
    for mod in added:
        pm.unregister(mod)
    get_critics()  # refresh the cache for later tests


def test_a_plugin_registered_at_runtime_is_picked_up(registered):
    registered("runtime_plugin", lambda register: register(_Echo("echo")))
    assert "echo" in get_critics()
    assert critic_sources()["echo"] == ""
    time, pos = line_motion(0.1)
    r = critique(make_trajectory(time, pos), Scene(), critics=["echo"])
    assert r.flag_of("echo") is Flag.OK


def test_a_plugin_whose_hook_fails_is_skipped_with_a_warning(registered, caplog):
    def boom(register):
        raise RuntimeError("cannot start")

    registered("exploding_plugin", boom)
    with pytest.warns(PluginWarning, match="exploding_plugin.*RuntimeError: cannot start"):
        critics = get_critics()
    assert set(BUILTIN_CRITICS) <= set(critics)
    assert any(e.name == "exploding_plugin" for e in plugins.plugin_errors)
    # and it is logged, on the plugins' logger
    logged = [r for r in caplog.records if r.name == "robocritics.critic.plugins" and r.levelname == "WARNING"]
    assert any("exploding_plugin" in r.getMessage() and "cannot start" in r.getMessage() for r in logged)


def test_bad_and_duplicate_critics_are_rejected_by_name(registered):
    class NoParams:
        name = "no_params"
        description = "x"

        def check(self, *a):
            return None

    def body(register):
        register(NoParams())
        register(_Echo("joint_speed"))  # name taken by the built-in
        register(_Echo("fine_one"))

    registered("mixed_plugin", body)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        critics = get_critics()
    text = " ".join(str(w.message) for w in caught)
    assert "no_params" in text and "Params" in text
    assert "'joint_speed' is already provided by robocritics" in text
    assert "fine_one" in critics and "no_params" not in critics
    assert critics["joint_speed"].__class__.__module__ == "robocritics.critic.builtin.joint_speed"


# --- registering a critic in a notebook ---------------------------------------------------


class _Slow:
    """A notebook-style critic: warns when the motion lasts longer than ``limit_s``."""

    name = "slow_motion"
    description = "motion duration against a limit"

    class Params(CriticParams):
        limit_s: float = 0.5

    def check(self, trajectory, scene, params):
        flag = Flag.WARNING if trajectory.duration_s > params.limit_s else Flag.OK
        return Verdict(critic=self.name, flag=flag, message=f"{trajectory.duration_s:.1f} s")


@pytest.fixture
def notebook_critics():
    yield robocritics.critic.register
    for name in ("slow_motion",):
        robocritics.critic.unregister(name)
    assert "slow_motion" not in get_critics()


def test_register_adds_a_critic_that_critique_runs_by_default(notebook_critics):
    traj = make_trajectory(*line_motion(0.1))  # 1 s
    critic = notebook_critics(_Slow())
    assert isinstance(critic, _Slow)
    assert get_critics()["slow_motion"] is critic and critic_sources()["slow_motion"] == ""
    assert list(get_critics())[:5] == list(BUILTIN_CRITICS)
    report = critique(traj, Scene())  # every installed critic: the five, any plugin's, then this one
    assert report.critics[:5] == list(BUILTIN_CRITICS) and report.critics[-1] == "slow_motion"
    assert report.flag_of("slow_motion") is Flag.WARNING
    assert report.other_verdicts[-1].critic == "slow_motion"
    assert report.score == critique(traj, Scene(), critics=BUILTIN_CRITICS).score
    # re-running the notebook cell (with an edited critic) replaces it
    class Patient(_Slow):
        class Params(CriticParams):
            limit_s: float = 2.0

    notebook_critics(Patient())
    assert critique(traj, Scene(), critics=["slow_motion"]).flag_of("slow_motion") is Flag.OK
    assert list(get_critics()).count("slow_motion") == 1


def test_register_validates_at_once_and_refuses_an_installed_name(notebook_critics):
    class NoCheck:
        name = "slow_motion"
        description = "x"
        Params = CriticParams

    with pytest.raises(CriticError, match="critic 'slow_motion' has no `check`"):
        notebook_critics(NoCheck())
    with pytest.raises(CriticError, match="_Slow is a class; pass an instance"):
        notebook_critics(_Slow)
    impostor = _Slow()
    impostor.name = "joint_speed"
    with pytest.raises(CriticError, match="'joint_speed' is already provided by robocritics"):
        notebook_critics(impostor)
    assert get_critics()["joint_speed"].__class__.__module__ == "robocritics.critic.builtin.joint_speed"
    assert "slow_motion" not in get_critics()


def test_a_distributions_metadata_is_read_once_for_all_its_entry_points(tmp_path):
    from importlib.metadata import PathDistribution

    info = tmp_path / "demo_critics-1.2.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: demo-critics\nVersion: 1.2\n")
    (info / "entry_points.txt").write_text("[robocritics]\nfirst = demo_first\nsecond = demo_second\n")
    first, second = PathDistribution(info).entry_points
    assert first.dist is second.dist  # one distribution object for a package's entry points
    assert plugins._dist_of(first) == ("demo-critics", "1.2")
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: renamed\nVersion: 9\n")
    assert plugins._dist_of(second) == ("demo-critics", "1.2")  # the same distribution: not parsed again
    (again,) = [ep for ep in PathDistribution(info).entry_points if ep.name == "first"]
    assert plugins._dist_of(again) == ("renamed", "9")  # another distribution object reads its own file
    (info / "METADATA").unlink()
    (bare,) = [ep for ep in PathDistribution(info).entry_points if ep.name == "first"]
    assert plugins._dist_of(bare) == ("", "")  # no metadata: an unknown package, as before


def test_a_run_contract_critic_and_the_old_contract_plugin_in_one_report(plugin_site):
    """The example plugin keeps ``check(trajectory, scene, params)``; a critic of the run contract
    ``check(execution, params)`` reads the plan and the robot; both judge the same run in one report."""
    done = run_python(
        plugin_site,
        """
        import json
        from pydantic import Field
        from robocritics import Robot, Scene, critique, simulate
        from robocritics.critic import CriticParams, Flag, Verdict, register, takes_execution, get_critics

        class SkillCount:
            name = "skill_count"
            description = "Number of skill calls in the program's plan against a budget."

            class Params(CriticParams):
                max_calls: int = Field(3, ge=0, description="most skill calls allowed (count)")

            def check(self, execution, params):
                calls = len(execution.plan.calls) if execution.plan is not None else 0
                flag = Flag.WARNING if calls > params.max_calls else Flag.OK
                return Verdict(critic=self.name, flag=flag, message=f"{calls} calls on the {execution.robot.name}",
                               value=float(calls), threshold=float(params.max_calls), unit="calls")

        register(SkillCount())
        run = simulate("move_to(green_apple)\\nhome()\\nhome()\\nhome()\\n", Scene.builtin("sorting"), Robot.ur3e())
        report = critique(run, critics=["skill_count", "cycle_time"],
                          params={"cycle_time": {"max_cycle_time_s": 1.0, "target_cycle_time_s": 0.5}})
        print(json.dumps({"critics": report.critics, "flags": [v.flag.value for v in report.verdicts],
                          "message": report.verdict("skill_count").message,
                          "contracts": [takes_execution(get_critics()[n]) for n in report.critics]}))
        """,
    )
    assert done.returncode == 0, done.stderr
    import json

    data = json.loads(done.stdout)
    assert data["critics"] == ["skill_count", "cycle_time"]
    assert data["contracts"] == [True, False]
    assert data["flags"] == ["WARNING", "ERROR"]  # 4 calls > 3; the motion takes longer than 1 s
    assert data["message"] == "4 calls on the ur3e"
