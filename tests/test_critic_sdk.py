"""critique(): selection by name, parameter overrides and their errors, the Critic protocol."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import BaseModel, Field

from robocritics.critic import (
    BUILTIN_CRITICS,
    Critic,
    CriticParams,
    Flag,
    Verdict,
    critic_sources,
    critique,
    get_critics,
    select_critics,
)
from robocritics.critic.builtin.joint_speed import Params as JointSpeedParams
from robocritics.errors import CriticError
from robocritics.scene import Scene, Workspace
from robocritics.execution import Execution
from robocritics.robot.model import default_workspace
from synth import line_motion, make_trajectory, realistic_trajectory


@pytest.fixture(scope="module")
def traj():
    time, pos = line_motion(1.2)
    return make_trajectory(time, pos)


def test_the_five_builtins_come_from_the_package_entry_points():
    critics = get_critics()
    assert list(critics)[:5] == list(BUILTIN_CRITICS)
    sources = critic_sources()
    for name in BUILTIN_CRITICS:
        assert sources[name] == "robocritics"
        assert isinstance(critics[name], Critic)


@pytest.mark.parametrize("name", BUILTIN_CRITICS)
def test_params_document_every_threshold(name):
    c = get_critics()[name]
    assert c.description and c.name == name
    params = c.Params()  # every field has a default
    for field, info in c.Params.model_fields.items():
        assert info.description, f"{name}.{field} has no description"
        if isinstance(getattr(params, field), float):
            unit_said = any(u in field for u in ("_m", "_s", "fraction", "tolerance")) or " m" in info.description
            assert unit_said, f"{name}.{field}: say the unit in the name or description"
    # source of each number
    text = " ".join((info.description or "") for info in c.Params.model_fields.values())
    assert "source" in text or "CoFrame" in text or "paper" in text


def test_select_by_name_in_order_and_comma_string(traj):
    r = critique(traj, Scene(), critics=["pinch_point", "joint_speed"])
    assert r.critics == ["pinch_point", "joint_speed"]
    r = critique(traj, Scene(), critics="joint_speed, collision,joint_speed")
    assert r.critics == ["joint_speed", "collision"]


def test_unknown_critic_name_suggests_the_closest(traj):
    with pytest.raises(CriticError, match=r"unknown critic 'joint_sped'; did you mean 'joint_speed'\?"):
        critique(traj, Scene(), critics=["joint_sped"])
    with pytest.raises(CriticError, match="no critics selected"):
        critique(traj, Scene(), critics=[])


def test_params_override_any_threshold(traj):
    assert critique(traj, Scene(), critics=["joint_speed"]).flag_of("joint_speed") is Flag.WARNING
    r = critique(traj, Scene(), critics=["joint_speed"], params={"joint_speed": {"warn_speed_m_s": 1.3}})
    assert r.flag_of("joint_speed") is Flag.OK
    assert r.params["joint_speed"]["warn_speed_m_s"] == 1.3
    r = critique(traj, Scene(), critics=["joint_speed"], params={"joint_speed": JointSpeedParams(warn_speed_m_s=0.5, max_speed_m_s=1.0)})
    assert r.flag_of("joint_speed") is Flag.ERROR


@pytest.mark.parametrize(
    "params, match",
    [
        ({"joint_speed": {"warn_speed_m_s": "fast"}}, r"critic 'joint_speed'.*warn_speed_m_s.*valid number"),
        ({"joint_speed": {"warn_speed_m_s": -1}}, r"critic 'joint_speed'.*warn_speed_m_s.*greater than 0"),
        ({"joint_speed": {"warn_speed": 1.0}}, r"unknown parameter 'warn_speed'; did you mean 'warn_speed_m_s'\? \(its parameters: warn_speed_m_s, "),
        ({"joint_speed": {"warn_speed_m_s": 2.0}}, r"critic 'joint_speed'.*must not exceed max_speed_m_s"),
        ({"joint_sped": {}}, r"params given for unknown critic 'joint_sped'; did you mean 'joint_speed'"),
        ({"joint_speed": 3}, r"params for critic 'joint_speed' must be a mapping"),
        ({"joint_speed": get_critics()["collision"].Params()}, r"must be a dict or Params of that critic"),
    ],
)
def test_invalid_params_name_the_critic_and_field(traj, params, match):
    with pytest.raises(CriticError, match=match):
        critique(traj, Scene(), params=params)
    with pytest.raises(CriticError, match=match):
        select_critics(None, params)


class Always:
    """An ad-hoc critic object, passed to critique() without registering it."""

    name = "always"
    description = "always warns"

    class Params(CriticParams):
        level: str = Field("WARNING", description="flag to give")

    def check(self, trajectory, scene, params):
        return Verdict(critic=self.name, flag=Flag(params.level), message="as configured")


def test_critic_objects_can_be_passed_directly(traj):
    r = critique(traj, Scene(), critics=[Always(), "pinch_point"], params={"always": {"level": "ERROR"}})
    assert r.critics == ["always", "pinch_point"]
    assert r.flag_of("always") is Flag.ERROR and r.flag_of("pinch_point") is Flag.OK
    # the score is the motion critics' index (pinch_point alone here, scaled); `always` is beside it
    assert r.score == 10.0
    assert [v.critic for v in r.other_verdicts] == ["always"]
    assert r.has_errors and not r.passed
    assert "beside the score: always Error" in r.summary()


class NoParams:
    name = "no_params"
    description = "forgot its thresholds"

    def check(self, trajectory, scene, params):
        return Verdict(critic=self.name, flag=Flag.OK, message="fine")


class NoCheck:
    name = "no_check"
    description = "forgot to judge"
    Params = CriticParams


class Nameless:
    description = "no name"
    Params = CriticParams

    def check(self, trajectory, scene, params):
        return Verdict(critic="?", flag=Flag.OK, message="fine")


class Defaultless(Always):
    name = "defaultless"

    class Params(CriticParams):
        limit_m: float = Field(description="no default, m")


@pytest.mark.parametrize(
    "critic, match",
    [
        (NoParams(), r"critic 'no_params' has no `Params`"),
        (NoCheck(), r"critic 'no_check' has no `check`"),
        (Nameless(), r"needs a `name`.*got None"),
        (Defaultless(), r"critic 'defaultless': every field of Params needs a default"),
        (Always, r"Always is a class; pass an instance: Always\(\)"),
        (42, r"needs a `name`"),
    ],
)
def test_an_ad_hoc_critic_is_validated_like_a_registered_one(traj, critic, match):
    with pytest.raises(CriticError, match=match):
        critique(traj, Scene(), critics=[critic])


def test_critique_takes_an_execution_and_its_scene():
    traj = make_trajectory(*line_motion(0.1))  # 0.1 m, about 0.3 m from the shoulder
    inside = Scene()
    tiny = Scene(workspace=default_workspace().model_copy(update={"radius_m": 0.05}))  # the motion is outside it
    execution = Execution(trajectory=traj, plan=None, events=[], final_scene=tiny, scene=tiny, robot=None)
    r = critique(execution, critics=["space_usage"])
    assert r.flag_of("space_usage") is Flag.ERROR  # judged in the execution's scene
    assert r.trajectory_hash == traj.content_hash()
    assert r == critique(traj, tiny, critics=["space_usage"])
    assert critique(execution, inside, critics=["space_usage"]).flag_of("space_usage") is Flag.OK  # an explicit scene wins


def test_critique_needs_a_trajectory_and_a_scene(traj):
    with pytest.raises(CriticError, match=r"needs the scene"):
        critique(traj, critics=["joint_speed"])
    with pytest.raises(CriticError, match=r"judges a Trajectory or an Execution, got dict"):
        critique({"q": []}, Scene())


def test_a_failing_critic_is_named(traj):
    class Broken(Always):
        name = "broken"

        def check(self, trajectory, scene, params):
            raise ZeroDivisionError("oops")

    class Liar(Always):
        name = "liar"

        def check(self, trajectory, scene, params):
            return {"flag": "OK"}

    with pytest.raises(CriticError, match="critic 'broken' failed: ZeroDivisionError: oops"):
        critique(traj, Scene(), critics=[Broken()])
    with pytest.raises(CriticError, match="critic 'liar' returned dict"):
        critique(traj, Scene(), critics=[Liar()])


def test_checks_are_pure_and_deterministic():
    traj = realistic_trajectory(duration_s=3.0, rate_hz=250.0, n_waypoints=3)
    before = {k: getattr(traj, k).copy() for k in ("q", "time", "frames", "proximity", "step")}
    a = critique(traj, Scene.builtin("sorting"), critics=BUILTIN_CRITICS)
    b = critique(traj, Scene.builtin("sorting"), critics=BUILTIN_CRITICS)
    assert a == b
    for k, arr in before.items():
        np.testing.assert_array_equal(getattr(traj, k), arr)


def test_verdict_is_immutable_and_validated():
    v = Verdict(critic="x", flag="WARNING", message="m")
    assert v.flag is Flag.WARNING
    with pytest.raises(Exception):
        v.flag = Flag.OK
    with pytest.raises(Exception):
        Verdict(critic="x", flag="BAD", message="m")


def test_the_contract_is_told_apart_by_arity_and_anything_else_is_refused(traj):
    from robocritics.critic import takes_execution

    class RunContract(Always):
        name = "run_contract"

        def check(self, execution, params):
            assert execution.plan is None and execution.robot is None and execution.source == "trajectory"
            return Verdict(critic=self.name, flag=Flag.OK, message=f"{len(execution.trajectory)} samples")

    class TwoMany(Always):
        name = "too_many"

        def check(self, a, b, c, d):
            raise AssertionError("never called")

    assert takes_execution(RunContract()) and not takes_execution(Always())
    r = critique(traj, Scene(), critics=[RunContract(), Always()])
    assert r.critics == ["run_contract", "always"] and r.verdict("run_contract").message == f"{len(traj)} samples"
    with pytest.raises(CriticError, match=r"takes 4 parameters; a critic's check is check\(execution, params\)"):
        critique(traj, Scene(), critics=[TwoMany()])


def test_an_on_demand_critic_runs_when_the_run_asks_or_when_named(traj):
    class OnDemand(Always):
        name = "on_demand"

        def requested(self, execution):
            return execution.trajectory.duration_s > 100.0

    from robocritics.critic import register, unregister

    register(OnDemand())
    try:
        assert "on_demand" not in critique(traj, Scene()).critics  # not asked for by this 1-s run
        assert "on_demand" in critique(traj, Scene(), critics=["on_demand"]).critics  # named
    finally:
        unregister("on_demand")
