"""Dashboard client, URScript streaming program and the loopback controller's simulation of it.

Real sockets on 127.0.0.1, ephemeral ports. The controller's rules (watchdog, stall,
protective stop, unlock delay) are tested on simulated time (``clock="stepped"``:
one control cycle per setpoint sent, plus ``step()``), so every count below is exact
however loaded the machine is.
"""

from __future__ import annotations

import signal
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
from robocritics.robot.arms import UR3E
from ur_support import DT, Streamer, controller_process, powered_dashboard, sim_kwargs, stepped


@pytest.fixture
def sim():
    """A real-time controller, for the protocol conversations (no timing asserted)."""
    with URSim(**sim_kwargs()) as s:
        yield s


@pytest.fixture
def ssim():
    """A controller on simulated time."""
    with URSim(**stepped()) as s:
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


def test_unlock_protective_stop_is_refused_until_the_delay_passed(ssim):
    ssim.trigger_protective_stop("operator test")
    t_stop = ssim.time_s
    with powered_dashboard(ssim) as dash:
        assert dash.safety_status() == "PROTECTIVE_STOP"
        ssim.step(round(0.3 / DT) - 1)  # unlock_delay_s = 0.3 s of controller time, less one cycle
        with pytest.raises(RTDEError, match="Cannot unlock protective stop until 5s"):
            dash.unlock_protective_stop()
        assert dash.safety_status() == "PROTECTIVE_STOP"
        ssim.step(1)
        assert ssim.time_s - t_stop == pytest.approx(0.3)
        dash.unlock_protective_stop()
        assert dash.safety_status() == "NORMAL"


def test_a_new_controller_is_running_at_the_models_home_pose():
    """One default for ``URSim()`` and ``robocritics ursim``: RUNNING, at the pose ``simulate`` starts from."""
    from robocritics import Robot

    with URSim(**stepped()) as sim:
        snap = sim.snapshot()
        assert snap.robot_mode_name == "RUNNING" and snap.safety_mode_name == "NORMAL" and snap.runtime_state_name == "STOPPED"
        assert snap.q == pytest.approx(tuple(Robot.ur3e().home_q), abs=1e-12)
        assert sim.speed_limits == UR3E.velocity_rad_s


def test_a_stepped_controller_stands_still_until_it_is_clocked():
    with URSim(**stepped()) as sim:
        with RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0) as c:
            c.setup_outputs(["timestamp"], 500)
            c.setup_inputs(["input_int_register_30"])
            c.start()
            time.sleep(0.05)
            assert c.packages_received == 0 and sim.time_s == 0.0  # wall time does not move it
            assert sim.step(10) == pytest.approx(10 * DT)
            c.wait_for(lambda st: st["timestamp"] == pytest.approx(10 * DT), 1.0, "the 10th cycle")
            for k in range(5):
                c.send({"input_int_register_30": k})  # every input package is one cycle
            c.wait_for(lambda st: st["timestamp"] == pytest.approx(15 * DT), 1.0, "the cycles of 5 inputs")
            assert c.packages_received == 15
        with pytest.raises(DeployError, match="needs clock='stepped'"):
            URSim(**sim_kwargs()).step()
        with pytest.raises(DeployError, match="clock must be one of realtime, stepped"):
            URSim(clock="fast")


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


def test_streamed_servo_sequence_reaches_its_target(ssim):
    with Streamer(ssim) as st:
        start = st.start_program()
        assert start["output_int_register_26"] == 7
        q0 = list(st.q)
        target = [q0[0] + 0.6, q0[1] - 0.3, q0[2] + 0.4, q0[3] + 0.8, q0[4] - 0.5, q0[5] + 1.0]
        st.move(target, 1.0)
        st.hold(150, gripper_m=0.01)
        mid = ssim.snapshot()
        assert mid.runtime_state == 2 and mid.safety_mode == 1
        assert mid.applied_seq == st.seq  # lockstep: every setpoint was applied in its own cycle
        end = st.finish()
        status = program_status(end)
        assert status.state is ProgramState.DONE and status.applied_seq == st.seq and status.session == 7
        assert status.gripper_opening_m == 0.01
        err = max(abs(a - b) for a, b in zip(end["actual_q"], target))
        assert err < 2e-3
        snap = ssim.snapshot()
        assert snap.program is None and snap.runtime_state == 1 and max(map(abs, snap.qd)) == 0.0
        assert snap.gripper_opening_m == 0.01 and snap.digital_out & (1 << 16)  # placeholder gripper closed
    kinds = [e.kind for e in ssim.events()]
    assert kinds.index("program_started") < kinds.index("done") < kinds.index("program_ended")
    assert not ssim.events("protective_stop") and not ssim.events("watchdog")


def test_watchdog_stops_the_program_when_the_client_goes_quiet(ssim):
    with Streamer(ssim) as st:
        st.start_program(watchdog_min_hz=10.0)  # the watchdog allows 1/10 Hz = 0.1 s without an update
        st.hold(50)
        quiet_from = ssim.time_s  # the cycle of the last update
        ssim.step(round(0.1 / DT) - 1)
        assert ssim.snapshot().runtime_state == 2  # 0.1 s without an update is still allowed…
        ssim.step(2)
        state = ssim.snapshot()
        assert state.runtime_state == 1 and state.program is None  # …a cycle more is not
        (ev,) = ssim.events("watchdog")
        assert ev.time_s - quiet_from == pytest.approx(0.1)  # 0.1 s after the cycle that read the last update
        assert "program robocritics_stream stopped" in ev.message and "not updated for 0.102 s" in ev.message
        assert state.program_state == ProgramState.STREAMING  # the controller, not the program, stopped it
        ssim.step(1)
        st.client.wait_for(lambda s: s["runtime_state"] == 1, 1.0, "the stop to be reported")
        deadline = time.monotonic() + 1.0
        msgs = []
        while not any("watchdog" in m.message for m in msgs) and time.monotonic() < deadline:
            msgs += st.client.messages()
            time.sleep(0.01)
        assert any("RTDE watchdog: input_int_register_24 not updated" in m.message for m in msgs)


def test_a_counter_that_stops_changing_stalls_the_program(ssim):
    with Streamer(ssim) as st:
        st.start_program(watchdog_min_hz=4.0)  # stall after 125 unchanged cycles; updates keep the watchdog quiet
        st.hold(20)
        program = parse_streaming_program(streaming_program(watchdog_min_hz=4.0))
        assert program.stall_limit_cycles == 125
        for n in range(1, program.stall_limit_cycles + 1):
            state = st.send(st.q, bump=False)  # updates keep coming (watchdog happy) but the counter is frozen
            assert state["output_int_register_25"] == ProgramState.STREAMING, n
        state = st.send(st.q, bump=False)  # the 126th unchanged cycle
        assert state["output_int_register_25"] == ProgramState.STALLED
        state = st.finish()  # stopj, then the program ends
        assert state["output_int_register_25"] == ProgramState.STALLED
    assert ssim.events("stalled") and not ssim.events("watchdog")


def test_setpoint_jump_causes_a_protective_stop_but_a_fast_legal_move_does_not(ssim):
    with Streamer(ssim) as st:
        st.start_program()
        step = 0.9 * UR3E.velocity_rad_s[0] * DT  # 90 % of the base speed limit
        q = list(st.q)
        for _ in range(150):
            q[0] += step
            state = st.send(q)
        assert state["safety_mode"] == 1 and not ssim.events("protective_stop")
        jump = list(st.q)
        jump[1] += 0.05  # 25 rad/s for one 2 ms step
        state = st.send(jump)
        assert state["safety_mode"] == 3 and state["runtime_state"] == 1  # in the very cycle it arrived
        (ev,) = ssim.events("protective_stop")
        assert "setpoint jump on joint 1" in ev.message and "rad/s" in ev.message
        with powered_dashboard(ssim) as dash:
            assert dash.safety_status() == "PROTECTIVE_STOP"
        # 10 rad/s² from about 0.9 π rad/s: standing still within 0.3 s
        ssim.step_until(lambda s: max(map(abs, s.qd)) == 0.0, 0.3, "the arm to stand still")


def test_first_setpoint_far_from_the_arm_is_refused(ssim):
    with Streamer(ssim) as st:
        far = list(st.q)
        far[2] += 0.3
        st.send(far)
        send_program("127.0.0.1", streaming_program(watchdog_min_hz=5.0), ssim.secondary_port)
        state = st.hold(1)
        assert state["output_int_register_25"] == ProgramState.START_REJECTED and state["runtime_state"] == 1
        assert max(abs(a - b) for a, b in zip(ssim.q, st.state["actual_q"])) < 1e-12  # it never moved
    (ev,) = ssim.events("start_rejected")
    assert "joint 2" in ev.message


def test_injected_protective_stop_and_drop_during_streaming(ssim):
    with Streamer(ssim) as st:
        st.start_program()
        st.hold(20)
        ssim.trigger_protective_stop("light curtain")
        state = st.hold(1)
        assert state["safety_mode"] == 3 and state["runtime_state"] == 1
    ssim.step(round(0.3 / DT))  # the unlock delay, in controller time
    with powered_dashboard(ssim) as dash:
        dash.unlock_protective_stop()
    with Streamer(ssim) as st:
        st.start_program()
        ssim.inject_drop(after_s=0.05)
        sent = st.seq
        with pytest.raises(RTDEError, match="closed by the controller"):
            st.hold(1000)
        assert st.seq - sent == round(0.05 / DT)  # dropped in the cycle 0.05 s later
    ssim.step_until(lambda s: s.runtime_state == 1, 0.2, "the watchdog after the drop")
    assert ssim.events("watchdog")


# ---------------------------------------------------------------------------- CLI


def test_cli_runs_until_interrupted():
    from robocritics import Robot

    with controller_process() as ctl:
        with DashboardClient("127.0.0.1", ctl.dashboard_port, timeout_s=2.0) as dash:
            assert dash.robot_mode() == "RUNNING"  # the same default as URSim()
        assert ctl.state()["actual_q"] == pytest.approx(tuple(Robot.ur3e().home_q), abs=1e-12)
        ctl.proc.send_signal(signal.SIGINT)
        assert ctl.proc.wait(timeout=60) == 0  # a clean exit; the bound only has to hold on a loaded machine


def test_cli_options_reach_the_controller():
    q0 = (0.1, -1.2, 1.3, -1.4, -1.5, 0.6)
    with controller_process("--robot-mode", "POWER_OFF", "--local-control", "--initial-q", *map(str, q0)) as ctl:
        with DashboardClient("127.0.0.1", ctl.dashboard_port, timeout_s=2.0) as dash:
            assert dash.robot_mode() == "POWER_OFF" and dash.is_in_remote_control() is False
        assert ctl.state()["actual_q"] == pytest.approx(q0, abs=1e-12)
