"""The loopback controller's text servers: the Dashboard Server (port 29999, one reply line per command line)
and the secondary interface (port 30002, program text). Functions of the :class:`URSim` they serve.

Part of :mod:`robocritics.testing.ursim` (see :mod:`~robocritics.testing.ursim.controller`).
"""

from __future__ import annotations

import re
import socket
import time

from robocritics._text import safe_text
from robocritics.deploy import urscript
from robocritics.deploy.rtde import MessageLevel, RobotMode, RuntimeState, SafetyMode, TextMessage
from robocritics.errors import DeployError
from robocritics.testing.ursim.servo import _HoldProgram, _StreamProgram
from robocritics.testing.ursim.state import CONTROLLER_STOP_DECEL, DT, _enum_name

MAX_LINE_BYTES = 4096
"""Longest dashboard command line the controller reads [bytes]; a longer one ends the connection."""
MAX_SCRIPT_CHARS = 1_000_000
"""Longest program text the secondary interface holds before its ``end`` [characters]."""

LOCAL_CONTROL_REPLY = "Command is not allowed due to safety reasons: the robot is in local control"
UNLOCK_TOO_EARLY_REPLY = (
    "Cannot unlock protective stop until 5s after occurrence. Always inspect cause of protective stop before unlocking"
)


# ---------------------------------------------------------------------------- dashboard server

def serve_dashboard(sim: "URSim", sock: socket.socket, peer: str) -> None:
    with sim._aux_connection(sock):
        sock.sendall(b"Connected: Universal Robots Dashboard Server\n")
        f = sock.makefile("rb")
        while True:
            raw = f.readline(MAX_LINE_BYTES + 1)
            if not raw:
                break
            if len(raw) > MAX_LINE_BYTES:  # a real controller answers nothing useful to that either
                sock.sendall(b"could not understand: line too long\n")
                break
            line = raw.decode("utf-8", "replace").strip()
            if not line:
                continue
            reply, close = dashboard_reply(sim, line)
            sim._event("dashboard", safe_text(f"{peer}: {line!r} -> {reply!r}", 600))
            if sim._silent_dashboard:
                continue
            if sim._reply_delay_s:
                time.sleep(sim._reply_delay_s)
            sock.sendall(reply.encode("utf-8") + b"\n")
            if close:
                break

def dashboard_reply(sim: "URSim", line: str) -> tuple[str, bool]:
    low = re.sub(r"\s+", " ", line.strip()).lower()
    with sim._lock:
        s = sim._state
        remote = sim.remote_control
        if low == "quit":
            return "Disconnected", True
        if low == "robotmode":
            return f"Robotmode: {_enum_name(RobotMode, s.robot_mode)}", False
        if low == "safetystatus":
            return f"Safetystatus: {_enum_name(SafetyMode, s.safety_mode)}", False
        if low == "safetymode":
            return f"Safetymode: {_enum_name(SafetyMode, s.safety_mode)}", False
        if low == "is in remote control":
            return ("true" if remote else "false"), False
        if low == "running":
            return f"Program running: {'true' if s.runtime_state == RuntimeState.PLAYING else 'false'}", False
        if low == "programstate":
            state = _enum_name(RuntimeState, s.runtime_state)
            name = sim._program.name if sim._program is not None else (sim._loaded_program or "<unnamed>")
            return f"{state} {name}", False
        if low == "polyscopeversion":
            return "URSoftware {}.{}.{}.{} (robocritics URSim)".format(*sim.controller_version), False
        if low == "get robot model":
            return sim.model.dashboard_model, False
        if low == "get loaded program":
            return (f"Loaded program: {sim._loaded_program}" if sim._loaded_program else "No program loaded"), False
        if low == "close safety popup":
            return "closing safety popup", False
        if low == "close popup":
            return "closing popup", False
        if low in ("power on", "power off", "brake release", "play", "stop", "pause", "unlock protective stop") or low.startswith("load "):
            if not remote:
                return LOCAL_CONTROL_REPLY, False
        if low == "power on":
            if s.robot_mode < RobotMode.IDLE:
                s.robot_mode = RobotMode.IDLE
            return "Powering on", False
        if low == "power off":
            if sim._program is not None:
                sim._end_program("program_ended", f"{sim._program.name} stopped: power off", None)
            s.robot_mode = RobotMode.POWER_OFF
            s.qd = [0.0] * 6
            sim._stopping_decel = None
            return "Powering off", False
        if low == "brake release":
            s.robot_mode = RobotMode.RUNNING
            return "Brake releasing", False
        if low.startswith("load "):
            prog = line.strip()[5:].strip()
            if not prog.endswith(".urp"):
                return f"File not found: {prog}", False
            sim._loaded_program = prog
            return f"Loading program: {prog}", False
        if low == "play":
            if sim._loaded_program is None or s.robot_mode != RobotMode.RUNNING or s.safety_mode != SafetyMode.NORMAL:
                return "Failed to execute: play", False
            if sim._program is None:
                sim._start_program(_HoldProgram(sim._loaded_program))
            elif s.runtime_state == RuntimeState.PAUSED:
                s.runtime_state = RuntimeState.PLAYING
            return "Starting program", False
        if low == "stop":
            if sim._program is None:
                return "Failed to execute: stop", False
            sim._end_program("program_ended", f"{sim._program.name} stopped from the dashboard", CONTROLLER_STOP_DECEL)
            return "Stopped", False
        if low == "pause":
            if sim._program is None:
                return "Failed to execute: pause", False
            s.runtime_state = RuntimeState.PAUSED
            return "Pausing program", False
        if low == "unlock protective stop":
            if s.safety_mode == SafetyMode.PROTECTIVE_STOP:
                since = (s.tick - (sim._protective_stop_tick or 0)) * DT
                if since < sim.unlock_delay_s:
                    return UNLOCK_TOO_EARLY_REPLY, False
                s.safety_mode = SafetyMode.NORMAL
                sim._event("protective_stop_released", "protective stop released from the dashboard")
            return "Protective stop releasing", False
    return f"could not understand: '{safe_text(line, 200)}'", False

# ---------------------------------------------------------------------------- secondary interface

def serve_secondary(sim: "URSim", sock: socket.socket, peer: str) -> None:
    text = ""
    with sim._aux_connection(sock):
        while sim._running.is_set():
            chunk = sock.recv(65536)
            if not chunk:
                break
            text += chunk.decode("utf-8", "replace")
            text = _take_programs(sim, text, peer, final=False)
            if len(text) > MAX_SCRIPT_CHARS:
                msg = f"program from {peer} rejected: more than {MAX_SCRIPT_CHARS:,} characters without an end"
                sim._event("program_rejected", msg)
                sim._broadcast(TextMessage(msg, "Controller", MessageLevel.ERROR))
                return
        _take_programs(sim, text, peer, final=True)

def _take_programs(sim: "URSim", text: str, peer: str, final: bool) -> str:
    while True:
        m = re.search(r"^end[ \t]*\r?$", text, flags=re.MULTILINE)
        if m is None or not re.search(r"^def\s", text[: m.start()], flags=re.MULTILINE):
            break
        _receive_script(sim, text[: m.end()], peer)
        text = text[m.end() :].lstrip("\r\n")
    if final and text.strip():
        _receive_script(sim, text, peer)
        text = ""
    return text

def _receive_script(sim: "URSim", script: str, peer: str) -> None:
    with sim._lock:
        s = sim._state
        reason = None
        params = None
        if not sim.remote_control:
            reason = "the robot is in local control (enable remote control on the teach pendant)"
        elif s.robot_mode != RobotMode.RUNNING:
            reason = f"the robot is not running (robot mode {_enum_name(RobotMode, s.robot_mode)}); power on and release the brakes"
        elif s.safety_mode != SafetyMode.NORMAL:
            reason = f"safety mode is {_enum_name(SafetyMode, s.safety_mode)}; unlock the protective stop first"
        else:
            try:
                params = urscript.parse_streaming_program(script)
            except DeployError as exc:
                reason = f"{exc} — this loopback controller only runs robocritics streaming programs"
        if reason is not None or params is None:
            msg = f"program from {peer} rejected: {safe_text(reason, 400)}"
            sim._event("program_rejected", msg)
            sim._broadcast(TextMessage(msg, "Controller", MessageLevel.ERROR))
            return
        if sim._program is not None:
            sim._event("program_ended", f"{sim._program.name} replaced by a new program")
        sim._start_program(_StreamProgram(sim, params))
        # a client that sends a program is active: no idle cycle before its next setpoint is read
        sim._last_input_wall = time.monotonic()
