"""Issue 22, class 1: nothing from the robot is trusted when it is not a number.

The loopback controller (real RTDE over 127.0.0.1, byte for byte) sends NaN, +inf or -inf in an output field
(``URSim.corrupt_output``) at the gate or at a known point of the stream. Every rule that reads numbers from the
robot must fail closed: the gate refuses (nothing sent), a running stream stops the arm through the same stop
path as any fault with ``cause == "non_finite"`` naming the field, and no motion is sent after it.
"""

from __future__ import annotations

import copy
import math
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics.deploy import DeployFault, DeployRefused, RTDEClient, resample
from robocritics.deploy.gate import check_robot, check_trajectory
from robocritics.deploy.rtde import RTDEValueError, first_non_finite
from robocritics.errors import DeployError, RTDEError
from robocritics.testing.ursim import URSim
from test_ur_deploy import (  # noqa: F401  (fixtures)
    arm_for,
    assert_nothing_sent,
    assert_stopped,
    check_fault,
    controller,
    fault_during,
    home,
    motion,
    scene,
)
from ur_support import STATE_FIELDS, stepped

BAD = [math.nan, math.inf, -math.inf]
BAD_IDS = ["nan", "+inf", "-inf"]


def _shown(value: float) -> str:
    return {"nan": "nan", "inf": "inf", "-inf": "-inf"}[repr(value)]


# ---------------------------------------------------------------------------- the guard itself


@settings(max_examples=200, deadline=None)
@given(st.dictionaries(
    st.sampled_from(["timestamp", "actual_q", "robot_mode", "target_q", "speed_scaling"]),
    st.one_of(st.floats(), st.integers(-2**31, 2**31), st.booleans(), st.tuples(*[st.floats()] * 6)),
))
def test_first_non_finite_agrees_with_a_plain_scan(values):
    expected = None
    for name, v in values.items():
        items = list(enumerate(v)) if isinstance(v, tuple) else [(None, v)]
        bad = [(i, x) for i, x in items if isinstance(x, float) and not math.isfinite(x)]
        if bad:
            expected = (name, *bad[0])
            break
    got = first_non_finite(values)
    if expected is None:
        assert got is None
    else:
        assert got is not None and got[:2] == expected[:2]
        assert repr(got[2]) == repr(expected[2])


def test_first_non_finite_counts_what_is_not_a_number_as_not_finite():
    assert first_non_finite({"robot_mode": 7, "actual_q": np.zeros(6)}) is None
    assert first_non_finite({"actual_q": np.array([0.0, np.nan, 0, 0, 0, 0])})[:2] == ("actual_q", 1)
    assert first_non_finite({"robot_mode": "RUNNING"})[:2] == ("robot_mode", None)
    assert first_non_finite({"robot_mode": None})[:2] == ("robot_mode", None)


# ---------------------------------------------------------------------------- the gate's rules, as pure functions


GOOD_STATE = {"robot_mode": 7, "safety_mode": 1, "runtime_state": 1, "actual_q": (0.0,) * 6, "timestamp": 1.0}


@pytest.mark.parametrize("value", BAD, ids=BAD_IDS)
@pytest.mark.parametrize("field, index", [("actual_q", 3), ("robot_mode", None), ("safety_mode", None),
                                          ("runtime_state", None), ("timestamp", None)])
def test_the_robot_rules_refuse_a_state_with_a_value_that_is_not_a_number(field, index, value):
    """A comparison with NaN is False: `dev > tol` let a NaN joint pass the start-pose rule."""
    state = dict(GOOD_STATE)
    if index is None:
        state[field] = value
    else:
        q = list(state[field])
        q[index] = value
        state[field] = tuple(q)
    reasons = check_robot(state, np.zeros(6), remote_control=True, start_tolerance_rad=0.01)
    assert [c for c, _ in reasons] == ["non_finite"]
    where = field if index is None else f"{field}[{index}]"
    assert f"{where} = {_shown(value)}" in reasons[0][1]
    assert check_robot(GOOD_STATE, np.zeros(6), remote_control=True, start_tolerance_rad=0.01) == []


def test_the_start_rule_fails_closed_on_a_nan_first_sample():
    reasons = check_robot(GOOD_STATE, np.array([0, 0, np.nan, 0, 0, 0]), remote_control=True, start_tolerance_rad=0.01)
    assert [c for c, _ in reasons] == ["start_mismatch"] and "joint 2" in reasons[0][1]


@pytest.mark.parametrize("limit", [math.inf, math.nan, 0.0, -1.0])
def test_the_speed_rule_refuses_limits_it_cannot_check_against(motion, limit):
    traj = copy.copy(motion[0].trajectory)
    vel = list(traj.limits.velocity_rad_s)
    vel[1] = limit
    traj.limits = traj.limits.model_copy(update={"velocity_rad_s": tuple(vel)})
    reasons = check_trajectory(traj, resample(traj))
    assert [c for c, _ in reasons] == ["setpoint_speed"] and "not 6 finite positive numbers" in reasons[0][1]
    assert check_trajectory(motion[0].trajectory, resample(motion[0].trajectory)) == []


@pytest.mark.parametrize("value", BAD, ids=BAD_IDS)
@pytest.mark.parametrize("column", ["q", "time", "gripper_opening_m"])
def test_resampling_refuses_inputs_that_are_not_numbers(motion, column, value):
    traj = copy.copy(motion[0].trajectory)
    arr = np.array(getattr(traj, column), dtype=float)
    arr[(7, 2) if arr.ndim == 2 else 7] = value
    setattr(traj, column, arr)
    with pytest.raises(DeployError, match=f"trajectory {column} is not finite at sample 7"):
        resample(traj)


def test_resampling_refuses_a_stream_too_long_to_hold(motion):
    traj = copy.copy(motion[0].trajectory)
    t = np.array(traj.time, dtype=float)
    t[-1] = 1e300
    traj.time = t
    with pytest.raises(DeployError, match="more than .* setpoints"):
        resample(traj)


# ---------------------------------------------------------------------------- over the wire: the client


@pytest.mark.parametrize("value", BAD, ids=BAD_IDS)
def test_the_client_raises_a_typed_error_naming_the_field_and_keeps_only_finite_values(value):
    with URSim(**stepped()) as sim:
        with RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0) as client:
            client.setup_outputs(STATE_FIELDS, 500)
            client.start()
            sim.step(3)
            deadline = time.monotonic() + 2.0
            while client.packages_received < 3 and time.monotonic() < deadline:
                time.sleep(0.001)
            good = client.latest()
            sim.corrupt_output("actual_q", value, index=4)
            sim.step(2)
            with pytest.raises(RTDEValueError) as info:
                client.wait_next(1.0)
            exc = info.value
            assert (exc.field, exc.index, exc.cause) == ("actual_q", 4, "non_finite")
            assert f"actual_q[4] = {_shown(value)}" in str(exc) and isinstance(exc, RTDEError)
            for read in (client.latest, client.drain, lambda: client.wait_next(0.2)):
                with pytest.raises(RTDEValueError):
                    read()
            stale = client.latest(allow_stale=True)  # the post-mortem: the last values that were numbers
            assert all(math.isfinite(v) for v in stale["actual_q"]) and stale["actual_q"] == good["actual_q"]
            assert client.connected  # the socket is up: the stop path can still send the done command


# ---------------------------------------------------------------------------- over the wire: the gate


@pytest.mark.parametrize("value", BAD, ids=BAD_IDS)
@pytest.mark.parametrize("field, index", [("actual_q", 2), ("timestamp", None), ("actual_qd", 0), ("target_q", 5),
                                          ("output_double_register_24", None)])
def test_the_gate_refuses_when_the_robot_reports_a_value_that_is_not_a_number(motion, home, field, index, value):
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            sim.corrupt_output(field, value, index=index)
            deadline = time.monotonic() + 5.0  # a package already on its way may still be finite
            while arm.rtde.data_fault is None and time.monotonic() < deadline:
                time.sleep(0.002)
            with pytest.raises(DeployRefused) as info:
                arm.deploy(execution, report)
        assert info.value.causes == ("non_finite",)
        where = field if index is None else f"{field}[{index}]"
        assert f"{where} = {_shown(value)}" in str(info.value) and "nothing was sent" in str(info.value)
        sim.corrupt_output(field, None)
        assert_nothing_sent(sim, home)


def test_a_controller_that_sends_nan_from_the_first_package_cannot_be_connected_to(home):
    with controller(home) as sim:
        sim.corrupt_output("actual_q", math.nan, index=0)
        with pytest.raises(RTDEValueError, match=r"actual_q\[0\] = nan"):
            arm_for(sim).connect()
        assert not sim.events("program_started")


@pytest.mark.parametrize("field, wrong, right", [("actual_q", "VECTOR3D", "VECTOR6D"), ("timestamp", "INT32", "DOUBLE"),
                                                ("safety_mode", "VECTOR6D", "INT32")])
def test_a_controller_that_answers_other_field_types_is_refused_at_connect(home, field, wrong, right):
    with controller(home, extra_outputs={field: wrong}) as sim:
        with pytest.raises(RTDEError, match=f"{field} is {wrong}, not {right}"):
            arm_for(sim).connect()
        assert not sim.events("program_started")


def test_a_controller_that_declares_a_mode_field_as_double_is_refused_at_connect(home):
    """A mode sent as DOUBLE could be NaN; URArm insists on the RTDE specification's types."""
    with controller(home, extra_outputs={"robot_mode": "DOUBLE"}) as sim:
        sim.extras["robot_mode"] = 7.0
        with pytest.raises(RTDEError, match="robot_mode is DOUBLE, not INT32"):
            arm_for(sim).connect()
        sim.extras["robot_mode"] = math.nan
        with pytest.raises(RTDEError, match="robot_mode is DOUBLE, not INT32"):
            arm_for(sim).connect()
        assert not sim.events("program_started")


# ---------------------------------------------------------------------------- over the wire: the stream


def _assert_no_motion_after(sim: URSim, execution, exc: DeployFault) -> None:
    """The arm stopped near where it was at the fault: far from the end of the trajectory."""
    assert_stopped(sim)
    q_end = execution.trajectory.q[-1]
    q_fault = execution.trajectory.q[exc.sample]
    assert np.max(np.abs(np.array(sim.q) - q_fault)) < 0.1
    assert np.max(np.abs(np.array(sim.q) - q_end)) > 0.2


@pytest.mark.parametrize("value", BAD, ids=BAD_IDS)
def test_a_nan_joint_mid_stream_stops_the_arm(motion, home, value):
    """The tracking rule never tripped on NaN joints (a comparison with NaN is False)."""
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            exc, elapsed = fault_during(sim, arm, execution, report, 0.8,
                                        lambda: sim.corrupt_output("actual_q", value, index=1))
        check_fault(exc, execution, "non_finite", at_s=0.8)
        assert f"actual_q[1] = {_shown(value)}" in str(exc)
        assert exc.stopped and "dashboard stop sent" in exc.stop_report and elapsed < 0.8 + 5.0
        assert exc.actual_q is not None and all(math.isfinite(v) for v in exc.actual_q)
        _assert_no_motion_after(sim, execution, exc)


@pytest.mark.parametrize("field, index", [("timestamp", None), ("actual_qd", 3), ("target_q", 0),
                                          ("output_double_register_24", None)])
def test_any_field_that_is_not_a_number_mid_stream_stops_the_arm(motion, home, field, index):
    """The rate rule (timestamp), the stand-still rule (actual_qd) and fields no rule reads today alike."""
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            exc, _ = fault_during(sim, arm, execution, report, 0.6,
                                  lambda: sim.corrupt_output(field, math.inf, index=index))
        check_fault(exc, execution, "non_finite", at_s=0.6)
        where = field if index is None else f"{field}[{index}]"
        assert f"{where} = inf" in str(exc) and exc.stopped
        _assert_no_motion_after(sim, execution, exc)


def test_nan_while_the_program_starts_stops_before_any_motion(motion, home):
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            sim.at_program_time(0.0, lambda: sim.corrupt_output("actual_q", math.nan, index=0))
            with pytest.raises(DeployFault) as info:
                arm.deploy(execution, report)
        assert info.value.cause == "non_finite" and info.value.stopped
        assert_stopped(sim)
        assert np.max(np.abs(np.array(sim.q) - np.array(home))) < 1e-3  # it never moved


def test_nan_while_the_arm_settles_or_finishes_is_a_fault_not_a_final_error_of_nan(motion, home):
    """The old end: the command exited 0 with "final error nan rad"."""
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            sim.at_program_time(execution.trajectory.duration_s + 0.02,
                                lambda: sim.corrupt_output("actual_q", math.nan, index=5))
            with pytest.raises(DeployFault) as info:
                arm.deploy(execution, report)
        assert info.value.cause == "non_finite" and "actual_q[5] = nan" in str(info.value)
        assert_stopped(sim)


def test_after_a_nan_fault_a_new_connection_with_finite_values_deploys_again(motion, home, scene):
    import robocritics as rc
    from robocritics.critic import BUILTIN_CRITICS

    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            fault_during(sim, arm, execution, report, 0.5, lambda: sim.corrupt_output("actual_q", math.nan, index=0))
        sim.corrupt_output("actual_q", None)
        assert_stopped(sim)
        with arm_for(sim) as arm:
            again = rc.simulate(
                "lib.set_speed(0.5)\nmove_above(green_apple, 0.12)\n", scene, start_q=arm.actual_q()
            )
            # a 0.5 s watchdog: this test is about the values, not about a loaded host stalling the client
            result = arm.deploy(again, rc.critique(again, critics=BUILTIN_CRITICS), watchdog_min_hz=2.0)
        assert math.isfinite(result.final_error_rad) and result.final_error_rad < 1e-3


@pytest.mark.parametrize("option", ["silence_timeout_s", "start_timeout_s", "settle_tolerance_rad", "settle_timeout_s",
                                    "stop_timeout_s", "monitor_period_s", "max_tracking_error_rad",
                                    "min_data_rate_fraction", "spin_s", "rate_hz", "start_tolerance_rad"])
@pytest.mark.parametrize("value", BAD, ids=BAD_IDS)
def test_a_threshold_that_is_not_a_number_is_refused_before_anything_is_asked(motion, home, option, value):
    """`age > nan` is False: a NaN silence_timeout_s would have switched the silence rule off."""
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            with pytest.raises(DeployError, match=option):
                arm.deploy(execution, report, **{option: value})
        assert not sim.events("program_started")
