"""`robocritics deploy` end to end against the loopback UR controller on 127.0.0.1."""

import numpy as np
import pytest

from robocritics import Robot, Scene, simulate
from robocritics.cli import main
from robocritics.testing.ursim import URSim

PROGRAM = "set_speed(0.5)\nmove_to(0.28, 0.05, 0.22)\nmove_down(0.04)\n"


@pytest.fixture
def sim():
    with URSim(rtde_port=0, dashboard_port=0, secondary_port=0, robot_mode="RUNNING", initial_q=Robot.ur3e().home_q) as s:
        yield s


def ports(sim):
    return ["--rtde-port", str(sim.rtde_port), "--dashboard-port", str(sim.dashboard_port), "--secondary-port", str(sim.secondary_port)]


def test_deploy_streams_the_verified_program(sim, tmp_path, capsys):
    program = tmp_path / "short.py"
    program.write_text(PROGRAM)
    assert main(["deploy", str(program), "--scene", "sorting", *ports(sim)]) == 0
    final = simulate(PROGRAM, Scene.builtin("sorting")).trajectory.q[-1]
    np.testing.assert_allclose(sim.q, final, atol=1e-3)
    assert "score 10/10" in capsys.readouterr().out


def test_deploy_refuses_a_program_with_errors(sim, capsys):
    before = np.array(sim.q)
    assert main(["deploy", "examples/programs/sorting_naive.py", *ports(sim)]) == 1
    err = capsys.readouterr().err
    assert "deploy stopped" in err and "Error" in err
    np.testing.assert_array_equal(sim.q, before)
    assert not sim.events("program_started")
