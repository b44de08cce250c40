"""pinch_point: self pairs only (non-adjacent arm links, arm vs gripper)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from critic_asserts import assert_matches_reference, assert_well_formed, critic, run, execution_of
from critic_reference import ref_pinch_point
from robocritics.critic import Flag
from robocritics.trajectory import Step
from strategies import trajectories
from synth import env_pair, make_trajectory, self_pair

T = 60
TIME = np.arange(T) / 125.0


def folded(distance, pairs=None, steps=None, step=None):
    pairs = pairs or [self_pair("forearm_link", "wrist_3_link"), self_pair("upper_arm_link", "left_finger", group_b="gripper")]
    prox = np.full((T, len(pairs)), 0.3)
    prox[25:35, 0] = distance
    return make_trajectory(TIME, np.zeros((T, 1, 3)), pairs=pairs, proximity=prox, steps=steps, step=step)


def test_folded_elbow_at_2_cm_errs():
    steps = [Step(skill="move_to", line=3), Step(skill="move_to", line=8)]
    v = run("pinch_point", folded(0.02, steps=steps, step=(np.arange(T) >= 20).astype(int)))
    assert v.flag is Flag.ERROR
    assert v.value == pytest.approx(0.02) and v.threshold == 0.025 and v.unit == "m"
    assert "forearm_link" in v.message and "wrist_3_link" in v.message and "2.0 cm" in v.message
    assert v.evidence.links == ["forearm_link", "wrist_3_link"]
    assert v.evidence.lines == [8] and (v.evidence.first_sample, v.evidence.last_sample) == (25, 34)
    assert_well_formed(v, "pinch_point")


def test_folded_elbow_at_4_cm_warns_at_10_cm_is_ok():
    v = run("pinch_point", folded(0.04))
    assert v.flag is Flag.WARNING and v.threshold == 0.06
    assert_well_formed(v, "pinch_point")
    assert run("pinch_point", folded(0.10)).flag is Flag.OK


def test_environment_pairs_never_trigger_pinch_point():
    pairs = [env_pair("left_finger", "apple"), env_pair("forearm_link", "table", group_a="arm", group_b="table")]
    v = run("pinch_point", folded(0.02, pairs=pairs))
    assert v.flag is Flag.OK and v.value is None
    mixed = [env_pair("left_finger", "apple"), self_pair("forearm_link", "wrist_3_link")]
    prox = np.full((T, 2), 0.3)
    prox[:, 0] = 0.001  # environment pair very close: irrelevant here
    traj = make_trajectory(TIME, np.zeros((T, 1, 3)), pairs=mixed, proximity=prox)
    v = run("pinch_point", traj)
    assert v.flag is Flag.OK and v.value == pytest.approx(0.3)


def test_touching_parts_say_so():
    v = run("pinch_point", folded(-0.004))
    assert v.flag is Flag.ERROR and "touch" in v.message


@st.composite
def params(draw):
    lo = draw(st.floats(0.0, 0.08))
    return {"d_min_m": lo, "d_max_m": lo + draw(st.floats(0.001, 0.08))}


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(traj=trajectories(), overrides=params())
def test_agrees_with_the_per_sample_reference(traj, overrides):
    c = critic("pinch_point")
    p = c.Params(**overrides)
    v = c.check(execution_of(traj), p)
    assert_matches_reference(v, ref_pinch_point(traj, p))
    assert_well_formed(v, "pinch_point")
