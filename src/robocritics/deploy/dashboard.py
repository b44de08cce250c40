"""Client for the UR Dashboard Server (TCP port 29999, newline-terminated text).

The controller greets every connection with ``Connected: Universal Robots
Dashboard Server`` and then answers one line per command line::

    with DashboardClient("192.168.1.10") as dash:
        if not dash.is_in_remote_control():
            raise ...                       # programs sent over 30002 would be ignored
        dash.power_on(); dash.wait_robot_mode("IDLE", timeout_s=30)
        dash.brake_release(); dash.wait_robot_mode("RUNNING", timeout_s=30)

Every exchange has a timeout; an unexpected reply or a timeout raises
:class:`~robocritics.errors.RTDEError` quoting the command and the reply.
"""

from __future__ import annotations

import socket
import time

from robocritics._text import safe_text
from robocritics.deploy.rtde import RobotMode
from robocritics.errors import RTDEError

__all__ = ["DASHBOARD_PORT", "GREETING", "DashboardClient"]

DASHBOARD_PORT = 29999
GREETING = "Connected: Universal Robots Dashboard Server"
MAX_REPLY_BYTES = 4096
"""Longest reply line accepted [bytes]; the controller's longest answers are a few hundred."""


def _quoted(reply: str) -> str:
    """A controller's reply for an error message: escaped and clipped (it is outside text)."""
    return "'" + safe_text(reply, 200) + "'"


class DashboardClient:
    """A Dashboard Server connection.

    ``timeout_s`` bounds connecting and every command/reply exchange [s].
    Methods raise :class:`RTDEError` when the controller answers something
    unexpected (the message quotes command and reply) or does not answer.
    """

    def __init__(self, host: str, port: int = DASHBOARD_PORT, timeout_s: float = 2.0) -> None:
        self.host = host
        self.port = int(port)
        self.timeout_s = float(timeout_s)
        self._sock: socket.socket | None = None
        self._buf = b""

    @property
    def address(self) -> str:
        return f"{self.host}:{self.port}"

    def __enter__(self) -> "DashboardClient":
        if self._sock is None:
            self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ connection

    def connect(self) -> str:
        """Connect and check the greeting; returns the greeting line."""
        if self._sock is not None:
            raise RTDEError(f"dashboard client for {self.address} is already connected")
        try:
            self._sock = socket.create_connection((self.host, self.port), timeout=self.timeout_s)
        except socket.timeout:
            raise RTDEError(f"cannot connect to the dashboard server at {self.address}: no answer within {self.timeout_s:g} s") from None
        except (OSError, UnicodeError, OverflowError) as exc:  # also a bad host label or port number
            raise RTDEError(f"cannot connect to the dashboard server at {self.address}: {getattr(exc, 'strerror', None) or exc}") from None
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._buf = b""
        try:
            greeting = self._read_line("waiting for the greeting")
        except RTDEError:
            self._drop()
            raise
        if not greeting.startswith(GREETING):
            self._drop()
            raise RTDEError(f"{self.address} is not a UR dashboard server: greeting was {_quoted(greeting)}, expected {GREETING!r}")
        return greeting

    def close(self) -> None:
        """Say ``quit`` (best effort) and close the connection."""
        if self._sock is None:
            return
        try:
            self._sock.sendall(b"quit\n")
            self._sock.settimeout(min(self.timeout_s, 0.5))
            self._sock.recv(256)
        except OSError:
            pass
        self._drop()

    quit = close

    def _drop(self) -> None:
        if self._sock is not None:
            try:
                self._sock.close()
            finally:
                self._sock = None

    # ------------------------------------------------------------------ raw exchange

    def command(self, text: str, timeout_s: float | None = None) -> str:
        """Send one command line and return the reply line (without the newline)."""
        if self._sock is None:
            raise RTDEError(f"dashboard client for {self.address} is not connected; call connect() first")
        if "\n" in text:
            raise RTDEError(f"dashboard command must be one line, got {text!r}")
        try:
            self._sock.settimeout(self.timeout_s if timeout_s is None else timeout_s)
            self._sock.sendall(text.encode("utf-8") + b"\n")
        except socket.timeout:
            raise RTDEError(f"dashboard {self.address}: sending {text!r} timed out") from None
        except OSError as exc:
            self._drop()
            raise RTDEError(f"dashboard connection to {self.address} failed while sending {text!r}: {getattr(exc, 'strerror', None) or exc}") from None
        return self._read_line(f"waiting for the reply to {text!r}", timeout_s)

    def _read_line(self, doing: str, timeout_s: float | None = None) -> str:
        assert self._sock is not None
        timeout = self.timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + timeout
        while b"\n" not in self._buf:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise RTDEError(f"dashboard server at {self.address} did not answer within {timeout:g} s while {doing}")
            try:
                self._sock.settimeout(remaining)
                chunk = self._sock.recv(4096)
            except socket.timeout:
                continue
            except OSError as exc:
                self._drop()
                raise RTDEError(f"dashboard connection to {self.address} failed while {doing}: {getattr(exc, 'strerror', None) or exc}") from None
            if not chunk:
                self._drop()
                raise RTDEError(f"dashboard server at {self.address} closed the connection while {doing}")
            self._buf += chunk
            if b"\n" not in self._buf and len(self._buf) > MAX_REPLY_BYTES:
                self._drop()
                raise RTDEError(f"dashboard server at {self.address} sent more than {MAX_REPLY_BYTES} bytes without "
                                f"a line end while {doing}")
        line, _, self._buf = self._buf.partition(b"\n")
        return line.decode("utf-8", "replace").rstrip("\r")

    def _expect(self, text: str, *accepted: str) -> str:
        reply = self.command(text)
        if not any(reply.lower().startswith(a.lower()) for a in accepted):
            raise RTDEError(
                f"dashboard {self.address}: {text!r} failed: controller replied {_quoted(reply)} "
                f"(expected {' or '.join(repr(a) for a in accepted)})"
            )
        return reply

    # ------------------------------------------------------------------ commands

    def power_on(self) -> None:
        """Power the arm on (robot mode goes POWER_OFF → IDLE, brakes still engaged)."""
        self._expect("power on", "Powering on")

    def power_off(self) -> None:
        self._expect("power off", "Powering off")

    def brake_release(self) -> None:
        """Release the brakes (robot mode IDLE → RUNNING)."""
        self._expect("brake release", "Brake releasing")

    def load(self, program: str) -> None:
        """Load a program file (``.urp``) stored on the controller."""
        self._expect(f"load {program}", "Loading program")

    def play(self) -> None:
        """Start the loaded program; raises if nothing is loaded or the robot is not ready."""
        self._expect("play", "Starting program")

    def pause(self) -> None:
        self._expect("pause", "Pausing program")

    def stop(self) -> bool:
        """Stop the running program. Returns False if no program was running ('Failed to execute: stop')."""
        reply = self.command("stop")
        if reply.startswith("Stopped"):
            return True
        if reply.startswith("Failed to execute"):
            return False
        raise RTDEError(f"dashboard {self.address}: 'stop' got unexpected reply {_quoted(reply)}")

    def robot_mode(self) -> str:
        """Robot mode, e.g. ``"RUNNING"``, ``"IDLE"``, ``"POWER_OFF"`` (a :class:`~robocritics.deploy.rtde.RobotMode` name)."""
        reply = self._expect("robotmode", "Robotmode:")
        return reply.split(":", 1)[1].strip()

    def safety_status(self) -> str:
        """Safety status, e.g. ``"NORMAL"`` or ``"PROTECTIVE_STOP"`` (a :class:`~robocritics.deploy.rtde.SafetyMode` name)."""
        reply = self._expect("safetystatus", "Safetystatus:")
        return reply.split(":", 1)[1].strip()

    def program_state(self) -> str:
        """Program state line, e.g. ``"PLAYING robocritics_stream"`` or ``"STOPPED <unnamed>"``."""
        return self.command("programState")

    def running(self) -> bool:
        """True if a program is running (``running`` → ``Program running: true``)."""
        reply = self._expect("running", "Program running:")
        return reply.split(":", 1)[1].strip().lower() == "true"

    def unlock_protective_stop(self) -> None:
        """Release a protective stop. The controller refuses within 5 s of the stop; that raises."""
        self._expect("unlock protective stop", "Protective stop releasing")

    def close_safety_popup(self) -> None:
        self._expect("close safety popup", "closing safety popup")

    def is_in_remote_control(self) -> bool:
        """True if the pendant is in remote control (needed to run programs sent to port 30002)."""
        reply = self.command("is in remote control").strip().lower()
        if reply not in ("true", "false"):
            raise RTDEError(f"dashboard {self.address}: 'is in remote control' got unexpected reply {_quoted(reply)}")
        return reply == "true"

    def robot_model(self) -> str:
        """The arm's model as the dashboard names it (``get robot model`` → ``"UR3"``, ``"UR5"``, ``"UR10"``, ``"UR16"``)."""
        reply = self.command("get robot model").strip()
        if not reply or len(reply) > 32 or not reply.replace("-", "").replace("_", "").isalnum():
            raise RTDEError(f"dashboard {self.address}: 'get robot model' got unexpected reply {_quoted(reply)}")
        return reply

    def polyscope_version(self) -> str:
        return self.command("PolyscopeVersion")

    def wait_robot_mode(self, mode: str, timeout_s: float = 10.0, poll_s: float = 0.05) -> None:
        """Poll ``robotmode`` until it equals ``mode`` [s]; raises with the last mode on timeout."""
        mode = mode.upper()
        if mode not in RobotMode.__members__:
            raise RTDEError(f"unknown robot mode {_quoted(mode)}; one of {', '.join(RobotMode.__members__)}")
        deadline = time.monotonic() + timeout_s
        current = self.robot_mode()
        while current != mode:
            if time.monotonic() >= deadline:
                raise RTDEError(f"dashboard {self.address}: robot mode is {_quoted(current)}, not {mode}, after {timeout_s:g} s")
            time.sleep(poll_s)
            current = self.robot_mode()
