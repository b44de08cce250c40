"""Issue 22, classes 5 (RTDE part) and 6: a malicious controller floods, forges and truncates.

The controller is the loopback one (real RTDE on 127.0.0.1) with raw packages injected
(``URSim.inject_packages``) or text messages broadcast; the dashboard attacks use a hand-written
TCP server on 127.0.0.1. Packages nobody asked for are counted, never queued, logged once per kind, and a
flood is a fault that stops the arm; text from the controller never reaches a terminal or a log unescaped or
unbounded.
"""

from __future__ import annotations

import logging
import math
import os
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from robocritics.deploy import DashboardClient, DeployFault, RTDEClient
from robocritics.deploy.rtde import (
    MAX_UNEXPECTED_PACKAGES,
    MESSAGE_CHARS,
    Command,
    MessageLevel,
    RTDEFloodError,
    pack_package,
)
from robocritics.errors import RTDEError
from robocritics.testing.ursim import URSim
from test_ur_deploy import (  # noqa: F401  (fixtures)
    arm_for,
    assert_stopped,
    check_fault,
    controller,
    fault_during,
    home,
    motion,
    scene,
)
from ur_support import STATE_FIELDS, stepped

ROOT = Path(__file__).resolve().parent.parent
EVIL = "\x1b[2J\x1b[H\x1b]0;pwned\x07\x9b31m\u202eDEPLOYED OK\r\n"
"""Clears the screen, homes the cursor, sets the window title, an 8-bit CSI, a bidi override, a forged line."""
UNSAFE = ("\x1b", "\x07", "\x9b", "\u202e", "\r")


def _wait(predicate, timeout_s: float = 5.0, what: str = "condition") -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"{what} not reached within {timeout_s} s")
        time.sleep(0.002)


def _streaming_client(sim: URSim, protocol_version: int = 2) -> RTDEClient:
    client = RTDEClient("127.0.0.1", sim.rtde_port, timeout_s=1.0, protocol_version=protocol_version)
    client.connect()
    client.setup_outputs(STATE_FIELDS, 500)
    client.start()
    return client


# ---------------------------------------------------------------------------- floods of packages nobody asked for


def test_unknown_packages_are_counted_logged_once_per_kind_and_never_queued(caplog):
    caplog.set_level(logging.WARNING, logger="robocritics.deploy.rtde")
    with URSim(**stepped()) as sim:
        client = _streaming_client(sim)
        try:
            sim.inject_packages(0x42, b"\x00" * 61, count=400)  # 'B': no such RTDE package type
            sim.inject_packages(0x7A, b"", count=100)  # 'z'
            _wait(lambda: client.packages_unexpected == 500, what="500 unexpected packages read")
            assert client.connected
            assert len(client._replies) == 0  # nothing kept for them (the 2.1 GB queue)
            lines = [r.getMessage() for r in caplog.records if "nobody asked for" in r.getMessage()]
            assert len(lines) == 2 and "66" in lines[0] and "'z'" not in lines[0]
            client.pause()  # requests still pair with their replies
            client.start()
            n0 = client.packages_received
            sim.step(2)
            _wait(lambda: client.packages_received > n0, what="data after the restart")
            assert math.isfinite(client.latest()["timestamp"])
            # past the bound: a flood, a typed error, the connection is given up
            sim.inject_packages(0x42, b"", count=MAX_UNEXPECTED_PACKAGES)
            _wait(lambda: not client.connected, what="the flood to fail the connection")
            with pytest.raises(RTDEFloodError, match="flooded the connection") as info:
                client.latest()
            assert info.value.cause == "controller_flood"
        finally:
            client.close()
    summary = [r.getMessage() for r in caplog.records if "were held back" in r.getMessage()]
    assert len(summary) == 1 and "unexpected packages" in summary[0]
    assert len(caplog.records) < 10


@pytest.mark.parametrize(
    "command, payload",
    [
        (0x42, b"x"),  # an unknown type
        (Command.REQUEST_PROTOCOL_VERSION, b"\x01"),  # replies nobody asked for
        (Command.DATA_PACKAGE, b"\x09" + b"\x00" * 8),  # data for a recipe that does not exist
        (Command.TEXT_MESSAGE, b"\xff"),  # malformed text messages
    ],
    ids=["unknown_type", "unrequested_reply", "unknown_recipe", "malformed_message"],
)
def test_a_flood_mid_stream_is_a_fault_that_stops_the_arm(motion, home, command, payload, caplog):
    caplog.set_level(logging.WARNING, logger="robocritics.deploy.rtde")
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            exc, elapsed = fault_during(sim, arm, execution, report, 0.7,
                                        lambda: sim.inject_packages(command, payload, count=MAX_UNEXPECTED_PACKAGES + 50))
        check_fault(exc, execution, "controller_flood")
        assert exc.stopped and elapsed < 0.7 + 5.0
        assert_stopped(sim)
    assert sum("nobody asked" in r.getMessage() or "unknown recipe" in r.getMessage()
               or "malformed" in r.getMessage() for r in caplog.records) <= 2


def test_fewer_unexpected_packages_than_the_bound_do_not_stop_a_deployment(motion, home):
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            sim.at_program_time(0.5, lambda: sim.inject_packages(0x42, b"", count=MAX_UNEXPECTED_PACKAGES // 2))
            result = arm.deploy(execution, report, watchdog_min_hz=2.0)
            assert arm.rtde.packages_unexpected >= MAX_UNEXPECTED_PACKAGES // 2
        assert result.final_error_rad < 1e-3


@pytest.mark.parametrize(
    "raw, cause",
    [
        (struct.pack(">HB", 200, Command.DATA_PACKAGE) + b"\x01", "connection_drop"),  # swallows the next packages
        (struct.pack(">HB", 2, Command.DATA_PACKAGE), "connection_drop"),  # a size below the header's own
    ],
    ids=["truncated_data_package", "size_below_header"],
)
def test_a_malformed_package_mid_stream_stops_the_arm(motion, home, raw, cause):
    execution, report = motion
    with controller(home) as sim:
        with arm_for(sim) as arm:
            exc, _ = fault_during(sim, arm, execution, report, 0.7, lambda: sim.inject_packages(0, raw=raw))
        check_fault(exc, execution, cause)
        assert exc.stopped
        assert_stopped(sim)


def test_a_controller_that_drops_the_connection_inside_a_package_stops_the_arm(motion, home):
    execution, report = motion

    def cut():
        sim.inject_packages(0, raw=struct.pack(">HB", 60, Command.DATA_PACKAGE) + b"\x01\x00")
        sim.inject_drop()

    with controller(home) as sim:
        with arm_for(sim) as arm:
            exc, _ = fault_during(sim, arm, execution, report, 0.7, cut)
        check_fault(exc, execution, "connection_drop")
        assert exc.stopped and "dashboard stop" in exc.stop_report
        assert_stopped(sim)


# ---------------------------------------------------------------------------- text from the controller


def test_controller_text_is_escaped_clipped_and_its_log_lines_bounded(caplog):
    caplog.set_level(logging.INFO, logger="robocritics.deploy.rtde")
    with URSim(**stepped()) as sim:
        client = _streaming_client(sim)
        try:
            for _ in range(3000):
                sim.broadcast_message(EVIL * 10, level=MessageLevel.ERROR, source="Contr\x1b[8moller")
            _wait(lambda: len(client._messages) == client._messages.maxlen, what="the messages")
            time.sleep(0.2)
            messages = client.messages()
            assert client.connected  # messages are the controller's right: no fault, only bounds
        finally:
            client.close()
    assert len(messages) == 256  # the newest, bounded
    for m in messages:
        assert not any(c in m.message + m.source for c in UNSAFE)
        assert "\\x1b[2J" in m.message and "\\u202eDEPLOYED OK" in m.message and "\\x1b[8m" in m.source
    logged = [r.getMessage() for r in caplog.records if "EVIL" in r.getMessage() or "DEPLOYED OK" in r.getMessage()]
    assert len(logged) == 20  # LOGGED_MESSAGES_PER_KIND for one level and source; the rest counted
    assert not any(c in line for line in logged for c in UNSAFE)
    assert any("were held back" in r.getMessage() for r in caplog.records)


def test_huge_text_messages_are_cut_with_a_note():
    """Protocol 1 messages are as long as a package (64 kB); 14-22 MB reached stderr."""
    with URSim(**stepped(protocol_versions=(1,))) as sim:
        client = _streaming_client(sim, protocol_version=1)
        try:
            assert client.protocol_version == 1
            for _ in range(50):
                sim.broadcast_message(EVIL + "A" * 60_000, level=MessageLevel.ERROR)
            _wait(lambda: sim.step() >= 0 and len(client._messages) == 50, what="50 messages")  # cycles flush
            messages = client.messages()
        finally:
            client.close()
    for m in messages:
        assert len(m.message) < MESSAGE_CHARS + 40 and "more characters cut]" in m.message
        assert not any(c in m.message for c in UNSAFE)


def test_a_fault_quotes_the_controllers_message_escaped(motion, home):
    execution, report = motion

    def attack():
        sim.broadcast_message(EVIL, level=MessageLevel.ERROR)
        sim.trigger_protective_stop("light curtain " + EVIL + "B" * 100_000)

    with controller(home) as sim:
        with arm_for(sim) as arm:
            exc, _ = fault_during(sim, arm, execution, report, 0.6, attack)
        check_fault(exc, execution, "protective_stop")
    text = str(exc)
    assert "light curtain" in text and "\\x1b]0;pwned\\x07" in text
    assert not any(c in text for c in UNSAFE) and len(text) < 5000
    assert all(not any(c in m for c in UNSAFE) for m in exc.controller_messages)


def test_the_deploy_command_prints_nothing_a_terminal_would_act_on(tmp_path):
    """`robocritics deploy` as a user runs it (its own process, logging to stderr as Python does by default)
    against a controller that floods forged text messages and then protective-stops."""
    program = tmp_path / "short.py"
    program.write_text("set_speed(0.5)\nmove_to(0.28, 0.05, 0.22)\nmove_down(0.04)\n")

    def attack():
        for _ in range(500):
            sim.broadcast_message(EVIL * 8, level=MessageLevel.ERROR, source=EVIL)
        sim.inject_packages(0x42, b"", count=300)
        sim.trigger_protective_stop(EVIL)

    with URSim(**stepped(idle_after_s=0.05)) as sim:
        sim.at_program_time(0.3, attack)
        env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
        done = subprocess.run(
            [sys.executable, "-m", "robocritics", "deploy", str(program), "--scene", "sorting",
             "--rtde-port", str(sim.rtde_port), "--dashboard-port", str(sim.dashboard_port),
             "--secondary-port", str(sim.secondary_port)],
            capture_output=True, timeout=300, env=env,
        )
        assert_stopped(sim)
    err = done.stderr.decode("utf-8")
    assert done.returncode == 1, err[-2000:]
    verdict = [line for line in err.splitlines() if line.startswith("robocritics:")]
    # the flood itself may hold the data packages back long enough to be the first fault seen
    assert len(verdict) == 1 and any(f"deploy stopped: deploy stopped [{cause}]" in verdict[0]
                                     for cause in ("protective_stop", "controller_silent")), verdict
    assert not any(c in err + done.stdout.decode("utf-8") for c in UNSAFE), err[:2000]
    assert "Traceback" not in err and len(err) < 20_000
    # the 300 injected packages are logged once, not 300 times; a deploy that fell silent first (the flood holding
    # the data back on a loaded machine) stopped before it read them
    logged = err.count("nobody asked for")
    assert logged == 1 if "[protective_stop]" in verdict[0] else logged <= 1


# ---------------------------------------------------------------------------- a dashboard server that attacks


def _fake_dashboard(send) -> tuple[socket.socket, threading.Thread]:
    ls = socket.socket()
    ls.bind(("127.0.0.1", 0))
    ls.listen(1)

    def serve():
        conn, _ = ls.accept()
        try:
            send(conn)
        except OSError:
            pass
        finally:
            conn.close()

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    return ls, t


def test_a_dashboard_reply_without_end_is_refused_at_a_bound():
    def endless(conn):
        chunk = b"Connected: Universal Robots Dashboard Server" + b"\x1b[2J" * 4000
        for _ in range(2500):  # 40 MB if nobody stops reading
            conn.sendall(chunk)

    ls, t = _fake_dashboard(endless)
    with ls:
        dash = DashboardClient("127.0.0.1", ls.getsockname()[1], timeout_s=5.0)
        with pytest.raises(RTDEError, match="more than 4096 bytes without a line end"):
            dash.connect()
    t.join(5.0)


def test_a_forged_dashboard_greeting_is_quoted_escaped():
    ls, t = _fake_dashboard(lambda conn: conn.sendall(EVIL.replace("\r\n", "").encode() * 50 + b"\n"))
    with ls:
        dash = DashboardClient("127.0.0.1", ls.getsockname()[1], timeout_s=2.0)
        with pytest.raises(RTDEError) as info:
            dash.connect()
    t.join(5.0)
    text = str(info.value)
    assert "is not a UR dashboard server" in text and "\\x1b[2J" in text and "more characters cut]" in text
    assert not any(c in text for c in UNSAFE)
