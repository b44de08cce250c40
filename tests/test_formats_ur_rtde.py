"""A real ur_rtde recording: `robocritics deploy` of a program to the loopback controller while ur_rtde's
``RTDEReceiveInterface.startFileRecording`` records it, then the CSV checked back like the program.

ur_rtde always talks to port 30004, so the controller (``robocritics ursim`` in its own process, as a real
controller runs on its own machine) runs in real time on it (skipped when the port is taken); the recorder runs
in its own process too (ur_rtde's constructor holds the GIL while it waits for replies).
"""

import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from robocritics import Scene, critique, simulate
from robocritics.cli import main
from robocritics.formats import load_motion
from robocritics.formats.load import moving_span
from ur_support import controller_process

#: about 12 s of motion: long enough that the controller's settling at the end (its servo lag decaying, ~0.1 s
#: with the streaming program's lookahead) stays within the 1 % the recorded duration is held to
PROGRAM = (
    "set_speed(0.4)\nmove_to(0.28, 0.05, 0.22)\nmove_down(0.04)\nmove_to(0.2, -0.1, 0.25)\nmove_to(0.25, 0.1, 0.2)\n"
    "move_to(0.15, 0.2, 0.25)\nmove_to(0.3, -0.05, 0.18)\nmove_to(0.2, -0.15, 0.22)\nhome()\n"
)

RECORDER = r"""
import os, sys, time
import rtde_receive
r = rtde_receive.RTDEReceiveInterface("127.0.0.1", 500.0, ["timestamp", "actual_q"])
assert r.startFileRecording(sys.argv[1], ["timestamp", "actual_q"])
print("recording", flush=True)
deadline = time.time() + 120
while not os.path.exists(sys.argv[2]) and time.time() < deadline:
    time.sleep(0.01)
r.stopFileRecording()
r.disconnect()
"""


def record_a_deploy(program: Path, tmp_path: Path, capsys) -> tuple[Path, str] | None:
    """Deploy ``program`` to a fresh controller on port 30004 (its own process) while ur_rtde records it:
    ``(csv, deploy output)``, or None when the deploy was stopped by a fault (a starved real-time stream)."""
    csv, stop = tmp_path / "recording.csv", tmp_path / "stop"
    for leftover in (csv, stop):
        leftover.unlink(missing_ok=True)
    with controller_process("--rtde-port", "30004") as ctl:
        recorder = subprocess.Popen(
            [sys.executable, "-c", RECORDER, str(csv), str(stop)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        try:
            assert recorder.stdout.readline().strip() == "recording", recorder.stderr.read()[-2000:]
            time.sleep(0.3)  # a still lead-in, as a real recording has
            ports = ["--dashboard-port", str(ctl.dashboard_port), "--secondary-port", str(ctl.secondary_port)]
            status = main(["deploy", str(program), "--host", "127.0.0.1", *ports])
            out, err = capsys.readouterr()
            time.sleep(0.3)
            stop.touch()
            assert recorder.wait(timeout=30) == 0, recorder.stderr.read()[-2000:]
        finally:
            if recorder.poll() is None:
                recorder.kill()
            recorder.stdout.close()
            recorder.stderr.close()
    if status != 0:
        assert "deploy stopped" in err, err  # a fault of the real-time stream on a starved machine, nothing else
        return None
    return csv, out


def test_a_ur_rtde_recording_of_a_deployed_program_scores_like_the_program(tmp_path, capsys):
    pytest.importorskip("rtde_receive", reason="ur-rtde is not installed")
    if not _port_free(30004):
        pytest.skip("port 30004 is taken; ur-rtde always uses it")
    scene = Scene.builtin("sorting")
    program = tmp_path / "sorting_moves.py"
    program.write_text(PROGRAM)
    expected = simulate(PROGRAM, scene)  # a fresh controller is at the model's home pose: the same plan
    expected_report = critique(expected)
    for _ in range(3):  # a real-time stream on a loaded 2-core machine can be starved into a watchdog stop
        recorded_run = record_a_deploy(program, tmp_path, capsys)
        if recorded_run is not None:
            break
    else:
        pytest.fail("three deploys in a row were stopped by faults")
    csv, out = recorded_run
    assert "score 10/10" in out
    streamed = re.search(r"deployed \d+ setpoints at 500 Hz in ([\d.]+) s \(trajectory ([\d.]+) s\)", out)
    header = csv.read_text().splitlines()[0]
    assert header.startswith("timestamp,actual_q_0")
    late_s = float(streamed.group(1)) - float(streamed.group(2))
    recorded = load_motion(csv, scene=scene)
    assert recorded.source == "ur_rtde recording recording.csv"
    report = critique(recorded)
    first, last = moving_span(expected.trajectory.q, expected.trajectory.gripper_opening_m)
    motion_s = float(expected.trajectory.time[last] - expected.trajectory.time[first])
    with capsys.disabled():  # the measurement, shown with -s
        print(f"\nrecorded {recorded.duration_s:.3f} s, score {report.score:g}; program motion {motion_s:.3f} s "
              f"(trajectory {expected.duration_s:.3f} s), score {expected_report.score:g}; stream late {late_s:.3f} s")
    assert abs(report.score - expected_report.score) <= 1
    # A recording is judged from the arm's first motion to its last (moving_span: the still lead-in and tail, the
    # arm waiting and settling, are not the program's); the program's motion by the same rule. The controller
    # runs the motion as the setpoints arrive: on a loaded machine the stream can fall behind (the deploy reports
    # its wall time), which stretches the recorded motion by about that much; beyond it, 2 % (the recorder's own
    # samples, on a machine loaded to 8 runnable processes per core, drifted by 1.06 %).
    assert float(streamed.group(2)) == pytest.approx(expected.duration_s, abs=0.01)
    assert motion_s > 0.95 * expected.duration_s
    assert abs(recorded.duration_s - motion_s) <= 0.02 * motion_s + max(0.0, late_s)
    assert main(["check", str(csv), "--scene", "sorting"]) in (0, 1)
    assert "motion from ur_rtde recording recording.csv" in capsys.readouterr().out


def _port_free(port: int) -> bool:
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the controller binds: TIME_WAIT is no obstacle
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True
