"""Hostile command lines: every bad input exits 2 with exactly one line on stderr naming the argument or file,
nothing on stdout, no traceback. Most cases run `main([...])`; a few run the real `python -m robocritics`."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from robocritics import cli

GOOD_PROGRAM = "move_to(0.3, 0.1, 0.2)\n"
CUBE = {"id": "cube", "shape": "box", "size": [0.04, 0.04, 0.04], "position": [0.3, 0.0, 0.02]}


@pytest.fixture
def files(tmp_path):
    """Named hostile inputs, written to files in tmp_path."""
    contents = {
        "prog.py": GOOD_PROGRAM,
        "binary.bin": bytes(range(256)) * 4,
        "latin1.json": '{"name": "caf\xe9"}'.encode("latin-1"),
        "deep.json": "[" * 100_000 + "]" * 100_000,
        "bigint.json": '{"objects": [{"id": "cube", "shape": "box", "size": [0.04, 0.04, 0.04], "position": ['
        + "9" * 5000
        + ", 0, 0.02]}]}",
        "e300.json": json.dumps({"objects": [{**CUBE, "position": [1e300, 0, 0.02]}]}),
        "nan_ws.json": '{"workspace": {"center": [NaN, 0, 0.15]}}',
        "nan_table.json": '{"table": {"top_z": NaN}}',
        "nan_yaw.json": '{"containers": [{"id": "box_1", "size": [0.1, 0.1, 0.1], "position": [0.3, 0.2, 0.05], "yaw": NaN}]}',
        "home.json": json.dumps({"objects": [{**CUBE, "id": "home"}]}),
        "print.json": json.dumps({"objects": [{**CUBE, "id": "print"}]}),
        "lib.json": json.dumps({"objects": [{**CUBE, "id": "lib"}]}),
        "objects.json": json.dumps({"containers": [{"id": "objects", "size": [0.1, 0.1, 0.1], "position": [0.3, 0.2, 0.05]}]}),
        "keyword.json": json.dumps({"objects": [{**CUBE, "id": "class"}]}),
        "params_deep.json": '{"joint_speed": ' * 50 + "{}" + "}" * 50,
        "params_bigint.json": '{"joint_speed": {"warn_speed_m_s": ' + "9" * 5000 + "}}",
        "big.py": "# " + "x" * 1_100_000 + "\n",
        "slow.py": "reduce_speed(0.01)\nmove_to(0.3, 0.1, 0.2)\n",
        "waits.py": "for i in range(1000):\n    wait(10)\n",  # 2.8 h of motion: over a million samples at 125 Hz
    }
    for name, content in contents.items():
        (tmp_path / name).write_bytes(content if isinstance(content, bytes) else content.encode())
    (tmp_path / "folder").mkdir()
    os.mkfifo(tmp_path / "pipe.py")
    return tmp_path


def run(capsys, argv):
    code = cli.main(argv)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize(
    "argv, words",
    [
        # --rate: the documented range, named
        (["check", "prog.py", "--rate", "2"], "argument --rate: the sample rate must lie in [25, 500] Hz (sparser sampling"),
        (["check", "prog.py", "--rate", "1e7"], "argument --rate: the sample rate must lie in [25, 500] Hz (no controller"),
        (["check", "prog.py", "--rate", "nan"], "argument --rate: the sample rate must lie in [25, 500] Hz (not a finite number)"),
        (["check", "prog.py", "--rate", "-inf"], "argument --rate:"),
        (["check", "prog.py", "--rate", "fast"], "argument --rate: 'fast' is not a number of Hz"),
        (["check", "prog.py", "--rate", ""], "argument --rate: '' is not a number of Hz"),
        # --scene: every bad file is named with its problem
        (["check", "prog.py", "--scene", "folder"], "scene file 'folder' is a directory, not a file"),
        (["check", "prog.py", "--scene", "binary.bin"], "scene file 'binary.bin' is not UTF-8 text"),
        (["check", "prog.py", "--scene", "latin1.json"], "scene file 'latin1.json' is not UTF-8 text (invalid continuation byte at byte 13)"),
        (["check", "prog.py", "--scene", "deep.json"], "deep.json: JSON nested 100000 deep (from line 1); the limit is 32"),
        (["check", "prog.py", "--scene", "bigint.json"], "bigint.json: objects[0].position[0]: a 5000-digit integer is out of range"),
        (["check", "prog.py", "--scene", "e300.json"], "e300.json: objects[0].position[0]: 1e+300 is out of range"),
        (["check", "prog.py", "--scene", "nan_ws.json"], "nan_ws.json: workspace.center[0]: nan is not a finite number"),
        (["check", "prog.py", "--scene", "nan_table.json"], "nan_table.json: table.top_z: nan is not a finite number"),
        (["check", "prog.py", "--scene", "nan_yaw.json"], "nan_yaw.json: containers[0].yaw: nan is not a finite number"),
        (["check", "prog.py", "--scene", "home.json"], "home.json: objects[0].id: 'home' is a skill in robot programs"),
        (["check", "prog.py", "--scene", "print.json"], "print.json: objects[0].id: 'print' is a builtin of robot programs"),
        (["check", "prog.py", "--scene", "lib.json"], "lib.json: objects[0].id: 'lib' is the module 'lib' of robot programs"),
        (["check", "prog.py", "--scene", "objects.json"], "objects.json: containers[0].id: 'objects' is the list of the scene's objects"),
        (["check", "prog.py", "--scene", "keyword.json"], "keyword.json: objects[0].id: 'class' is a Python keyword"),
        (["check", "prog.py", "--scene", "/dev/zero"], "scene file '/dev/zero' is not a regular file"),
        (["check", "prog.py", "--scene", "missing.json"], "no such scene file 'missing.json'"),
        (["check", "prog.py", "--scene", ""], "--scene is empty"),
        (["check", "prog.py", "--scene", "s" * 5000], "(5,000 characters)': File name too long"),
        (["check", "prog.py", "--scene", "s" * 100], "no built-in scene 'sssss"),
        (["check", "prog.py", "--scene", "x\x00.json"], "cannot read scene file"),
        # the program file
        (["check", "folder"], "program file 'folder' is a directory, not a file"),
        (["check", "binary.bin"], "program file 'binary.bin' is not UTF-8 text (invalid start byte at byte 128)"),
        (["check", "pipe.py"], "program file 'pipe.py' is not a regular file"),
        (["check", "big.py"], "program file 'big.py' is larger than the limit of 1,000,000 bytes"),
        (["check", ""], "the program file name is empty"),
        (["check", "n\x00.py"], "cannot read program file"),
        # --params and --critics
        (["check", "prog.py", "--params", "params_deep.json"], "params file 'params_deep.json': JSON nested 51 deep"),
        (["check", "prog.py", "--params", "params_bigint.json"], "joint_speed"),
        (["check", "prog.py", "--params", "binary.bin"], "params file 'binary.bin' is not UTF-8 text"),
        (["check", "prog.py", "--params", "folder"], "params file 'folder' is a directory, not a file"),
        (["check", "prog.py", "--critics", ","], "no critics selected"),
        # deploy: ports and hosts are checked before anything connects
        (["deploy", "prog.py", "--rtde-port", "70000"], "argument --rtde-port: '70000' is not a TCP port (a whole number from 1 to 65535)"),
        (["deploy", "prog.py", "--dashboard-port", "0"], "argument --dashboard-port: '0' is not a TCP port"),
        (["deploy", "prog.py", "--secondary-port", "-1"], "argument --secondary-port: '-1' is not a TCP port"),
        (["deploy", "prog.py", "--rtde-port", "3e4"], "argument --rtde-port: '3e4' is not a TCP port"),
        (["deploy", "prog.py", "--rtde-port", "9" * 5000], "is not a TCP port"),
        (["deploy", "prog.py", "--host", ""], "argument --host: '' is empty"),
        (["deploy", "prog.py", "--host", "x" * 300], "argument --host: 'xxxx"),
        (["deploy", "prog.py", "--host", "a." + "b" * 70 + ".com"], "labels are at most 63 characters"),
        (["deploy", "prog.py", "--scene", "home.json"], "objects[0].id: 'home' is a skill"),
        (["deploy", "binary.bin"], "program file 'binary.bin' is not UTF-8 text"),
        # argparse's own errors are one line too
        (["check"], "robocritics check: error: the following arguments are required: PROGRAM (see robocritics check --help)"),
        (["check", "prog.py", "--no-such-option"], "unrecognized arguments: --no-such-option"),
        (["nonsense"], "robocritics: error: argument COMMAND: invalid choice: 'nonsense'"),
    ],
)
def test_bad_input_exits_2_with_one_line_naming_it(capsys, monkeypatch, files, argv, words):
    monkeypatch.chdir(files)
    code, out, err = run(capsys, argv)
    assert (code, out) == (2, ""), err
    assert err.endswith("\n") and err.count("\n") == 1, err
    assert words in err
    assert "Traceback" not in err and len(err) < 600


def test_a_good_program_still_checks(capsys, monkeypatch, files):
    monkeypatch.chdir(files)
    code, out, err = run(capsys, ["check", "prog.py", "--rate", "25", "--critics", "joint_speed"])
    assert code == 0 and err == "" and out.startswith("RoboCritics report: score ")


@pytest.mark.parametrize(
    "argv, words",
    [
        (["check", "deep.json", "--scene", "deep.json"], "robocritics: error: SceneError: deep.json: JSON nested 100000 deep"),
        (["check", "prog.py", "--rate", "2"], "robocritics check: error: argument --rate: the sample rate must lie in [25, 500] Hz"),
        (["deploy", "prog.py", "--host", "x" * 300, "--dry-run"], "robocritics deploy: error: argument --host:"),
    ],
)
def test_the_real_command_prints_no_traceback(files, argv, words):
    # the installed entry point, end to end (interpreter start-up, imports, exit status)
    done = subprocess.run(
        [sys.executable, "-m", "robocritics", *argv], cwd=files, capture_output=True, text=True, timeout=120, check=False
    )
    assert (done.returncode, done.stdout) == (2, ""), done.stderr
    assert done.stderr.count("\n") == 1 and done.stderr.startswith(words), done.stderr


@pytest.mark.parametrize(
    "argv, words, line",
    [
        # legal programs, impossible motions: the planner's typed errors, with the line, as the runtime critic's Error
        (["check", "slow.py"], "ProgramError: line 1, column 1: reduce_speed: percent must be in 1 <= percent <= 100, got 0.01", 1),
        (["check", "waits.py"], "MotionBudgetError: line 2: wait(seconds=10): the trajectory needs more than 1,000,000 samples", 2),
    ],
)
def test_a_program_that_cannot_run_is_a_runtime_error_report(capsys, monkeypatch, files, argv, words, line):
    monkeypatch.chdir(files)
    code, out, err = run(capsys, argv)
    assert code == 1, err
    assert err.count("\n") == 1 and words in err and "Traceback" not in err
    assert "runtime" in out and f"line {line}" in out
