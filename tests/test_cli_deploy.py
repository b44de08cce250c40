"""`robocritics deploy` end to end against the loopback UR controller on 127.0.0.1.

The first test is the user's story: `robocritics ursim` in one process, then `robocritics deploy
PROGRAM --host 127.0.0.1` with nothing but the ports, streamed in real time. Its program is the
careful sorting program cut after the first apple is placed (about 17 s of motion instead of 59 s, to keep
the suite short); the whole program is the same code path. The others run the controller in-process
on simulated time.
"""

import socket
from pathlib import Path

import numpy as np

from robocritics import Robot, Scene, simulate
from robocritics.cli import main
from robocritics.deploy import resample
from robocritics.testing.ursim import URSim
from ur_support import controller_process, stepped

ROOT = Path(__file__).resolve().parent.parent
PROGRAM = "set_speed(0.5)\nmove_to(0.28, 0.05, 0.22)\nmove_down(0.04)\n"


def ports(sim):
    return ["--rtde-port", str(sim.rtde_port), "--dashboard-port", str(sim.dashboard_port), "--secondary-port", str(sim.secondary_port)]


def first_apple_of(careful_source: str) -> str:
    """The careful sorting program, placing only the first apple."""
    head, loop = careful_source.split("for apple in objects:")
    assert "pick(apple)" in loop
    return head + "apple = objects[0]\npick(apple)\nbox = brown_box if apple.ripeness == 'ripe' else white_box\n" \
        "place_in(box, spots[box.id].pop())\n"


def test_a_first_deploy_to_a_fresh_ursim_needs_no_flags(tmp_path, capsys):
    careful = tmp_path / "sorting_first_apple.py"  # the file name picks the sorting scene, as for `check`
    careful.write_text(first_apple_of((ROOT / "examples" / "programs" / "sorting_careful.py").read_text()))
    expected = simulate(careful.read_text(), Scene.builtin("sorting"))  # a fresh ursim is at the model's home pose
    with controller_process() as ctl:
        start = ctl.state()
        assert main(["deploy", str(careful), "--host", "127.0.0.1", *ctl.ports(), "--dry-run"]) == 0
        out = capsys.readouterr().out
        assert "score 10/10" in out and "dry run:" in out and "gate passed, nothing sent" in out
        assert ctl.state()["actual_q"] == start["actual_q"]  # a dry run moves nothing

        assert main(["deploy", str(careful), "--host", "127.0.0.1", *ctl.ports()]) == 0
        out = capsys.readouterr().out
        end = ctl.state()
    assert "score 10/10" in out  # the trajectory `robocritics check` judges: planned from the same pose
    assert f"deployed {len(resample(expected.trajectory))} setpoints at 500 Hz" in out
    np.testing.assert_allclose(end["actual_q"], expected.trajectory.q[-1], atol=1e-3)
    assert (end["runtime_state"], end["safety_mode"], end["output_int_register_25"]) == (1, 1, 2)  # program DONE


def test_deploy_plans_from_where_the_arm_is(tmp_path, capsys):
    q0 = np.array(Robot.ur3e().home_q) + [0.3, 0.1, -0.2, 0.0, 0.0, 0.4]
    program = tmp_path / "short.py"
    program.write_text(PROGRAM)
    with URSim(**stepped(idle_after_s=0.05, initial_q=q0)) as sim:
        assert main(["deploy", str(program), "--scene", "sorting", *ports(sim)]) == 0
        final = simulate(PROGRAM, Scene.builtin("sorting"), start_q=q0).trajectory.q[-1]
        np.testing.assert_allclose(sim.q, final, atol=1e-3)
        assert not sim.events("start_rejected") and len(sim.events("program_started")) == 1
    out = capsys.readouterr().out
    assert "planned from the arm's joints [" + ", ".join(f"{v:.4f}" for v in q0) + "] rad" in out
    assert "score 10/10" in out


def test_deploy_refuses_a_program_with_errors(capsys):
    with URSim(**stepped(idle_after_s=0.05)) as sim:
        before = np.array(sim.q)
        assert main(["deploy", str(ROOT / "examples" / "programs" / "sorting_naive.py"), *ports(sim)]) == 1
        err = capsys.readouterr().err
        assert "deploy stopped" in err and "[report_errors]" in err and "Error" in err
        np.testing.assert_array_equal(sim.q, before)
        assert not sim.events("program_started")


def test_a_bad_program_is_reported_before_connecting(tmp_path, capsys):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        closed_port = s.getsockname()[1]  # nothing listens here
    program = tmp_path / "bad.py"
    program.write_text("move_to(0.3, 0.0\n")
    assert main(["deploy", str(program), "--rtde-port", str(closed_port)]) == 2
    err = capsys.readouterr().err
    assert "ProgramError" in err and "line 1" in err and "cannot connect" not in err
    program.write_text(PROGRAM)
    assert main(["deploy", str(program), "--rtde-port", str(closed_port)]) == 1
    assert f"cannot connect to RTDE at 127.0.0.1:{closed_port}" in capsys.readouterr().err


def test_deploy_exits_1_when_the_arm_reports_joints_that_are_not_numbers(tmp_path, capsys):
    """Issue 22: NaN joints at the gate passed the start-pose rule and the command exited 0."""
    import math

    program = tmp_path / "short.py"
    program.write_text(PROGRAM)
    with URSim(**stepped(idle_after_s=0.05)) as sim:
        before = np.array(sim.q)
        sim.corrupt_output("actual_q", math.nan, index=3)
        assert main(["deploy", str(program), "--scene", "sorting", *ports(sim)]) == 1
        np.testing.assert_array_equal(sim.q, before)
        assert not sim.events("program_started")
    out, err = capsys.readouterr()
    assert "deploy stopped: RTDE 127.0.0.1" in err and "actual_q[3] = nan" in err and err.count("\n") == 1
    assert "planned from" not in out  # nothing was planned from a NaN


def test_deploy_exits_1_when_a_value_turns_infinite_mid_stream(tmp_path, capsys):
    import math

    program = tmp_path / "short.py"
    program.write_text(PROGRAM)
    with URSim(**stepped(idle_after_s=0.05)) as sim:
        sim.at_program_time(0.3, lambda: sim.corrupt_output("timestamp", -math.inf))
        assert main(["deploy", str(program), "--scene", "sorting", *ports(sim)]) == 1
        sim.wait_for(lambda s: s.program is None and max(map(abs, s.qd)) == 0.0, 5.0, "the arm to stop")
    err = capsys.readouterr().err
    assert "deploy stopped [non_finite]" in err and "timestamp = -inf" in err
