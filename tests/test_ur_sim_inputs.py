"""Issue 22, class 7 (the ``ursim`` part): bad options of ``robocritics ursim`` are one line on stderr and exit
status 2, never a traceback (``--rtde-port 99999`` was an OverflowError); the loopback controller bounds what a
client sends it too."""

from __future__ import annotations

import math
import socket
import subprocess
import sys

import pytest

from robocritics.cli import main
from robocritics.errors import DeployError
from robocritics.testing.ursim import URSim
from ur_support import sim_kwargs


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--rtde-port", "99999"], "argument --rtde-port: '99999' is not a TCP port"),
        (["--dashboard-port", "-1"], "argument --dashboard-port: '-1' is not a TCP port"),
        (["--secondary-port", "1" * 5000], "is not a TCP port"),
        (["--rtde-port", "0x10"], "'0x10' is not a TCP port"),
        (["--initial-q", "nan", "0", "0", "0", "0", "0"], "argument --initial-q: 'nan' is not a finite number"),
        (["--initial-q", "0", "inf", "0", "0", "0", "0"], "'inf' is not a finite number"),
        (["--host", "\x1b[2Jno.such.host.invalid", "--rtde-port", "0"], "cannot listen on \\x1b[2Jno.such.host.invalid"),
        (["--host", "a" * 300, "--rtde-port", "0"], "cannot listen on"),
        (["--model", "ur99"], "argument --model: invalid choice"),
    ],
    ids=["rtde_port_too_big", "negative_port", "huge_port", "hex_port", "nan_joint", "inf_joint", "escape_in_host",
         "long_host", "unknown_model"],
)
def test_a_bad_option_is_one_line_and_exit_2(capsys, argv, words):
    assert main(["ursim", *argv]) == 2
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("robocritics ursim: error: ") and words in lines[0], err
    assert "Traceback" not in err and "\x1b" not in err and len(err) < 1200 and out == ""


def test_the_command_itself_exits_2_with_one_line():
    done = subprocess.run([sys.executable, "-m", "robocritics", "ursim", "--rtde-port", "99999"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "is not a TCP port" in done.stderr and "Traceback" not in done.stderr


def test_a_port_in_use_is_one_line_and_exit_2(capsys):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        port = s.getsockname()[1]
        assert main(["ursim", "--rtde-port", str(port), "--dashboard-port", "0", "--secondary-port", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"cannot listen on 127.0.0.1:{port} (rtde_port)" in err


@pytest.mark.parametrize("kw, words", [
    ({"rtde_port": 99999}, "rtde_port must be a TCP port"),
    ({"dashboard_port": -5}, "dashboard_port must be a TCP port"),
    ({"secondary_port": "30002"}, "secondary_port must be a TCP port"),
    ({"initial_q": (0.0, math.nan, 0.0, 0.0, 0.0, 0.0)}, "initial_q must be 6 finite joint positions"),
])
def test_the_controller_refuses_bad_ports_and_joints_with_a_typed_error(kw, words):
    with pytest.raises(DeployError, match=words):
        URSim(**{**sim_kwargs(), **kw})


def test_corrupting_an_integer_field_with_nan_is_refused():
    """INT32 cannot carry NaN on the wire; the injection says so instead of crashing the control loop."""
    with URSim(**sim_kwargs(clock="stepped")) as sim:
        with pytest.raises(DeployError, match="robot_mode.*INT32 on the wire"):
            sim.corrupt_output("robot_mode", math.nan)
        with pytest.raises(DeployError, match="no output field"):
            sim.corrupt_output("no_such_field")


def test_a_dashboard_line_without_end_ends_the_connection():
    with URSim(**sim_kwargs(clock="stepped")) as sim:
        with socket.create_connection(("127.0.0.1", sim.dashboard_port), timeout=5) as s:
            s.recv(100)
            try:
                s.sendall(b"x" * 100_000)
            except OSError:
                pass
            data = b""
            while True:
                try:
                    chunk = s.recv(4096)
                except OSError:
                    break
                if not chunk:
                    break
                data += chunk
        assert data == b"could not understand: line too long\n"
