"""Dashboard client, URScript streaming program and the loopback controller's simulation of it.

Real sockets on 127.0.0.1, ephemeral ports.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

from robocritics.errors import DeployError, RTDEError
from robocritics.testing.ursim import URSim
from robocritics.deploy import (
    DashboardClient,
    ProgramState,
    RTDEClient,
    parse_streaming_program,
    program_status,
    send_program,
    streaming_program,
)
from robocritics.testing.ursim.controller import UR3E_SPEED_LIMITS
from ur_support import Streamer, powered_dashboard, sim_kwargs


@pytest.fixture
def sim():
    with URSim(**sim_kwargs()) as s:
        yield s


# ---------------------------------------------------------------------------- dashboard


def test_dashboard_power_up_sequence_and_queries():
    with URSim(**sim_kwargs(robot_mode="POWER_OFF")) as sim:
        with DashboardClient("127.0.0.1", sim.dashboard_port, timeout_s=1.0) as dash:
            assert dash.robot_mode() == "POWER_OFF"
            assert dash.is_in_remote_control() is True
            dash.power_on()
            dash.wait_robot_mode("IDLE", timeout_s=1.0)
            dash.brake_release()
            dash.wait_robot_mode("RUNNING", timeout_s=1.0)
            assert sim.snapshot().robot_mode == 7
            assert dash.safety_status() == "NORMAL"
            assert dash.running() is False
            with pytest.raises(RTDEError, match="'play' failed: controller replied 'Failed to execute: play'"):
                dash.play()  # nothing loaded
            assert dash.stop() is False
            dash.load("/programs/pick.urp")
            dash.play()
            assert dash.running() is True and dash.program_state() == "PLAYING /programs/pick.urp"
            assert dash.stop() is True
            assert dash.running() is False
            assert dash.command("make coffee") == "could not understand: 'make coffee'"
            assert dash.polyscope_version().startswith("URSoftware 5.15")
        assert sim.events("dashboard")[-1].message.endswith("'quit' -> 'Disconnected'")


def test_local_control_refuses_commands_and_programs(sim):
    sim.set_remote_control(False)
    with powered_dashboard(sim) as dash:
        assert dash.is_in_remote_control() is False
        with pytest.raises(RTDEError, match="'power on' failed: controller replied .*local control"):
            dash.power_on()
        assert dash.robot_mode() == "RUNNING"  # read-only commands still work
    with RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0) as c:
        c.setup_outputs(["runtime_state"], 125)
        c.start()
        send_program("127.0.0.1", streaming_program(), sim.secondary_port, timeout_s=1.0)
        deadline = time.monotonic() + 1.0
        while not (msgs := c.messages()) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert msgs and "local control" in msgs[0].message
        assert c.wait_next(1.0)["runtime_state"] == 1
    (ev,) = sim.events("program_rejected")
    assert "local control" in ev.message


def test_dashboard_timeouts_and_wrong_servers_are_typed_errors(sim):
    sim.set_silent(rtde=False, dashboard=True)
    with DashboardClient("127.0.0.1", sim.dashboard_port, timeout_s=0.2) as dash:  # greeting still arrives
        t0 = time.monotonic()
        with pytest.raises(RTDEError, match=r"did not answer within 0\.2 s while waiting for the reply to 'robotmode'"):
            dash.robot_mode()
        assert time.monotonic() - t0 < 0.5
    with pytest.raises(RTDEError, match="while waiting for the greeting"):
        DashboardClient("127.0.0.1", sim.secondary_port, timeout_s=0.2).connect()  # a server that says nothing


def test_unlock_protective_stop_is_refused_until_the_delay_passed(sim):
    sim.trigger_protective_stop("operator test")
    with powered_dashboard(sim) as dash:
        assert dash.safety_status() == "PROTECTIVE_STOP"
        with pytest.raises(RTDEError, match="Cannot unlock protective stop until 5s"):
            dash.unlock_protective_stop()
        time.sleep(0.35)
        dash.unlock_protective_stop()
        assert dash.safety_status() == "NORMAL"


# ---------------------------------------------------------------------------- the URScript program


def test_streaming_program_text_and_parameters_round_trip():
    text = streaming_program(lookahead_time_s=0.05, gain=500, watchdog_min_hz=20.0, stop_deceleration_rad_s2=3.0)
    assert text.startswith("# robocritics-stream-program v1\n")
    assert "servoj(q, t=0.002, lookahead_time=0.05, gain=500.0)" in text
    assert 'rtde_set_watchdog("input_int_register_24", 20.0, "stop")' in text
    assert "stopj(3.0)" in text and "write_output_integer_register(24, seq)" in text
    for r in range(24, 31):
        assert f"read_input_float_register({r})" in text
    assert text.count("def ") == 1 and text.rstrip().endswith("end")
    p = parse_streaming_program(text)
    assert (p.lookahead_time_s, p.gain, p.watchdog_min_hz, p.watchdog_action) == (0.05, 500.0, 20.0, "stop")
    assert p.stall_limit_cycles == 25 and p.stop_deceleration_rad_s2 == 3.0 and p.gripper_close_below_m == 0.0425
    hooked = parse_streaming_program(streaming_program(gripper_hook="rq_move_mm(opening_m * 1000)"))
    assert hooked.gripper_close_below_m is None
    with pytest.raises(DeployError, match="lookahead_time_s must be in"):
        streaming_program(lookahead_time_s=0.5)
    with pytest.raises(DeployError, match="gain must be in"):
        streaming_program(gain=50)
    with pytest.raises(DeployError, match="is not a streaming-program state"):
        program_status({"output_int_register_24": 1, "output_int_register_25": 17, "output_int_register_26": 1, "output_double_register_24": 0.0})
    with pytest.raises(DeployError, match="lacks 'output_int_register_26'"):
        program_status({"output_int_register_24": 1, "output_int_register_25": 1})
    with pytest.raises(DeployError, match="first line is not"):
        parse_streaming_program("def f():\n  movej([0,0,0,0,0,0])\nend\n")


def test_unrecognised_scripts_are_rejected_with_a_message(sim):
    with RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0) as c:
        c.setup_outputs(["runtime_state"], 125)
        c.start()
        send_program("127.0.0.1", "def wave():\n  movej([0, -1.57, 1.57, 0, 0, 0])\nend\n", sim.secondary_port)
        deadline = time.monotonic() + 1.0
        while not (msgs := c.messages()) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert msgs and "only runs robocritics streaming programs" in msgs[0].message
        assert msgs[0].level_name == "ERROR"
    assert sim.snapshot().program is None


# ---------------------------------------------------------------------------- streaming through the sim


def test_streamed_servo_sequence_reaches_its_target(sim):
    with Streamer(sim) as st:
        start = st.start_program()
        assert start["output_int_register_26"] == 7
        q0 = list(st.q)
        target = [q0[0] + 0.6, q0[1] - 0.3, q0[2] + 0.4, q0[3] + 0.8, q0[4] - 0.5, q0[5] + 1.0]
        st.move(target, 1.0)
        st.hold(150, gripper_m=0.01)
        mid = sim.snapshot()
        assert mid.runtime_state == 2 and mid.safety_mode == 1
        assert mid.applied_seq == st.seq or mid.applied_seq >= st.seq - 3
        end = st.finish()
        status = program_status(end)
        assert status.state is ProgramState.DONE and status.applied_seq == st.seq and status.session == 7
        assert status.gripper_opening_m == 0.01
        err = max(abs(a - b) for a, b in zip(end["actual_q"], target))
        assert err < 2e-3
        snap = sim.snapshot()
        assert snap.program is None and snap.runtime_state == 1 and max(map(abs, snap.qd)) == 0.0
        assert snap.gripper_opening_m == 0.01 and snap.digital_out & (1 << 16)  # placeholder gripper closed
    kinds = [e.kind for e in sim.events()]
    assert kinds.index("program_started") < kinds.index("done") < kinds.index("program_ended")
    assert not sim.events("protective_stop") and not sim.events("watchdog")


def test_watchdog_stops_the_program_when_the_client_goes_quiet(sim):
    with Streamer(sim) as st:
        st.start_program(watchdog_min_hz=10.0)
        st.hold(50)
        quiet_from = time.monotonic()
        state = st.client.wait_for(lambda s: s["runtime_state"] == 1, 1.0, "the watchdog to stop the program")
        stopped_after = time.monotonic() - quiet_from
        assert 0.05 < stopped_after < 0.5  # 1/10 Hz plus transport (the controller may catch up on late cycles)
        assert state["output_int_register_25"] == ProgramState.STREAMING  # the controller, not the program, stopped it
        deadline = time.monotonic() + 1.0
        msgs = []
        while not any("watchdog" in m.message for m in msgs) and time.monotonic() < deadline:
            msgs += st.client.messages()
            time.sleep(0.01)
        assert any("RTDE watchdog: input_int_register_24 not updated" in m.message for m in msgs)
    (ev,) = sim.events("watchdog")
    assert "program robocritics_stream stopped" in ev.message


def test_a_counter_that_stops_changing_stalls_the_program(sim):
    with Streamer(sim) as st:
        st.start_program(watchdog_min_hz=4.0)  # stall after 125 unchanged cycles; updates keep the watchdog quiet
        st.hold(20)
        t0 = time.monotonic()
        while time.monotonic() - t0 < 1.0 and st.client.latest()["runtime_state"] == 2:
            st.send(st.q, bump=False)  # updates keep coming (watchdog happy) but the counter is frozen
            st.pace()
        state = st.client.wait_for(lambda s: s["runtime_state"] == 1, 1.0, "the stall check")
        assert state["output_int_register_25"] == ProgramState.STALLED
    assert sim.events("stalled") and not sim.events("watchdog")


def test_setpoint_jump_causes_a_protective_stop_but_a_fast_legal_move_does_not(sim):
    with Streamer(sim) as st:
        st.start_program()
        step = 0.9 * UR3E_SPEED_LIMITS[0] * 0.002  # 90 % of the base speed limit
        q = list(st.q)
        for _ in range(150):
            q[0] += step
            st.send(q)
            st.pace()
        assert sim.snapshot().safety_mode == 1 and not sim.events("protective_stop")
        jump = list(st.q)
        jump[1] += 0.05  # 25 rad/s for one 2 ms step
        st.send(jump)
        state = st.client.wait_for(lambda s: s["safety_mode"] == 3, 1.0, "a protective stop")
        assert state["runtime_state"] == 1
        (ev,) = sim.events("protective_stop")
        assert "setpoint jump on joint 1" in ev.message and "rad/s" in ev.message
        with powered_dashboard(sim) as dash:
            assert dash.safety_status() == "PROTECTIVE_STOP"
        sim.wait_for(lambda s: max(map(abs, s.qd)) == 0.0, 1.0, "the arm to stand still")


def test_first_setpoint_far_from_the_arm_is_refused(sim):
    with Streamer(sim) as st:
        far = list(st.q)
        far[2] += 0.3
        st.send(far)
        send_program("127.0.0.1", streaming_program(watchdog_min_hz=5.0), sim.secondary_port)
        st.hold(1)
        state = st.client.wait_for(lambda s: s["output_int_register_25"] == ProgramState.START_REJECTED, 1.0, "a refused start")
        assert state["runtime_state"] == 1
        assert max(abs(a - b) for a, b in zip(sim.q, st.state["actual_q"])) < 1e-12  # it never moved
    (ev,) = sim.events("start_rejected")
    assert "joint 2" in ev.message


def test_injected_protective_stop_and_drop_during_streaming(sim):
    with Streamer(sim) as st:
        st.start_program()
        st.hold(20)
        sim.trigger_protective_stop("light curtain")
        state = st.client.wait_for(lambda s: s["safety_mode"] == 3, 1.0, "the injected protective stop")
        assert state["runtime_state"] == 1
    with Streamer(sim) as st:
        with powered_dashboard(sim) as dash:
            time.sleep(0.3)
            dash.unlock_protective_stop()
        st.start_program()
        sim.inject_drop(after_s=0.05)
        with pytest.raises(RTDEError, match="closed by the controller"):
            for _ in range(1000):
                st.hold(1)
    sim.wait_for(lambda s: s.runtime_state == 1, 1.0, "the watchdog after the drop")
    assert sim.events("watchdog")


# ---------------------------------------------------------------------------- CLI


def test_cli_runs_until_interrupted():
    proc = subprocess.Popen(
        [sys.executable, "-m", "robocritics.testing.ursim", "--rtde-port", "0", "--dashboard-port", "0", "--secondary-port", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = proc.stdout.readline()
        assert line.startswith("URSim on 127.0.0.1: RTDE "), line + proc.stderr.read()
        dash_port = int(line.split("dashboard ")[1].split(",")[0])
        with DashboardClient("127.0.0.1", dash_port, timeout_s=2.0) as dash:
            assert dash.robot_mode() == "RUNNING"
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=5) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
