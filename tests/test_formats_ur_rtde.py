"""A real ur_rtde recording: `robocritics deploy` of a program to the loopback controller while ur_rtde's
``RTDEReceiveInterface.startFileRecording`` records it, then the CSV checked back like the program.

ur_rtde always talks to port 30004, so the controller runs in real time on it (skipped when the port is taken);
the recorder runs in its own process (ur_rtde's constructor holds the GIL while it waits for replies).
"""

import subprocess
import sys
import time

import pytest

from robocritics import Scene, critique, simulate
from robocritics.cli import main
from robocritics.errors import DeployError
from robocritics.formats import load_motion
from robocritics.testing.ursim import URSim

PROGRAM = "set_speed(0.6)\nmove_to(0.28, 0.05, 0.22)\nmove_down(0.04)\nmove_to(0.2, -0.1, 0.25)\nmove_to(0.25, 0.1, 0.2)\n"

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


def test_a_ur_rtde_recording_of_a_deployed_program_scores_like_the_program(tmp_path, capsys):
    pytest.importorskip("rtde_receive", reason="ur-rtde is not installed")
    scene = Scene.builtin("sorting")
    program = tmp_path / "sorting_moves.py"
    program.write_text(PROGRAM)
    expected = simulate(PROGRAM, scene)  # a fresh controller is at the model's home pose: the same plan
    expected_report = critique(expected)
    try:
        sim = URSim(dashboard_port=0, secondary_port=0).start()
    except DeployError as exc:
        pytest.skip(f"port 30004 is taken; ur-rtde always uses it: {exc}")
    csv, stop = tmp_path / "recording.csv", tmp_path / "stop"
    recorder = subprocess.Popen(
        [sys.executable, "-c", RECORDER, str(csv), str(stop)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        assert recorder.stdout.readline().strip() == "recording", recorder.stderr.read()[-2000:]
        time.sleep(0.3)  # a still lead-in, as a real recording has
        ports = ["--dashboard-port", str(sim.dashboard_port), "--secondary-port", str(sim.secondary_port)]
        assert main(["deploy", str(program), "--host", "127.0.0.1", *ports]) == 0
        assert "score 10/10" in capsys.readouterr().out
        time.sleep(0.3)
        stop.touch()
        assert recorder.wait(timeout=30) == 0, recorder.stderr.read()[-2000:]
    finally:
        if recorder.poll() is None:
            recorder.kill()
        recorder.stdout.close()
        recorder.stderr.close()
        sim.stop()
    header = csv.read_text().splitlines()[0]
    assert header.startswith("timestamp,actual_q_0")
    recorded = load_motion(csv, scene=scene)
    assert recorded.source == "ur_rtde recording recording.csv"
    report = critique(recorded)
    assert abs(report.score - expected_report.score) <= 1
    assert recorded.duration_s == pytest.approx(expected.duration_s, rel=0.01)
    assert main(["check", str(csv), "--scene", "sorting"]) in (0, 1)
    assert "motion from ur_rtde recording recording.csv" in capsys.readouterr().out
