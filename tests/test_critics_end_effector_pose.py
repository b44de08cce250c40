"""end_effector_pose ("spearing"): speed toward where the fingers point."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from critic_asserts import assert_matches_reference, assert_well_formed, critic, run, execution_of
from critic_reference import ref_end_effector_pose
from robocritics.critic import CriticError, Flag, critique
from robocritics.scene import Scene
from strategies import trajectories
from synth import frames_from, line_motion, make_trajectory

DOWN = (0.0, 0.0, -1.0)


def tcp_line(speed, direction, fingers=DOWN, rate_hz=125.0):
    time, pos = line_motion(speed, direction=direction, rate_hz=rate_hz)
    return make_trajectory(time, pos, z_axes=np.asarray(fingers, float))


def minimum_jerk_descent(peak_speed, rate_hz, distance=0.2):
    """A straight descent along the fingers with a minimum-jerk profile reaching ``peak_speed``."""
    duration = 1.875 * distance / peak_speed
    T = int(round(duration * rate_hz)) + 1
    time = np.linspace(0.0, duration, T)
    s = time / duration
    z = 0.3 - distance * (10 * s**3 - 15 * s**4 + 6 * s**5)
    pos = np.stack([np.full(T, 0.3), np.zeros(T), z], axis=-1)[:, None, :]
    return make_trajectory(time, pos, z_axes=np.array(DOWN))


def test_fast_descent_along_the_fingers_is_flagged_sideways_is_not():
    down = run("end_effector_pose", tcp_line(0.4, DOWN))
    assert down.flag is Flag.WARNING and down.value == pytest.approx(0.4)
    assert "0.25 m/s" in down.message and "fingers point" in down.message
    assert_well_formed(down, "end_effector_pose")
    err = run("end_effector_pose", tcp_line(0.6, DOWN))
    assert err.flag is Flag.ERROR and err.threshold == 0.5
    assert_well_formed(err, "end_effector_pose")
    side = run("end_effector_pose", tcp_line(0.6, (1.0, 0.0, 0.0)))
    assert side.flag is Flag.OK and side.value == pytest.approx(0.0, abs=1e-12)
    up = run("end_effector_pose", tcp_line(0.6, (0.0, 0.0, 1.0)))  # retreating against the fingers
    assert up.flag is Flag.OK and up.value == 0.0


def test_score_grows_with_alignment():
    angle = math.radians(60)
    oblique = run("end_effector_pose", tcp_line(0.6, (math.sin(angle), 0.0, -math.cos(angle))))
    assert oblique.value == pytest.approx(0.3)
    assert oblique.flag is Flag.WARNING
    assert oblique.details["alignment_at_worst"] == pytest.approx(0.5)


def test_fingers_pointing_sideways_spear_sideways_motion():
    v = run("end_effector_pose", tcp_line(0.6, (0.0, 1.0, 0.0), fingers=(0.0, 1.0, 0.0)))
    assert v.flag is Flag.ERROR


@pytest.mark.parametrize("peak", [0.2, 0.4, 0.7])
def test_same_motion_at_125_and_500_hz_gives_the_same_verdict(peak):
    slow = run("end_effector_pose", minimum_jerk_descent(peak, 125.0))
    fast = run("end_effector_pose", minimum_jerk_descent(peak, 500.0))
    assert slow.flag is fast.flag
    assert slow.value == pytest.approx(fast.value, rel=2e-3)
    assert fast.value == pytest.approx(peak, rel=2e-3)


def test_zero_finger_direction_is_refused():
    traj = tcp_line(0.4, DOWN)
    frames = traj.frames.copy()
    frames[5, 0, :3, 2] = 0.0
    bad = make_trajectory(traj.time, frames=frames, frame_names=("tcp",))
    with pytest.raises(CriticError, match="finger direction"):
        run("end_effector_pose", bad)
    with pytest.raises(CriticError, match="end_effector_pose"):
        critique(bad, Scene(), critics=["end_effector_pose"])


@st.composite
def params(draw):
    warn = draw(st.floats(0.05, 1.0))
    return {"warn_speed_m_s": warn, "max_speed_m_s": warn * draw(st.floats(1.0, 3.0))}


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(traj=trajectories(), overrides=params())
def test_agrees_with_the_per_sample_reference(traj, overrides):
    c = critic("end_effector_pose")
    p = c.Params(**overrides)
    v = c.check(execution_of(traj), p)
    assert_matches_reference(v, ref_end_effector_pose(traj, p), rel=1e-7)
    assert_well_formed(v, "end_effector_pose")
