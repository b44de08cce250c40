"""Timed motion: ruckig limits hold on the samples, speed scaling is a time stretch, lines are straight."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from robocritics import PlanningError, Robot, Scene, simulate
from robocritics.planning.timing import Limits, time_joint_move

LIMITS = Limits(
    velocity=np.array([np.pi] * 3 + [2 * np.pi] * 3),
    acceleration=np.array([5.0] * 3 + [10.0] * 3),
    jerk=np.array([50.0] * 3 + [100.0] * 3),
)
configs = arrays(np.float64, (6,), elements=st.floats(-3.0, 3.0, allow_nan=False))


@settings(max_examples=80, deadline=None)
@given(start=configs, goal=configs, fraction=st.floats(0.05, 1.0), rate=st.sampled_from([125.0, 500.0]))
def test_finite_difference_speeds_respect_scaled_limits(start, goal, fraction, rate):
    seg = time_joint_move(start, goal, LIMITS, fraction, rate)
    if seg.duration_s == 0:
        assert np.allclose(start, goal) and len(seg.q) == 1
        return
    q = np.vstack([seg.q, goal])  # the end configuration is the next segment's first sample
    t = np.append(seg.time, seg.duration_s)
    speed = np.abs(np.diff(q, axis=0)) / np.diff(t)[:, None]
    assert np.all(speed <= LIMITS.velocity * fraction * (1 + 1e-9))
    np.testing.assert_allclose(seg.q[0], start, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(start=configs, goal=configs, fraction=st.floats(0.1, 1.0))
def test_halving_the_speed_doubles_the_duration(start, goal, fraction):
    if np.max(np.abs(goal - start)) < 1e-3:
        return
    full = time_joint_move(start, goal, LIMITS, fraction, 125.0).duration_s
    half = time_joint_move(start, goal, LIMITS, fraction / 2, 125.0).duration_s
    assert half == pytest.approx(2 * full, rel=1e-6)


@pytest.mark.parametrize("fraction", [1.5, 0.0, 0.005, -1.0, float("nan"), float("inf")])
def test_speed_fraction_is_validated(fraction):
    with pytest.raises(PlanningError, match=r"speed fraction must lie in \[0\.01, 1\]"):
        time_joint_move(np.zeros(6), np.ones(6), LIMITS, fraction, 125.0)


def _program(speed_line):
    return f"""
{speed_line}
move_to(0.30, 0.10, 0.20)
move_linear(0.30, -0.10, 0.12)
move_down(0.05)
"""


def test_reduce_speed_stretches_the_program_and_lines_stay_straight():
    scene = Scene.builtin("sorting").model_copy(update={"objects": [], "containers": []})
    fast = simulate(_program("set_speed(1.0)"), scene)
    slow = simulate(_program("reduce_speed(50)"), scene)
    assert slow.trajectory.duration_s == pytest.approx(2 * fast.trajectory.duration_s, rel=1e-3)
    for ex in (fast, slow):
        traj = ex.trajectory
        tcp = traj.tcp[:, :3, 3]
        t = traj.time
        rate = 1 / np.median(np.diff(t))
        assert rate == pytest.approx(125.0)
        # samples of the move_linear step lie on the segment from its start to its end
        lines = np.array([s.line for s in traj.steps])[traj.step]
        on_line = tcp[lines == 4]
        a, b = on_line[0], np.array([0.30, -0.10, 0.12])
        d = (b - a) / np.linalg.norm(b - a)
        off = on_line - a - np.outer((on_line - a) @ d, d)
        assert np.max(np.linalg.norm(off, axis=1)) < 1e-6
        # no joint goes faster than its limit scaled by the speed in force
        qd = np.abs(np.diff(traj.q, axis=0)) / np.diff(t)[:, None]
        fraction = np.array([s.speed_fraction for s in traj.steps])[traj.step[:-1]]
        assert np.all(qd <= np.array(traj.limits.velocity_rad_s) * fraction[:, None] * (1 + 1e-6))


def test_unreachable_target_names_the_line():
    scene = Scene.builtin("sorting")
    with pytest.raises(PlanningError) as info:
        simulate("move_to(0.3, 0.0, 0.2)\nmove_to(0.9, 0.0, 0.1)\n", scene)
    assert info.value.line == 2
    assert "out of reach" in str(info.value)


def test_robot_from_urdf_uses_numeric_ik(tmp_path):
    ur = Robot.ur3e()
    other = Robot.from_urdf(ur.urdf_path)  # same arm, but without the DH shortcut
    q = other.ik([0.25, 0.1, 0.15], seed=ur.home_q)
    np.testing.assert_allclose(other.tcp_pose(q)[:3, 3], [0.25, 0.1, 0.15], atol=1e-6)


def test_ruckig_edge_case_is_timed():
    # this exact input makes ruckig's profile search fail; the planner must still time it
    from robocritics.planning.timing import time_path_1d

    s, times, duration = time_path_1d(0.08000000000000007, 0.6755520111743515, 4.0, 40.0, 125.0)
    assert duration == pytest.approx(0.4, rel=1e-5)
    assert s[0] == 0 and np.all(np.diff(s) >= 0) and s[-1] < 0.08000000000000007


@settings(max_examples=60, deadline=None, derandomize=True)
@given(start=configs, goal=configs, fraction=st.floats(0.05, 1.0), nudge=st.booleans())
def test_sampled_positions_are_ruckigs_at_time(start, goal, fraction, nudge):
    """Profile.position (every phase of every DOF evaluated at once) against ruckig's own at_time per sample,
    at the 125 Hz instants, phase boundaries and the end; nearly-equal start and goal give tiny profiles."""
    from robocritics.planning.timing import profile_joint_move, profile_path_1d

    if nudge:
        goal = start + 1e-4 * np.sign(goal - start + 0.5)
    for prof in (profile_joint_move(start, goal, LIMITS, fraction), profile_path_1d(0.3, 0.25 * fraction + 0.01, 1.0, 5.0)):
        if prof._traj is None:
            continue
        # what position() takes without reading it: no brake pre-phase, the end is the goal at rest
        for p, g in zip(prof._traj.profiles[0], prof.goal):
            assert p.brake.duration == 0.0 and (p.pf, p.vf, p.af) == (g, 0.0, 0.0)
        ends = np.concatenate([np.cumsum(p.t) for p in prof._traj.profiles[0]])
        times = np.concatenate([np.arange(0.0, prof.duration_s, 1 / 125.0), ends[ends <= prof.duration_s], [prof.duration_s]])
        ours = prof.position(times)
        ref = np.array([prof._traj.at_time(float(t))[0] for t in times]).reshape(len(times), -1)
        np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-12)


_EDGE = [0.0, -0.0, 1.0, -1.0, 1e-12, 2e-12, 1 + 1e-5, 1 + 2e-5, 1e300, math.inf, -math.inf, math.nan]


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.one_of(st.sampled_from(_EDGE), st.floats(-10, 10)), min_size=1, max_size=7),
    st.lists(st.one_of(st.sampled_from(_EDGE), st.floats(-1e-11, 1e-11), st.floats(-1e-4, 1e-4)), min_size=7, max_size=7),
)
def test_allclose_is_numpy_s(start, offsets):
    # the planner's "no motion" test: the same answer as np.allclose(start, goal, atol=1e-12), NaN and inf too
    from robocritics.planning.timing import _allclose

    start = np.array(start)
    goal = start + np.array(offsets[: len(start)])
    for a, b in ((start, goal), (start, start), (goal, start)):
        assert _allclose(a, b) == bool(np.allclose(a, b, atol=1e-12))
