"""The deploy hooks the studio's Deploy and Stop use: ``URArm.deploy(stop=Event, progress=callable)``, against the
loopback controller on simulated time (stepped: each setpoint is one 2 ms control cycle), so the stop point and the
progress reports do not depend on how loaded the machine is."""

from __future__ import annotations

import threading

import pytest

import robocritics as rc
from robocritics.critic import BUILTIN_CRITICS
from robocritics.deploy import DeployFault, URArm, resample
from robocritics.testing.ursim import URSim
from ur_support import stepped

PROGRAM = "lib.set_speed(0.5)\nmove_above(red_apple_1, 0.12)\nmove_above(green_apple, 0.12)\n"


@pytest.fixture(scope="module")
def motion():
    execution = rc.simulate(PROGRAM, rc.Scene.builtin("sorting"))
    report = rc.critique(execution, critics=BUILTIN_CRITICS)
    assert not report.has_errors, report.summary()
    return execution, report


def arm_for(sim) -> URArm:
    return URArm("127.0.0.1", rtde_port=sim.rtde_port, dashboard_port=sim.dashboard_port,
                 secondary_port=sim.secondary_port, timeout_s=1.0)


def test_stop_event_stops_the_arm_through_the_fault_path_and_progress_is_reported(motion):
    execution, report = motion
    plan = resample(execution.trajectory)
    stop = threading.Event()
    reports = []

    def progress(p):
        reports.append(p)
        if p.phase == "streaming" and p.time_s >= 0.5:  # Stop pressed half a second into the motion
            stop.set()

    with URSim(**stepped(initial_q=tuple(execution.robot.home_q), idle_after_s=0.05)) as sim:
        with arm_for(sim) as arm:
            with pytest.raises(DeployFault) as info:
                arm.deploy(execution, report, stop=stop, progress=progress)
        sim.wait_for(lambda s: s.program is None and max(map(abs, s.qd)) == 0.0, 5.0, "the arm to stop")
    fault = info.value
    assert fault.cause == "stop_requested" and fault.stopped, str(fault)
    assert "[stop_requested]" in str(fault)
    # stopped within a few control cycles of the request (lockstep: one setpoint per 2 ms cycle)
    assert 0.5 <= fault.time_s <= 0.5 + 0.1 + 10 * 0.002, fault.time_s
    streaming = [p for p in reports if p.phase == "streaming"]
    assert streaming and all(p.setpoints_total == len(plan) for p in reports)
    assert all(p.duration_s == pytest.approx(float(plan.time[-1])) for p in reports)
    sent = [p.setpoints_sent for p in streaming]
    assert sent == sorted(sent) and sent[-1] < len(plan)
    assert all(0.0 <= p.tracking_error_rad <= p.max_tracking_error_rad + 1e-12 for p in streaming)
    assert all(p.time_s == pytest.approx(float(plan.time[p.setpoints_sent - 1])) for p in streaming)


def test_a_deploy_that_is_not_stopped_reports_its_last_setpoint(motion):
    execution, report = motion
    plan = resample(execution.trajectory)
    reports = []
    with URSim(**stepped(initial_q=tuple(execution.robot.home_q), idle_after_s=0.05)) as sim:
        with arm_for(sim) as arm:
            result = arm.deploy(execution, report, stop=threading.Event(), progress=reports.append)
    assert result.samples_sent == len(plan)
    last = [p for p in reports if p.phase == "streaming"][-1]
    assert last.setpoints_sent == len(plan) and last.time_s == pytest.approx(float(plan.time[-1]))


def test_a_progress_callback_that_raises_never_stops_the_stream(motion):
    execution, report = motion

    def broken(_):
        raise RuntimeError("a display bug")

    with URSim(**stepped(initial_q=tuple(execution.robot.home_q), idle_after_s=0.05)) as sim:
        with arm_for(sim) as arm:
            result = arm.deploy(execution, report, progress=broken)
    assert result.samples_sent == len(resample(execution.trajectory))
