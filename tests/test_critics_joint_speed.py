"""joint_speed: paper Algorithm 1 (link linear speed) plus angular joint speed against limits."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from critic_asserts import assert_matches_reference, assert_well_formed, critic, run, execution_of
from critic_reference import ref_joint_speed
from robocritics.critic import Flag
from robocritics.trajectory import Step
from strategies import trajectories
from synth import FRAME_NAMES, frames_from, line_motion, make_trajectory


def moving_link(speed, rate_hz=125.0, frame="wrist_3_link", steps=None, step=None):
    """12 frames; every frame still except ``frame``, which moves at ``speed`` m/s along x."""
    time, pos = line_motion(speed, rate_hz=rate_hz)
    T = len(time)
    positions = np.tile(np.array([0.1, 0.0, 0.2]), (T, len(FRAME_NAMES), 1))
    positions[:, FRAME_NAMES.index(frame)] = pos[:, 0]
    return make_trajectory(time, positions, steps=steps, step=step)


def test_slow_link_is_ok():
    v = run("joint_speed", moving_link(0.5))
    assert v.flag is Flag.OK
    assert v.value == pytest.approx(0.5)
    assert_well_formed(v, "joint_speed")


def test_link_at_1_2_m_s_warns_in_the_papers_words():
    steps = [Step(skill="home", line=2), Step(skill="move_to", line=4), Step(skill="move_to", line=5), Step(skill="move_to", line=6)]
    time, _ = line_motion(1.2)
    step = np.minimum(np.arange(len(time)) * 4 // len(time), 3)
    step[0] = 0
    step[1:] = np.maximum(step[1:], 1)  # every moving sample belongs to lines 4-6
    v = run("joint_speed", moving_link(1.2, steps=steps, step=step))
    assert v.flag is Flag.WARNING
    assert v.value == pytest.approx(1.2)
    assert v.threshold == 1.0 and v.unit == "m/s"
    assert v.message.startswith("Joint speed is higher than the recommended value of 1 m/s (1.20 m/s at the wrist_3_link")
    assert v.hint == (
        "To minimize joint speed, you can consider reducing the speed of the robot during [move_to] actions on lines 4-6. "
        "This potentially increases the cycle time of the program."
    )
    assert v.evidence.lines == [4, 5, 6]
    assert v.evidence.skills == ["move_to"]
    assert v.evidence.links == ["wrist_3_link"]
    assert v.evidence.first_sample == 1 and v.evidence.last_sample == len(time) - 1
    assert_well_formed(v, "joint_speed")


def test_link_at_2_m_s_errs():
    v = run("joint_speed", moving_link(2.0, frame="forearm_link"))
    assert v.flag is Flag.ERROR
    assert v.value == pytest.approx(2.0)
    assert v.threshold == 1.5
    assert "maximum allowed speed of 1.5 m/s" in v.message and "forearm_link" in v.message
    assert_well_formed(v, "joint_speed")


def test_joint_over_its_limit_errs_within_tolerance_does_not():
    time = np.arange(126) / 125.0
    for factor, expected in ((1.005, Flag.OK), (1.05, Flag.ERROR)):
        q = np.zeros((len(time), 6))
        q[:, 2] = math.pi * factor * time  # elbow at factor x its limit
        traj = make_trajectory(time, np.zeros((len(time), 1, 3)), q=q)
        v = run("joint_speed", traj)
        assert v.flag is expected, (factor, v.message)
    assert "elbow_joint" in v.message and v.unit == "rad/s"
    assert v.value == pytest.approx(math.pi * 1.05)
    assert v.threshold == pytest.approx(math.pi)


def test_same_motion_at_125_and_500_hz_gives_the_same_speed():
    slow = run("joint_speed", moving_link(1.2, rate_hz=125))
    fast = run("joint_speed", moving_link(1.2, rate_hz=500))
    assert slow.flag is fast.flag is Flag.WARNING
    assert slow.value == pytest.approx(fast.value)


def test_speed_uses_physical_time_not_sample_count():
    # uneven sampling: 1 cm in 10 ms then 1 cm in 5 ms -> 1 m/s then 2 m/s
    time = np.array([0.0, 0.010, 0.015])
    pos = np.array([[[0, 0, 0.2]], [[0.01, 0, 0.2]], [[0.02, 0, 0.2]]])
    v = run("joint_speed", make_trajectory(time, pos))
    assert v.value == pytest.approx(2.0)
    assert v.evidence.worst_sample == 2


def test_frames_parameter_restricts_the_check():
    v = run("joint_speed", moving_link(2.0, frame="tcp"), frames=("base_link", "forearm_link"))
    assert v.flag is Flag.OK and v.value == 0.0


def test_single_sample_is_ok():
    v = run("joint_speed", make_trajectory([0.0], np.zeros((1, 1, 3))))
    assert v.flag is Flag.OK


def test_signal_is_downsampled_and_keeps_the_peak():
    time = np.arange(5001) / 500.0
    x = 0.1 * np.sin(time)  # slow...
    x[2500:] += 0.004  # ...with one 2 m/s jump between samples 2499 and 2500
    pos = np.stack([x, np.zeros_like(x), np.full_like(x, 0.2)], axis=-1)[:, None, :]
    v = run("joint_speed", make_trajectory(time, pos))
    assert len(v.signal.time_s) <= 400
    assert max(v.signal.value) == pytest.approx(v.value)
    assert v.flag is Flag.ERROR


@st.composite
def params(draw):
    warn = draw(st.floats(0.1, 2.0))
    return {"warn_speed_m_s": warn, "max_speed_m_s": warn * draw(st.floats(1.0, 2.0)), "joint_limit_tolerance": draw(st.sampled_from([0.0, 0.01, 0.2]))}


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(traj=trajectories(), overrides=params())
def test_agrees_with_the_per_sample_reference(traj, overrides):
    c = critic("joint_speed")
    p = c.Params(**overrides)
    v = c.check(execution_of(traj), p)
    assert_matches_reference(v, ref_joint_speed(traj, p))
    assert_well_formed(v, "joint_speed")


@settings(max_examples=100, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), T=st.integers(2, 200), L=st.integers(1, 13))
def test_link_speeds_are_the_per_sample_distance_over_time(seed, T, L):
    from robocritics.critic.builtin.joint_speed import link_speeds

    rng = np.random.default_rng(seed)
    X = rng.normal(scale=rng.choice([1e-4, 0.3, 5.0]), size=(T, L, 3))
    time = np.cumsum(rng.uniform(1e-3, 1e-2, size=T))
    want = np.array(
        [[np.linalg.norm(X[i + 1, k] - X[i, k]) / (time[i + 1] - time[i]) for k in range(L)] for i in range(T - 1)]
    )
    np.testing.assert_allclose(link_speeds(X, time), want, rtol=1e-14, atol=0)


@settings(max_examples=200, deadline=None)
@given(
    steps=st.lists(st.lists(st.sampled_from([0.0, 0.01, -0.01, 0.02, 0.005]), min_size=3, max_size=3), min_size=1, max_size=12),
    limits=st.lists(st.sampled_from([0.0, 1.0, 2.0, 0.5]), min_size=3, max_size=3),
    tolerance=st.sampled_from([0.0, 0.01]),
)
def test_joint_speeds_joint_by_joint_are_the_sample_major_ones(steps, limits, tolerance):
    """The joint-major layout gives the (T-1, n) formula's speeds, flags and np.argmax pick, ties (equal steps at
    several samples and joints) and NaN (a zero limit with no motion) included."""
    from robocritics.critic.builtin.joint_speed import _joint_speeds

    q = np.cumsum(np.vstack([np.zeros(3), np.array(steps)]), axis=0)
    time = np.cumsum(np.r_[0.0, np.full(len(steps), 0.004)])
    lim = np.array(limits)
    with np.errstate(divide="ignore", invalid="ignore"):
        w_ref = np.abs(np.diff(q, axis=0)) / np.diff(time)[:, None]
        ratio = w_ref / lim
        w, (ji, jj), worst, over, over_rows = _joint_speeds(q, time, lim, tolerance)
    want_i, want_j = divmod(int(np.argmax(ratio)), ratio.shape[1])
    np.testing.assert_array_equal(w, w_ref.T)
    assert (ji, jj) == (want_i, want_j)
    np.testing.assert_array_equal(worst, ratio[want_i, want_j])
    np.testing.assert_array_equal(over, (ratio > 1.0 + tolerance).T)
    np.testing.assert_array_equal(over_rows, (ratio > 1.0 + tolerance).any(axis=1))
