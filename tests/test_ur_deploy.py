"""Deployment: the gate, the 500 Hz servo stream, and every fault — against the loopback controller.

Everything runs over real sockets on 127.0.0.1 (ephemeral ports, except the
ur-rtde conformance test, which needs the real RTDE port 30004). A short
program (about 2 s of motion, ending 0.6 rad away from where it starts) keeps
the tests fast; every deployment and every fault ends within a bounded time.

The controller runs on simulated time (``clock="stepped"``: each setpoint the
client streams is one 2 ms control cycle; idle cycles only while the client is
quiet), so the gate, the faults (injected at a known controller time with
``URSim.at_program_time``) and the controller's watchdog do not depend on how
loaded the machine is. The real-time tests run the controller in its own
process, as a real one runs on its own machine, and assert only what holds on a
loaded 2-core host.
"""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from robocritics.critic import BUILTIN_CRITICS
import robocritics as rc
from robocritics.errors import DeployError, RTDEError
from robocritics.testing.ursim import URSim
from robocritics.deploy import (
    DashboardClient,
    DeployFault,
    DeployRefused,
    RTDEClient,
    URArm,
    approach_trajectory,
    resample,
)
from ur_support import DT, controller_process, stepped

SHORT_PROGRAM = """
lib.set_speed(0.5)
move_above(red_apple_1, 0.12)
move_above(green_apple, 0.12)
"""
INPUTS = [f"input_int_register_{n}" for n in (24, 25, 26)] + [f"input_double_register_{n}" for n in range(24, 31)]


@pytest.fixture(scope="module")
def scene():
    return rc.Scene.builtin("sorting")


@pytest.fixture(scope="module")
def motion(scene):
    """(execution, report) of the short program; the report has no Errors."""
    execution = rc.simulate(SHORT_PROGRAM, scene)
    report = rc.critique(execution, critics=BUILTIN_CRITICS)
    assert not report.has_errors, report.summary()
    assert 1.5 < execution.trajectory.duration_s < 3.0
    return execution, report


@pytest.fixture
def home(motion):
    return tuple(float(v) for v in motion[0].robot.home_q)


@contextmanager
def controller(q0, **kw):
    """A loopback controller on simulated time, clocked by the client's setpoints (idle cycles when it is quiet)."""
    with URSim(**stepped(initial_q=q0, idle_after_s=0.05, **kw)) as sim:
        yield sim


def arm_for(sim, **kw) -> URArm:
    return URArm("127.0.0.1", rtde_port=sim.rtde_port, dashboard_port=sim.dashboard_port,
                 secondary_port=sim.secondary_port, timeout_s=kw.pop("timeout_s", 1.0), **kw)


def assert_nothing_sent(sim: URSim, q0) -> None:
    """No program reached the controller, no setpoint was written, the arm did not move."""
    assert not sim.events("program_started") and not sim.events("program_rejected")
    snap = sim.snapshot()
    assert snap.program is None and snap.runtime_state == 1
    assert max(abs(a - b) for a, b in zip(snap.q, q0)) == 0.0
    with RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0) as probe:
        probe.setup_outputs(INPUTS, 125)
        probe.start()
        st = probe.wait_next(1.0)
    assert all(st[name] == 0 for name in INPUTS), st


def assert_stopped(sim: URSim) -> None:
    """The program is gone and the arm stands still (bounded wait for the deceleration)."""
    sim.wait_for(lambda s: s.program is None and s.runtime_state == 1 and max(map(abs, s.qd)) == 0.0,
                 5.0, "the arm to stop")


def fault_during(sim: URSim, arm: URArm, execution, report, at_s: float, action, **deploy_kw) -> tuple[DeployFault, float]:
    """Deploy, run ``action`` when the streaming program has run ``at_s`` s of controller time; the DeployFault
    and the wall time the deploy took."""
    sim.at_program_time(at_s, action)
    t0 = time.monotonic()
    with pytest.raises(DeployFault) as info:
        arm.deploy(execution, report, **deploy_kw)
    return info.value, time.monotonic() - t0


def check_fault(exc: DeployFault, execution, cause: str, at_s: float | None = None) -> None:
    n = len(execution.trajectory.q)
    assert isinstance(exc, DeployError)
    assert exc.cause == cause, str(exc)
    assert 0 < exc.sample < n - 1, f"sample {exc.sample} of {n}: {exc}"
    assert f"(at sample {exc.sample})" in str(exc) and f"[{cause}]" in str(exc)
    assert exc.setpoint_index > 0 and exc.time_s == pytest.approx(float(resample(execution.trajectory).time[exc.setpoint_index]))
    if at_s is not None:  # the client noticed within a few cycles of the fault (it streams in lockstep)
        assert at_s - 0.05 < exc.time_s < at_s + 0.1, exc.time_s


# ---------------------------------------------------------------------------- resampling


def test_resample_is_500_hz_on_the_physical_time_axis(motion):
    traj = motion[0].trajectory
    plan = resample(traj, 500.0)
    assert plan.interpolation == "linear"
    assert np.allclose(np.diff(plan.time[:-1]), 0.002)
    assert plan.time[-1] == pytest.approx(traj.duration_s) and len(plan) == int(np.floor(traj.duration_s / 0.002 + 1e-9)) + 2
    assert np.array_equal(plan.q[0], traj.q[0]) and np.array_equal(plan.q[-1], traj.q[-1])
    # the 2 ms setpoints follow the source samples (read back at the source instants)
    t_src = traj.time - traj.time[0]
    back = np.column_stack([np.interp(t_src, plan.time, plan.q[:, j]) for j in range(6)])
    assert np.max(np.abs(back - traj.q)) < 1e-4
    assert plan.source_index[0] == 0 and plan.source_index[-1] == len(traj.q) - 1
    assert np.all(np.diff(plan.source_index) >= 0)
    assert np.allclose(plan.gripper_opening_m, traj.gripper_opening_m[0])


def test_resample_uses_a_monotone_cubic_for_sparse_sources(motion):
    traj = motion[0].trajectory
    idx = np.arange(0, len(traj.q), 12)  # 96 ms between samples
    sparse = motion[0].robot.trajectory(traj.q[idx], traj.time[idx], rc.Scene.builtin("sorting"),
                                        gripper_opening_m=traj.gripper_opening_m[idx])
    plan = resample(sparse, 500.0)
    assert plan.interpolation == "pchip"
    lo, hi = traj.q[idx].min(axis=0), traj.q[idx].max(axis=0)
    assert np.all(plan.q >= lo - 1e-12) and np.all(plan.q <= hi + 1e-12)  # no overshoot


def test_resample_takes_a_trajectory_only(motion):
    traj = motion[0].trajectory
    with pytest.raises(DeployError, match="needs a robocritics.Trajectory, got dict"):
        resample({"q": traj.q, "time": traj.time}, 500.0)
    with pytest.raises(DeployError, match="rate_hz must be a positive number of Hz"):
        resample(traj, 0.0)


# ---------------------------------------------------------------------------- a full deployment


def test_deploy_streams_the_verified_trajectory_to_its_final_configuration(motion, home):
    execution, report = motion
    traj = execution.trajectory
    plan = resample(traj)
    with controller(home) as sim:
        with arm_for(sim) as arm:
            result = arm.deploy(execution, report)
        snap = sim.snapshot()
        events = [e for e in sim.events() if e.kind != "dashboard"]
    kinds = [e.kind for e in events]
    assert max(abs(a - b) for a, b in zip(snap.q, traj.q[-1])) < 1e-3
    assert max(abs(a - b) for a, b in zip(result.final_q, traj.q[-1])) < 1e-3 and result.final_error_rad < 1e-3
    assert snap.program is None and snap.runtime_state == 1 and snap.safety_mode == 1 and max(map(abs, snap.qd)) == 0.0
    assert snap.program_state == 2  # DONE: the program ended through the done command
    assert snap.gripper_opening_m == pytest.approx(float(traj.gripper_opening_m[-1]))
    assert kinds.count("program_started") == 1 and kinds.index("program_started") < kinds.index("done")
    assert not {"protective_stop", "watchdog", "stalled", "start_rejected"} & set(kinds)
    assert result.samples_sent == result.planned_setpoints == len(plan)
    assert result.trajectory_samples == len(traj.q) and result.trajectory_hash == report.trajectory_hash
    # in lockstep the program ran every setpoint for one cycle: it streamed for the trajectory's physical duration
    started = next(e.time_s for e in events if e.kind == "program_started")
    done = next(e.time_s for e in events if e.kind == "done")
    assert done - started == pytest.approx(traj.duration_s + result.settle_s, abs=0.2)
    assert 0 < result.max_tracking_error_rad < 0.05
    assert result.data_packages >= len(plan)  # at least one package per setpoint, every one checked
    assert "deployed" in result.summary() and not result.dry_run


def test_deploy_in_real_time_to_a_controller_in_its_own_process(motion, home):
    """The stream paced on the wall clock, to a controller running on its own (as a real one does)."""
    execution, report = motion
    traj = execution.trajectory
    with controller_process("--initial-q", *map(str, home)) as ctl:
        with URArm("127.0.0.1", rtde_port=ctl.rtde_port, dashboard_port=ctl.dashboard_port,
                   secondary_port=ctl.secondary_port, timeout_s=2.0) as arm:
            t0 = time.monotonic()
            result = arm.deploy(execution, report)
            elapsed = time.monotonic() - t0
        end = ctl.state()
    assert result.samples_sent == result.planned_setpoints == len(resample(traj))  # every setpoint, none skipped
    assert result.final_error_rad < 1e-3 and max(abs(a - b) for a, b in zip(end["actual_q"], traj.q[-1])) < 1e-3
    assert (end["runtime_state"], end["safety_mode"], end["output_int_register_25"]) == (1, 1, 2)  # ended DONE
    assert max(map(abs, end["actual_qd"])) == 0.0
    assert 0 < result.max_tracking_error_rad < 0.05
    # the wall clock: never faster than the physical time axis; a loaded host may stretch it (resyncs), boundedly
    assert traj.duration_s - 0.01 < result.duration_s < 2 * traj.duration_s + 1.0
    assert elapsed < 3 * traj.duration_s + 5.0


def test_dry_run_checks_everything_but_sends_nothing(motion, home):
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            result = arm.deploy(execution, report, dry_run=True)
        assert result.dry_run and result.samples_sent == 0 and result.planned_setpoints == len(resample(execution.trajectory))
        assert result.program.startswith("# robocritics-stream-program v1")
        assert "gate passed, nothing sent" in result.summary()
        assert_nothing_sent(sim, home)


def test_fieldbus_on_registers_0_to_23_does_not_stop_a_deployment(motion, home):
    execution, report = motion
    with controller(home, fieldbus_registers=True) as sim:
        with RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0) as other:  # the fieldbus really holds 0-23
            with pytest.raises(RTDEError, match="IN_USE"):
                other.setup_inputs(["input_int_register_0"])
        with arm_for(sim) as arm:
            result = arm.deploy(execution, report)
        assert max(abs(a - b) for a, b in zip(sim.q, execution.trajectory.q[-1])) < 1e-3
        assert result.final_error_rad < 1e-3


# ---------------------------------------------------------------------------- the gate


def test_gate_refuses_a_report_with_errors_and_names_the_critics(scene, home):
    naive = Path(__file__).resolve().parent.parent / "examples" / "programs" / "sorting_naive.py"
    execution = rc.simulate(naive.read_text(), scene)
    report = rc.critique(execution, critics=BUILTIN_CRITICS)
    assert report.has_errors
    with controller(home) as sim:
        with arm_for(sim) as arm:
            with pytest.raises(DeployRefused) as info:
                arm.deploy(execution, report)
            exc = info.value
            assert exc.cause == "report_errors" and exc.sample == -1 and isinstance(exc, DeployError)
            for verdict in report.errors:
                assert verdict.critic in str(exc) and verdict.message in str(exc)
            assert "allow_errors=True" in str(exc)
            # the override has to be explicit; a dry run shows it passes the rest of the gate
            assert arm.deploy(execution, report, allow_errors=True, dry_run=True).dry_run
        assert_nothing_sent(sim, home)


def test_gate_refuses_a_trajectory_the_report_did_not_judge(motion, scene, home):
    execution, report = motion
    other = rc.simulate("lib.set_speed(0.5)\nmove_above(green_apple, 0.12)\n", scene)
    with controller(home) as sim:
        with arm_for(sim) as arm:
            with pytest.raises(DeployRefused) as info:
                arm.deploy(other, report)
            assert info.value.cause == "hash_mismatch" and report.trajectory_hash[:12] in str(info.value)
            with pytest.raises(DeployRefused) as info:
                arm.deploy(execution, None)
            assert info.value.cause == "no_report"
        assert_nothing_sent(sim, home)


def test_gate_refuses_setpoints_faster_than_the_joint_limits_even_with_allow_errors(motion, scene, home):
    execution, _ = motion
    traj = execution.trajectory
    q = traj.q.copy()
    q[len(q) // 2 :, 0] += 0.05  # one 8 ms step of 0.05 rad: 6.25 rad/s on the base
    jumpy = execution.robot.trajectory(q, traj.time, scene, gripper_opening_m=traj.gripper_opening_m)
    report = rc.critique(jumpy, scene, critics=BUILTIN_CRITICS)
    with controller(home) as sim:
        with arm_for(sim) as arm:
            with pytest.raises(DeployRefused) as info:
                arm.deploy(jumpy, report, allow_errors=True)
            assert "setpoint_speed" in info.value.causes
            assert "joint 0" in str(info.value) and "protective-stop" in str(info.value)
        assert_nothing_sent(sim, home)


def test_gate_refuses_a_start_far_from_the_arm_and_offers_an_approach(motion, scene, home):
    execution, report = motion
    q0 = list(home)
    q0[2] += 0.05
    with controller(tuple(q0)) as sim:
        with arm_for(sim) as arm:
            with pytest.raises(DeployRefused) as info:
                arm.deploy(execution, report)
            assert info.value.cause == "start_mismatch"
            text = str(info.value)
            assert "joint 2" in text and "robocritics deploy PROGRAM --host HOST" in text
            assert "start_q=arm.actual_q()" in text and "arm.approach(execution)" in text
            assert_nothing_sent(sim, q0)
            approach = arm.approach(execution, speed_fraction=0.1)
            approach_report = rc.critique(approach, scene, critics=BUILTIN_CRITICS)  # the caller judges the approach like any motion
            assert not approach_report.has_errors
            assert np.allclose(approach.q[0], q0) and np.array_equal(approach.q[-1], execution.trajectory.q[0])
            assert np.all(np.diff(approach.time) > 0)
            vmax = np.max(np.abs(np.diff(approach.q, axis=0)) / np.diff(approach.time)[:, None], axis=0)
            assert np.all(vmax <= 0.1 * np.asarray(execution.robot.velocity_limits) + 1e-9)  # slow
            arm.deploy(approach, approach_report)
            assert max(abs(a - b) for a, b in zip(sim.q, execution.trajectory.q[0])) < 1e-3
            arm.deploy(execution, report)  # now the gate passes
        assert max(abs(a - b) for a, b in zip(sim.q, execution.trajectory.q[-1])) < 1e-3
        assert len(sim.events("program_started")) == 2


def test_a_motion_planned_from_the_arms_joints_passes_the_gate(scene, home):
    q0 = list(home)
    q0[0] += 0.3
    q0[2] -= 0.2
    with controller(tuple(q0)) as sim:
        with arm_for(sim) as arm:
            execution = rc.simulate(SHORT_PROGRAM, scene, start_q=arm.actual_q())
            report = rc.critique(execution, critics=BUILTIN_CRITICS)
            assert np.array_equal(execution.trajectory.q[0], q0) and not report.has_errors
            result = arm.deploy(execution, report)
        assert result.final_error_rad < 1e-3 and not sim.events("start_rejected")
        assert max(abs(a - b) for a, b in zip(sim.q, execution.trajectory.q[-1])) < 1e-3


def test_an_approach_must_pass_the_gate_too(motion, scene, home):
    execution, _ = motion
    q0 = list(home)
    q0[1] += 0.9  # fingers down among the apples: the approach starts in collision
    with controller(tuple(q0)) as sim:
        with arm_for(sim) as arm:
            approach = arm.approach(execution)
            approach_report = rc.critique(approach, scene, critics=BUILTIN_CRITICS)
            assert approach_report.has_errors
            with pytest.raises(DeployRefused) as info:
                arm.deploy(approach, approach_report)
            assert info.value.cause == "report_errors" and "collision" in str(info.value)
        assert_nothing_sent(sim, q0)


def test_approach_needs_a_trajectory_that_starts_empty_handed(motion, scene, home):
    execution, _ = motion
    traj = execution.trajectory
    holding = execution.robot.trajectory(traj.q, traj.time, scene, gripper_opening_m=traj.gripper_opening_m,
                                         attached=np.full(len(traj.q), "red_apple_1"))
    with pytest.raises(DeployError, match="starts holding 'red_apple_1'"):
        approach_trajectory(execution.robot, scene, home, holding)
    with pytest.raises(DeployError, match="goal must be a robocritics.Trajectory, got Execution"):
        approach_trajectory(execution.robot, scene, home, execution)


def test_gate_refuses_what_is_not_an_execution_or_a_trajectory(motion, home):
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            with pytest.raises(DeployRefused) as info:
                arm.deploy(execution.trajectory.q, report)
            assert info.value.causes == ("trajectory",) and "got ndarray" in str(info.value)
            with pytest.raises(DeployRefused) as info:
                arm.deploy(execution, report.model_dump())
            assert info.value.causes == ("no_report",) and "got a dict" in str(info.value)
            with pytest.raises(DeployError, match="needs the Execution"):
                arm.approach(execution.trajectory)
        assert_nothing_sent(sim, home)


@pytest.mark.parametrize(
    "setup, cause",
    [
        (lambda sim: sim.trigger_protective_stop("light curtain"), "safety_mode"),
        (lambda sim: sim.set_remote_control(False), "remote_control"),
        (None, "robot_mode"),
        (lambda sim: _play(sim), "program_running"),
    ],
    ids=["protective_stop", "local_control", "power_off", "program_running"],
)
def test_gate_refuses_when_the_controller_is_not_ready(motion, home, setup, cause):
    execution, report = motion
    kw = {"robot_mode": "POWER_OFF"} if setup is None else {}
    with controller(home, **kw) as sim:
        if setup is not None:
            setup(sim)
        q_before = sim.q
        with arm_for(sim) as arm:
            with pytest.raises(DeployRefused) as info:
                arm.deploy(execution, report)
            assert info.value.cause == cause, str(info.value)
            assert info.value.sample == -1
        assert not sim.events("program_started") or cause == "program_running"
        assert sim.q == q_before
        if cause != "program_running":
            assert_nothing_sent(sim, home)


def _play(sim: URSim) -> None:
    with DashboardClient("127.0.0.1", sim.dashboard_port, timeout_s=1.0) as dash:
        dash.load("/programs/pick.urp")
        dash.play()


def test_gate_lists_every_reason(motion, scene, home):
    execution, report = motion
    other = rc.simulate("lib.set_speed(0.5)\nmove_above(green_apple, 0.12)\n", scene)
    q0 = list(home)
    q0[0] += 0.2
    with controller(tuple(q0), robot_mode="POWER_OFF", remote_control=False) as sim:
        with arm_for(sim) as arm:
            with pytest.raises(DeployRefused) as info:
                arm.deploy(other, report)
    assert info.value.causes == ("hash_mismatch",)  # offline reasons first: nothing is asked of the robot
    with controller(tuple(q0), robot_mode="POWER_OFF", remote_control=False) as sim:
        with arm_for(sim) as arm:
            with pytest.raises(DeployRefused) as info:
                arm.deploy(execution, report)
        assert_nothing_sent(sim, q0)
    assert set(info.value.causes) == {"robot_mode", "remote_control", "start_mismatch"}
    assert "power on" in str(info.value) and "remote control" in str(info.value)


# ---------------------------------------------------------------------------- faults while streaming


def test_connection_drop_mid_stream_stops_the_arm(motion, home):
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            exc, elapsed = fault_during(sim, arm, execution, report, 0.8, lambda: sim.inject_drop())
            check_fault(exc, execution, "connection_drop", at_s=0.8)
            assert elapsed < 0.8 + 5.0
            assert exc.stopped and "dashboard stop" in exc.stop_report
            assert_stopped(sim)
            arm.connect()  # reconnects; the arm is mid-way: plan from there (or approach) first
            with pytest.raises(DeployRefused) as info:
                arm.deploy(execution, report)
            assert info.value.causes == ("start_mismatch",)


def test_protective_stop_mid_stream(motion, home):
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            exc, elapsed = fault_during(sim, arm, execution, report, 0.8, lambda: sim.trigger_protective_stop("light curtain"))
        check_fault(exc, execution, "protective_stop", at_s=0.8)
        assert exc.stopped and elapsed < 0.8 + 5.0
        assert "light curtain" in str(exc)  # the controller's message is quoted
        assert sim.snapshot().safety_mode == 3
        assert_stopped(sim)


def test_silent_controller_mid_stream(motion, home):
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            exc, elapsed = fault_during(sim, arm, execution, report, 0.8, lambda: sim.set_silent(rtde=True),
                                        silence_timeout_s=0.2)
        check_fault(exc, execution, "controller_silent")
        assert elapsed < 0.8 + 5.0
        assert_stopped(sim)


def test_controller_silent_on_every_channel_still_ends_in_bounded_time(motion, home):
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            exc, elapsed = fault_during(sim, arm, execution, report, 0.8,
                                        lambda: sim.set_silent(rtde=True, dashboard=True), stop_timeout_s=1.5)
        check_fault(exc, execution, "controller_silent")
        assert elapsed < 0.8 + 0.2 + 1.5 + 1.0
        assert_stopped(sim)  # the done command got through (inputs are still read); else the watchdog


def test_slow_controller_mid_stream(motion, home):
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            exc, elapsed = fault_during(sim, arm, execution, report, 0.6,
                                        lambda: sim.set_slow(reply_delay_s=0.05, output_rate_factor=0.2))
        check_fault(exc, execution, "controller_slow")
        assert "Hz" in str(exc) and elapsed < 0.6 + 5.0
        assert_stopped(sim)


def test_slow_or_silent_controller_at_connect_is_a_typed_error_in_bounded_time(home):
    with controller(home) as sim:
        sim.set_slow(reply_delay_s=0.6)
        t0 = time.monotonic()
        with pytest.raises(RTDEError, match="no reply"):
            arm_for(sim, timeout_s=0.3).connect()
        assert time.monotonic() - t0 < 2.0
        sim.set_slow()
        sim.set_silent(rtde=True)
        t0 = time.monotonic()
        with pytest.raises(RTDEError):
            arm_for(sim, timeout_s=0.3).connect()
        assert time.monotonic() - t0 < 2.0
        assert not sim.events("program_started")


def test_remote_control_switched_off_mid_stream(motion, home):
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            exc, elapsed = fault_during(sim, arm, execution, report, 0.8, lambda: sim.set_remote_control(False))
        check_fault(exc, execution, "remote_control")
        assert exc.stopped and "done command" in exc.stop_report and elapsed < 0.8 + 5.0
        assert_stopped(sim)


def test_program_stopped_by_someone_else_mid_stream(motion, home):
    execution, report = motion

    def stop_from_pendant():
        with DashboardClient("127.0.0.1", sim.dashboard_port, timeout_s=1.0) as dash:
            dash.stop()

    with controller(home) as sim:
        with arm_for(sim) as arm:  # a dashboard exchange cannot run inside the control cycle: its own thread
            exc, _ = fault_during(sim, arm, execution, report, 0.8, lambda: threading.Thread(target=stop_from_pendant).start())
        check_fault(exc, execution, "program_stopped")
        assert_stopped(sim)


def test_a_program_the_controller_ignores_times_out_and_stops(motion, home):
    """A secondary interface that swallows the program (like a controller that ignores it)."""
    execution, report = motion
    with controller(home) as sim, socket.socket() as blackhole:
        blackhole.bind(("127.0.0.1", 0))
        blackhole.listen(1)
        arm = URArm("127.0.0.1", rtde_port=sim.rtde_port, dashboard_port=sim.dashboard_port,
                    secondary_port=blackhole.getsockname()[1], timeout_s=1.0)
        with arm:
            t0 = time.monotonic()
            with pytest.raises(DeployFault) as info:
                arm.deploy(execution, report, start_timeout_s=0.5)
            assert time.monotonic() - t0 < 0.5 + 2.5
        exc = info.value
        assert exc.cause == "program_not_started" and exc.sample == 0 and exc.setpoint_index == -1
        assert "start_timeout_s 0.5" in str(exc)
        assert not sim.events("program_started") and max(abs(a - b) for a, b in zip(sim.q, home)) == 0.0


def test_an_unreachable_secondary_interface_fails_fast(motion, home):
    execution, report = motion
    with controller(home) as sim:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            closed_port = s.getsockname()[1]  # nothing listens once closed
        arm = URArm("127.0.0.1", rtde_port=sim.rtde_port, dashboard_port=sim.dashboard_port,
                    secondary_port=closed_port, timeout_s=1.0)
        with arm:
            with pytest.raises(DeployRefused) as refused:
                arm.deploy(execution, report, dry_run=True)  # the dry run notices it
            assert refused.value.cause == "secondary_interface"
            with pytest.raises(DeployFault) as info:
                arm.deploy(execution, report)
        assert info.value.cause == "program_not_started" and "sending the program failed" in str(info.value)
        assert not sim.events("program_started") and max(abs(a - b) for a, b in zip(sim.q, home)) == 0.0


def _hiccup_on_call(monkeypatch, n: int, action) -> None:
    """Run ``action`` once, in the client, just before its ``n``-th setpoint."""
    from robocritics.deploy.stream import _Stream

    original = _Stream._send
    calls = {"n": 0}

    def send(self, *args, **kw):
        calls["n"] += 1
        if calls["n"] == n:
            action()
        return original(self, *args, **kw)

    monkeypatch.setattr(_Stream, "_send", send)


def test_a_stalled_client_shifts_its_schedule_instead_of_jumping(motion, home, monkeypatch):
    execution, report = motion
    _hiccup_on_call(monkeypatch, 400, lambda: time.sleep(0.04))  # 20 missed periods, below the 100 ms watchdog
    with controller(home) as sim:
        with arm_for(sim) as arm:
            result = arm.deploy(execution, report)
        assert not sim.events("protective_stop") and not sim.events("watchdog")
    assert result.resyncs >= 1 and result.period_error_max_ms > 30
    assert result.duration_s > execution.trajectory.duration_s + 0.03  # the motion ran later, not faster
    assert result.max_tracking_error_rad < 0.05 and result.final_error_rad < 1e-3


def test_an_interrupt_mid_stream_stops_the_arm_and_propagates(motion, home, monkeypatch):
    execution, report = motion

    def interrupt():
        raise KeyboardInterrupt

    _hiccup_on_call(monkeypatch, 400, interrupt)
    with controller(home) as sim:
        with arm_for(sim) as arm:
            with pytest.raises(KeyboardInterrupt):
                arm.deploy(execution, report)
        assert_stopped(sim)
        assert sim.events("done")  # stopped through the program's done command
        assert max(abs(a - b) for a, b in zip(sim.q, home)) > 0.05  # it was mid-motion


def test_jumpy_setpoint_protective_stop(motion, home):
    """The controller's safety configuration allows 0.3 rad/s per joint, the trajectory (verified against the
    UR3e's π rad/s) moves faster: its setpoints jump for this controller, which protective-stops."""
    execution, report = motion
    with controller(home, speed_limits=(0.3,) * 6) as sim:
        with arm_for(sim) as arm:
            t0 = time.monotonic()
            with pytest.raises(DeployFault) as info:
                arm.deploy(execution, report)
            elapsed = time.monotonic() - t0
        check_fault(info.value, execution, "protective_stop")
        assert "setpoint jump" in str(info.value) and elapsed < execution.trajectory.duration_s
        (ev,) = sim.events("protective_stop")
        assert "setpoint jump" in ev.message
        assert_stopped(sim)


def test_tracking_error_too_large(motion, home):
    """An arm that cannot keep up (joints capped at 0.3 rad/s, no protective stop) falls behind the stream."""
    execution, report = motion
    with controller(home, speed_limits=(0.3,) * 6, jump_margin=1000.0) as sim:
        with arm_for(sim) as arm:
            with pytest.raises(DeployFault) as info:
                arm.deploy(execution, report, max_tracking_error_rad=0.02)
        check_fault(info.value, execution, "tracking_error")
        assert "0.02" in str(info.value)
        assert info.value.stopped and not sim.events("protective_stop")
        assert_stopped(sim)


def test_a_fresh_deploy_after_a_fault_works(motion, home):
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            exc, _ = fault_during(sim, arm, execution, report, 0.5, lambda: sim.trigger_protective_stop("test"))
            assert exc.cause == "protective_stop"
            assert_stopped(sim)
            with pytest.raises(DeployRefused) as info:  # still protective-stopped, and no longer at the start
                arm.deploy(execution, report)
            assert {"safety_mode", "start_mismatch"} <= set(info.value.causes)
            with pytest.raises(RTDEError, match="Cannot unlock protective stop"):
                arm.dashboard.unlock_protective_stop()
            sim.step(round(0.3 / DT))  # the unlock delay, in controller time
            arm.dashboard.unlock_protective_stop()
            approach = arm.approach(execution, speed_fraction=0.5)
            arm.deploy(approach, rc.critique(approach, execution.scene, critics=BUILTIN_CRITICS))
            arm.deploy(execution, report)
        assert max(abs(a - b) for a, b in zip(sim.q, execution.trajectory.q[-1])) < 1e-3


# ---------------------------------------------------------------------------- conformance with ur-rtde

_UR_RTDE_WATCHER = r"""
import json, select, sys, time
import rtde_receive
r = rtde_receive.RTDEReceiveInterface("127.0.0.1")
deadline = time.time() + 2
while r.getTimestamp() == 0.0 and time.time() < deadline:
    time.sleep(0.01)
start = r.getActualQ()
print("ready", flush=True)
samples, far, stamps = 0, 0.0, set()
deadline = time.time() + float(sys.argv[1])
while time.time() < deadline:
    if select.select([sys.stdin], [], [], 0)[0]:
        sys.stdin.readline()
        break
    q = r.getActualQ()
    stamps.add(r.getTimestamp())
    far = max(far, max(abs(a - b) for a, b in zip(q, start)))
    samples += 1
    time.sleep(0.002)
time.sleep(0.05)
out = dict(start=start, final=r.getActualQ(), far=far, samples=samples, stamps=len(stamps),
           runtime=r.getRuntimeState(), safety=r.getSafetyMode(), connected=r.isConnected())
r.disconnect()
print(json.dumps(out), flush=True)
"""


def test_conformance_ur_rtde_sees_the_deployed_motion(motion, home):
    """ur-rtde (a compiled client nobody here wrote) reads actual_q arriving at the final configuration."""
    pytest.importorskip("rtde_receive", reason="ur-rtde is not installed")
    execution, report = motion
    target = execution.trajectory.q[-1]
    try:
        sim = URSim(initial_q=home, dashboard_port=0, secondary_port=0, clock="stepped", idle_after_s=0.05).start()  # RTDE on 30004
    except DeployError as exc:
        pytest.skip(f"port 30004 is taken, so the ur-rtde conformance test cannot run (ur-rtde always uses it): {exc}")
    try:
        # ur-rtde holds the GIL while it waits, so it runs in its own process.
        proc = subprocess.Popen([sys.executable, "-c", _UR_RTDE_WATCHER, "20"], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            ready = proc.stdout.readline()
            assert ready.strip() == "ready", ready + proc.stderr.read()
            with URArm("127.0.0.1", rtde_port=30004, dashboard_port=sim.dashboard_port,
                       secondary_port=sim.secondary_port, timeout_s=1.0) as arm:
                result = arm.deploy(execution, report)
            proc.stdin.write("report\n")
            proc.stdin.flush()
            out_text, err_text = proc.communicate(timeout=10)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        assert proc.returncode == 0, err_text[-2000:]
        out = json.loads(out_text.strip().splitlines()[-1])
    finally:
        sim.stop()
    assert max(abs(a - b) for a, b in zip(out["start"], home)) < 1e-9
    assert max(abs(a - b) for a, b in zip(out["final"], target)) < 1e-3
    assert out["far"] > 0.5  # it watched the arm travel, not just the end
    assert out["stamps"] > 100 and out["connected"]
    assert (out["runtime"], out["safety"]) == (1, 1)
    assert result.final_error_rad < 1e-3
