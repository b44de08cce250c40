"""RTDE (Universal Robots Real-Time Data Exchange) client, protocol version 2 with fallback to 1.

The wire format (all integers big-endian)::

    package  = uint16 size (whole package, header included) | uint8 type | payload
    'V' 86   request protocol version   payload >H version      reply >B accepted
    'v' 118  controller version         payload (none)          reply >IIII major, minor, bugfix, build
    'O' 79   setup outputs              v2: >d frequency + b"name,name,..."   v1: b"name,..."
                                        reply v2: >B recipe id + b"TYPE,TYPE,..."   v1: b"TYPE,..."
    'I' 73   setup inputs               b"name,name,..."        reply >B recipe id + b"TYPE,..."
    'S' 83   start                      (none)                  reply >B accepted
    'P' 80   pause                      (none)                  reply >B accepted
    'U' 85   data package               inputs: >B recipe id + values
                                        outputs: v2 >B recipe id + values, v1 values only
    'M' 77   text message               v2: >B len, message, >B len, source, >B level
                                        v1: >B level, message

A reply type of ``NOT_FOUND`` marks a field the controller does not know, ``IN_USE``
an input another client or a fieldbus already owns.

Typical use::

    with RTDEClient("192.168.1.10", timeout_s=2.0) as rtde:
        rtde.setup_outputs(["timestamp", "actual_q", "runtime_state"], frequency_hz=500)
        setpoint = rtde.setup_inputs(["input_int_register_24", "input_double_register_24"])
        rtde.start()
        state = rtde.wait_next(timeout_s=0.1)      # blocks for the next package
        rtde.send({"input_int_register_24": 1, "input_double_register_24": 0.5})
        q = rtde.latest()["actual_q"]               # newest values, never blocks

A background thread reads the socket all the time, so the controller never drops
the connection because the client stopped reading; every data package lands in
:meth:`RTDEClient.latest` and in a bounded buffer (:meth:`RTDEClient.drain`).
Every socket operation has a timeout; a dropped or silent controller raises
:class:`~robocritics.errors.RTDEError` naming host, port and what was going on.
"""

from __future__ import annotations

import collections
import logging
import math
import socket
import struct
import threading
import time
from typing import Any, Callable, Mapping, Sequence

from robocritics._text import RepeatLimiter, safe_text
from robocritics.deploy.rtde_wire import (
    _COMMAND_NAMES,
    _HEADER,
    DATA_TYPES,
    LOGGED_MESSAGES_PER_KIND,
    MAX_FREQUENCY_HZ,
    MAX_UNEXPECTED_PACKAGES,
    MESSAGE_CHARS,
    RTDE_PORT,
    V1_FREQUENCY_HZ,
    Command,
    InputRecipe,
    MessageLevel,
    OutputRecipe,
    Recipe,
    RobotMode,
    RTDEFloodError,
    RTDEValueError,
    RuntimeState,
    SafetyMode,
    TextMessage,
    _names_arg,
    decode_text_message,
    encode_text_message,
    first_non_finite,
    mode_name,
    pack_package,
)
from robocritics.errors import RTDEError

__all__ = [
    "RTDE_PORT",
    "RobotMode",
    "SafetyMode",
    "RuntimeState",
    "mode_name",
    "Command",
    "DATA_TYPES",
    "MessageLevel",
    "Recipe",
    "OutputRecipe",
    "InputRecipe",
    "TextMessage",
    "RTDEClient",
    "RTDEValueError",
    "RTDEFloodError",
    "first_non_finite",
    "pack_package",
    "encode_text_message",
    "decode_text_message",
    "MAX_FREQUENCY_HZ",
    "V1_FREQUENCY_HZ",
    "MAX_UNEXPECTED_PACKAGES",
]

log = logging.getLogger(__name__)

class RTDEClient:
    """A client for the RTDE interface of a UR controller (TCP port 30004).

    Parameters
    ----------
    host, port:
        Controller address; ``port`` defaults to 30004.
    timeout_s:
        Timeout of every socket operation and of every request/reply exchange [s].
    protocol_version:
        Highest protocol version to ask for (2); the client falls back to 1 if the
        controller refuses 2.
    buffer_size:
        How many data packages the bounded buffer keeps (oldest dropped first).

    The constructor does not connect; :meth:`connect` (or ``with``) does, and
    negotiates the protocol version and reads the controller version. All methods
    raise :class:`~robocritics.errors.RTDEError` on failure.
    """

    def __init__(
        self,
        host: str,
        port: int = RTDE_PORT,
        timeout_s: float = 2.0,
        protocol_version: int = 2,
        buffer_size: int = 2048,
    ) -> None:
        if protocol_version not in (1, 2):
            raise RTDEError(f"RTDE protocol_version must be 1 or 2, got {protocol_version}")
        if not timeout_s > 0:
            raise RTDEError(f"timeout_s must be > 0 seconds, got {timeout_s}")
        self.host = host
        self.port = int(port)
        self.timeout_s = float(timeout_s)
        self._max_protocol = protocol_version
        self.protocol_version: int = 0
        """Negotiated protocol version (0 before :meth:`connect`)."""
        self.controller_version: tuple[int, int, int, int] | None = None
        """(major, minor, bugfix, build) of the controller software, after :meth:`connect`."""
        self._sock: socket.socket | None = None
        self._reader: threading.Thread | None = None
        self._send_lock = threading.Lock()
        self._request_lock = threading.Lock()
        self._cond = threading.Condition()
        self._replies: collections.deque[tuple[int, bytes]] = collections.deque()
        self._outputs: dict[int, OutputRecipe] = {}
        self._v1_output: OutputRecipe | None = None
        self._inputs: dict[int, InputRecipe] = {}
        self._latest: dict[str, Any] = {}
        self._buffer: collections.deque[dict[str, Any]] = collections.deque(maxlen=buffer_size)
        self._messages: collections.deque[TextMessage] = collections.deque(maxlen=256)
        self._count = 0
        self._dropped = 0
        self._last_rx = 0.0
        self._error: str | None = None
        self._error_type: type[RTDEError] = RTDEError
        self._data_fault: RTDEValueError | None = None
        self._awaiting: int | None = None  # the reply type a request waits for; other packages are unexpected
        self._unexpected = 0
        self._log_once = RepeatLimiter(per_kind=1)
        self._message_log = RepeatLimiter(per_kind=LOGGED_MESSAGES_PER_KIND, kinds=16)
        self._closing = False
        self._started = False
        self._activity = "idle"

    # ------------------------------------------------------------------ lifecycle

    def __enter__(self) -> "RTDEClient":
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def address(self) -> str:
        return f"{self.host}:{self.port}"

    @property
    def connected(self) -> bool:
        """True while the TCP connection is up and no error was seen."""
        return self._sock is not None and self._error is None and not self._closing

    @property
    def started(self) -> bool:
        """True between :meth:`start` and :meth:`pause`."""
        return self._started

    def connect(self) -> None:
        """Open the TCP connection, start the reader thread, negotiate the protocol, read the version."""
        if self._sock is not None:
            raise RTDEError(f"RTDE client for {self.address} is already connected")
        self._activity = "connecting"
        try:
            sock = socket.create_connection((self.host, self.port), timeout=self.timeout_s)
        except socket.timeout:
            raise RTDEError(
                f"cannot connect to RTDE at {self.address}: no answer within {self.timeout_s:g} s "
                "(controller off, wrong address, or a firewall?)"
            ) from None
        except (OSError, UnicodeError, OverflowError) as exc:  # also a bad host label or port number
            raise RTDEError(
                f"cannot connect to RTDE at {self.address}: {getattr(exc, 'strerror', None) or exc} "
                "(is the controller on and the RTDE interface enabled?)"
            ) from None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.settimeout(self.timeout_s)
        self._sock = sock
        self._closing = False
        self._error = None
        self._error_type = RTDEError
        self._data_fault = None
        self._unexpected = 0
        self._log_once = RepeatLimiter(per_kind=1)
        self._message_log = RepeatLimiter(per_kind=LOGGED_MESSAGES_PER_KIND, kinds=16)
        self._reader = threading.Thread(target=self._read_loop, name=f"rtde-reader-{self.address}", daemon=True)
        self._reader.start()
        try:
            self._negotiate()
            self.controller_version = self.get_controller_version()
        except BaseException:
            self.close()
            raise
        self._activity = "connected, not started"

    def close(self) -> None:
        """Pause synchronisation (best effort), close the socket and stop the reader thread."""
        sock = self._sock
        if sock is None:
            return
        if self._started and self._error is None:
            try:
                with self._cond:  # its reply is expected, not a package nobody asked for
                    self._awaiting = Command.CONTROL_PACKAGE_PAUSE
                self._send_raw(pack_package(Command.CONTROL_PACKAGE_PAUSE), "pausing before close")
            except RTDEError:
                pass
        self._closing = True
        self._started = False
        try:
            sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        sock.close()
        if self._reader is not None and self._reader is not threading.current_thread():
            self._reader.join(timeout=self.timeout_s)
        self._sock = None
        self._reader = None
        with self._cond:
            self._cond.notify_all()
        held_back = sum(self._log_once.suppressed().values()) + sum(self._message_log.suppressed().values())
        if held_back:
            log.warning("RTDE %s: %d more log lines of kinds already logged were held back (%d unexpected packages)",
                        self.address, held_back, self._unexpected)

    # ------------------------------------------------------------------ handshake

    def _negotiate(self) -> None:
        for version in range(self._max_protocol, 0, -1):
            reply = self._request(
                Command.REQUEST_PROTOCOL_VERSION, struct.pack(">H", version), f"negotiating protocol version {version}"
            )
            if len(reply) != 1:
                raise RTDEError(f"RTDE {self.address}: malformed reply to protocol version request: {reply!r}")
            if reply[0]:
                self.protocol_version = version
                return
            log.info("RTDE %s refused protocol version %d", self.address, version)
        raise RTDEError(
            f"RTDE controller at {self.address} accepted none of protocol versions "
            f"{', '.join(str(v) for v in range(self._max_protocol, 0, -1))}"
        )

    def get_controller_version(self) -> tuple[int, int, int, int]:
        """Ask the controller for its software version: (major, minor, bugfix, build)."""
        reply = self._request(Command.GET_URCONTROL_VERSION, b"", "reading the controller version")
        if len(reply) != 16:
            raise RTDEError(f"RTDE {self.address}: controller version reply has {len(reply)} bytes, expected 16")
        return struct.unpack(">IIII", reply)  # type: ignore[return-value]

    # ------------------------------------------------------------------ recipes

    def setup_outputs(self, names: Sequence[str] | str, frequency_hz: float = 125.0) -> OutputRecipe:
        """Ask the controller to send ``names`` at ``frequency_hz`` [Hz, 0 < f <= 500].

        Protocol version 1 has no frequency field; the controller then sends at
        125 Hz. Raises :class:`RTDEError` naming any field the controller does
        not know (``NOT_FOUND``).
        """
        names = _names_arg(names)
        freq = float(frequency_hz)
        if not (0.0 < freq <= MAX_FREQUENCY_HZ) or math.isnan(freq):
            raise RTDEError(f"RTDE output frequency must be in (0, {MAX_FREQUENCY_HZ:g}] Hz, got {frequency_hz}")
        text = ",".join(names).encode("ascii")
        if self.protocol_version >= 2:
            payload = struct.pack(">d", freq) + text
        else:
            payload = text
            freq = V1_FREQUENCY_HZ
        reply = self._request(Command.CONTROL_PACKAGE_SETUP_OUTPUTS, payload, f"setting up outputs {names}")
        if self.protocol_version >= 2:
            if not reply:
                raise RTDEError(f"RTDE {self.address}: empty reply to output setup")
            rid, types_txt = reply[0], reply[1:]
        else:
            rid, types_txt = 0, reply
        types = types_txt.decode("ascii", "replace").split(",") if types_txt else []
        self._check_types(names, types, "output")
        if self.protocol_version >= 2 and rid == 0:
            raise RTDEError(f"RTDE controller at {self.address} refused output recipe {names} (recipe id 0)")
        recipe = OutputRecipe(rid, tuple(names), tuple(types))
        recipe.frequency_hz = freq
        with self._cond:
            if self.protocol_version >= 2:
                self._outputs[rid] = recipe
            else:
                self._v1_output = recipe
                self._outputs = {0: recipe}
        return recipe

    def setup_inputs(self, names: Sequence[str] | str) -> InputRecipe:
        """Register an input recipe (fields the client will write with :meth:`send`).

        Raises :class:`RTDEError` naming fields that are unknown (``NOT_FOUND``) or
        owned by another client or a fieldbus (``IN_USE``).
        """
        names = _names_arg(names)
        reply = self._request(
            Command.CONTROL_PACKAGE_SETUP_INPUTS, ",".join(names).encode("ascii"), f"setting up inputs {names}"
        )
        if not reply:
            raise RTDEError(f"RTDE {self.address}: empty reply to input setup")
        rid = reply[0]
        types = reply[1:].decode("ascii", "replace").split(",") if len(reply) > 1 else []
        self._check_types(names, types, "input")
        if rid == 0:
            raise RTDEError(f"RTDE controller at {self.address} refused input recipe {names} (recipe id 0)")
        recipe = InputRecipe(rid, tuple(names), tuple(types))
        self._inputs[rid] = recipe
        return recipe

    def _check_types(self, names: list[str], types: list[str], kind: str) -> None:
        if len(types) != len(names):
            raise RTDEError(
                f"RTDE controller at {self.address} answered {len(types)} types for {len(names)} {kind} fields: "
                f"{safe_text(types, 300)} for {names}"
            )
        not_found = [n for n, t in zip(names, types) if t == "NOT_FOUND"]
        in_use = [n for n, t in zip(names, types) if t == "IN_USE"]
        version = ".".join(str(v) for v in self.controller_version) if self.controller_version else "unknown"
        if not_found:
            raise RTDEError(
                f"RTDE {kind} field(s) {', '.join(repr(n) for n in not_found)} NOT_FOUND: the controller at "
                f"{self.address} (software {version}) doesn't know them — misspelt, or older firmware that lacks "
                "them? Check the RTDE field list for this software version."
            )
        if in_use:
            raise RTDEError(
                f"RTDE input field(s) {', '.join(repr(n) for n in in_use)} IN_USE at {self.address}: another RTDE "
                "client or a fieldbus (EtherNet/IP, PROFINET, Modbus) already owns them. Fieldbuses hold registers "
                "0-23; use registers 24-47, or stop the other client."
            )

    # ------------------------------------------------------------------ start / pause

    def start(self) -> None:
        """Start data synchronisation (needs at least one output recipe)."""
        if not self._outputs:
            raise RTDEError(f"RTDE {self.address}: call setup_outputs() before start()")
        reply = self._request(Command.CONTROL_PACKAGE_START, b"", "starting synchronisation")
        if reply[:1] != b"\x01":
            raise RTDEError(f"RTDE controller at {self.address} refused to start synchronisation (reply {reply[:40]!r})")
        self._started = True
        self._activity = "streaming (synchronisation started)"

    def pause(self) -> None:
        """Pause data synchronisation; recipes stay configured, :meth:`start` resumes."""
        reply = self._request(Command.CONTROL_PACKAGE_PAUSE, b"", "pausing synchronisation")
        if reply[:1] != b"\x01":
            raise RTDEError(f"RTDE controller at {self.address} refused to pause (reply {reply[:40]!r})")
        self._started = False
        self._activity = "connected, paused"

    # ------------------------------------------------------------------ data

    def send(self, input_values: Mapping[str, Any], recipe: InputRecipe | None = None) -> None:
        """Send one input data package.

        ``input_values`` maps every field of one input recipe to its value; the
        recipe is found by its field names unless given. Needs :meth:`start` first.
        """
        self._raise_if_failed("sending inputs")
        if not self._started:
            raise RTDEError(f"RTDE {self.address}: call start() before send()")
        if recipe is None:
            recipe = self._find_input_recipe(input_values)
        payload = bytes((recipe.recipe_id,)) + recipe.pack(input_values)
        self._send_raw(pack_package(Command.DATA_PACKAGE, payload), "sending inputs")

    def _find_input_recipe(self, values: Mapping[str, Any]) -> InputRecipe:
        keys = set(values)
        for r in self._inputs.values():
            if set(r.names) == keys:
                return r
        if not self._inputs:
            raise RTDEError(f"RTDE {self.address}: no input recipe set up; call setup_inputs() first")
        known = [list(r.names) for r in self._inputs.values()]
        raise RTDEError(f"RTDE input values {sorted(keys)} match no input recipe; recipes are {known}")

    def send_message(self, message: str, source: str = "robocritics", level: int = MessageLevel.INFO) -> None:
        """Send a text message to the controller log."""
        payload = encode_text_message(TextMessage(message, source, level), self.protocol_version or 2)
        self._send_raw(pack_package(Command.TEXT_MESSAGE, payload), "sending a text message")

    def latest(self, allow_stale: bool = False) -> dict[str, Any]:
        """The newest value of every output field received so far (empty before the first package).

        Never blocks. Raises :class:`RTDEError` once the connection has dropped, and
        :class:`RTDEValueError` once a data package carried a non-finite number, unless
        ``allow_stale`` (then it returns the last values received before either, e.g. for
        a post-mortem of where the robot was).
        """
        if not allow_stale:
            self._raise_if_failed("reading the latest data")
            self._raise_if_untrusted()
        with self._cond:
            return dict(self._latest)

    def wait_next(self, timeout_s: float | None = None) -> dict[str, Any]:
        """Block until the next data package arrives and return :meth:`latest` at that moment.

        ``timeout_s`` defaults to the client's ``timeout_s`` [s]. Raises
        :class:`RTDEError` if nothing arrives in time (silent controller) or the
        connection drops, :class:`RTDEValueError` once a package carried a non-finite number.
        """
        timeout = self.timeout_s if timeout_s is None else float(timeout_s)
        self._raise_if_failed("waiting for data")
        self._raise_if_untrusted()
        if not self._started:
            raise RTDEError(f"RTDE {self.address}: call start() before waiting for data")
        deadline = time.monotonic() + timeout
        with self._cond:
            start = self._count
            while self._count == start:
                if self._error is not None:
                    break
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise RTDEError(
                        f"no RTDE data package from {self.address} within {timeout:g} s while {self._activity} "
                        f"(controller silent or overloaded; last package {self._age_text()})"
                    )
                self._cond.wait(remaining)
            if self._error is None:
                self._raise_if_untrusted()
                return dict(self._latest)
        self._raise_if_failed("waiting for data")
        raise AssertionError("unreachable")

    receive = wait_next
    """Alias of :meth:`wait_next` (the name the official RTDE client uses)."""

    def wait_for(self, predicate: Callable[[dict[str, Any]], bool], timeout_s: float, what: str) -> dict[str, Any]:
        """Wait until ``predicate(latest())`` is true; ``what`` describes the condition for the error [s]."""
        deadline = time.monotonic() + timeout_s
        state = self.latest()
        while not (state and predicate(state)):
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise RTDEError(f"RTDE {self.address}: timed out after {timeout_s:g} s waiting for {what}; last state {state}")
            try:
                state = self.wait_next(min(remaining, self.timeout_s))
            except RTDEError:
                if self._error is not None or time.monotonic() < deadline:
                    raise
        return state

    def drain(self) -> list[dict[str, Any]]:
        """Remove and return every buffered data package (oldest first), one dict per package.

        Raises :class:`RTDEValueError` once a data package carried a non-finite number."""
        self._raise_if_untrusted()
        with self._cond:
            out = list(self._buffer)
            self._buffer.clear()
        return out

    def messages(self) -> list[TextMessage]:
        """Remove and return the text messages the controller sent (oldest first; at most the newest 256).

        Message and source are outside text, already made safe to print: escape sequences and control
        characters shown as escapes, the message cut after :data:`MESSAGE_CHARS` characters with a note."""
        with self._cond:
            out = list(self._messages)
            self._messages.clear()
        return out

    @property
    def packages_received(self) -> int:
        """Number of data packages received since :meth:`connect`."""
        return self._count

    @property
    def packages_unexpected(self) -> int:
        """Packages nobody asked for (counted, never queued); past :data:`MAX_UNEXPECTED_PACKAGES` the
        connection fails with :class:`RTDEFloodError`."""
        return self._unexpected

    @property
    def packages_dropped(self) -> int:
        """Packages pushed out of the bounded buffer before :meth:`drain` took them."""
        return self._dropped

    def age_s(self) -> float:
        """Seconds since the last data package arrived (``inf`` if none did)."""
        return time.monotonic() - self._last_rx if self._count else math.inf

    @property
    def output_recipes(self) -> list[OutputRecipe]:
        return list(self._outputs.values())

    @property
    def input_recipes(self) -> list[InputRecipe]:
        return list(self._inputs.values())

    # ------------------------------------------------------------------ plumbing

    def _age_text(self) -> str:
        age = self.age_s()
        return "never" if math.isinf(age) else f"{age:.3f} s ago"

    @property
    def data_fault(self) -> RTDEValueError | None:
        """The error of the first data package with a non-finite number (None while every number was finite).

        From then on :meth:`latest`, :meth:`wait_next` and :meth:`drain` raise it; :meth:`send` still works,
        so the client can still tell the controller to stop."""
        return self._data_fault

    def _raise_if_untrusted(self) -> None:
        fault = self._data_fault
        if fault is not None:
            raise RTDEValueError(str(fault), field=fault.field, index=fault.index, value=fault.value,
                                 package=fault.package)

    def _raise_if_failed(self, doing: str) -> None:
        if self._error is not None:
            raise self._error_type(self._error)
        if self._sock is None:
            raise RTDEError(f"RTDE client for {self.address} is not connected (while {doing}); call connect() first")

    def _send_raw(self, data: bytes, doing: str) -> None:
        sock = self._sock
        if sock is None:
            raise RTDEError(f"RTDE client for {self.address} is not connected (while {doing})")
        try:
            with self._send_lock:
                sock.sendall(data)
        except socket.timeout:
            raise RTDEError(
                f"sending to RTDE {self.address} timed out after {self.timeout_s:g} s while {doing} "
                "(controller not reading?)"
            ) from None
        except OSError as exc:
            msg = self._error or (
                f"RTDE connection to {self.address} failed while {doing}: {getattr(exc, 'strerror', None) or exc} "
                f"(after {self._count} data packages; last package {self._age_text()})"
            )
            self._fail(msg)
            raise RTDEError(msg) from None

    def _request(self, command: int, payload: bytes, doing: str) -> bytes:
        self._raise_if_failed(doing)
        with self._request_lock:
            with self._cond:
                self._replies.clear()
                self._awaiting = command
            try:
                return self._exchange(command, payload, doing)
            finally:
                with self._cond:
                    self._awaiting = None

    def _exchange(self, command: int, payload: bytes, doing: str) -> bytes:
        """Send one request and wait for its reply (``_request`` holds the request lock)."""
        previous = self._activity
        self._activity = doing
        self._send_raw(pack_package(command, payload), doing)
        deadline = time.monotonic() + self.timeout_s
        with self._cond:
            while True:
                while self._replies:
                    cmd, body = self._replies.popleft()
                    if cmd == command:
                        self._activity = previous
                        return body
                    self._unexpected_package(f"unexpected reply {_COMMAND_NAMES.get(cmd, cmd)} while {doing}", cmd)
                if self._error is not None:
                    raise self._error_type(self._error)
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    msg = (
                        f"no reply to {_COMMAND_NAMES.get(command, command)} from RTDE {self.address} within "
                        f"{self.timeout_s:g} s while {doing} (controller silent or overloaded)"
                    )
                    # a late reply would be taken for the answer to the next request: give up on this connection
                    self._error = msg
                    self._started = False
                    self._cond.notify_all()
                    raise RTDEError(msg)
                self._cond.wait(remaining)

    def _fail(self, message: str, error_type: type[RTDEError] = RTDEError) -> None:
        with self._cond:
            if self._error is None:
                self._error = message
                self._error_type = error_type
            self._started = False
            self._cond.notify_all()

    def _read_loop(self) -> None:
        sock = self._sock
        assert sock is not None
        buf = bytearray()
        try:
            while not self._closing:
                try:
                    chunk = sock.recv(65536)
                except socket.timeout:
                    continue
                if not chunk:
                    if not self._closing:
                        self._fail(
                            f"RTDE connection to {self.address} was closed by the controller while {self._activity} "
                            f"(after {self._count} data packages; last package {self._age_text()})"
                        )
                    return
                buf += chunk
                pos = 0
                n = len(buf)
                while n - pos >= 3:
                    size, cmd = _HEADER.unpack_from(buf, pos)
                    if size < 3:
                        raise RTDEError(f"RTDE {self.address} sent a package with invalid size {size}")
                    if n - pos < size:
                        break
                    self._dispatch(cmd, bytes(buf[pos + 3 : pos + size]))
                    pos += size
                if pos:
                    del buf[:pos]
        except RTDEError as exc:
            self._fail(str(exc), type(exc) if type(exc) is not RTDEValueError else RTDEError)
        except OSError as exc:
            if not self._closing:
                self._fail(
                    f"RTDE connection to {self.address} failed while {self._activity}: {getattr(exc, 'strerror', None) or exc} "
                    f"(after {self._count} data packages; last package {self._age_text()})"
                )
        except Exception as exc:  # a parse bug must not die silently
            self._fail(f"RTDE reader for {self.address} stopped: {type(exc).__name__}: {exc}")

    def _dispatch(self, cmd: int, payload: bytes) -> None:
        if cmd == Command.DATA_PACKAGE:
            self._data_package(payload)
        elif cmd == Command.TEXT_MESSAGE:
            try:
                msg = decode_text_message(payload, self.protocol_version or 2)
            except RTDEError as exc:
                self._unexpected_package(str(exc), "malformed text message")
                return
            msg = TextMessage(safe_text(msg.message, MESSAGE_CHARS), safe_text(msg.source, 60), msg.level)
            if self._message_log.admit((msg.level, msg.source)):
                log.log(
                    logging.ERROR if msg.level <= MessageLevel.ERROR else logging.WARNING if msg.level == 2 else logging.INFO,
                    "RTDE %s %s [%s]: %s",
                    self.address,
                    msg.level_name,
                    msg.source,
                    msg.message,
                )
            with self._cond:
                self._messages.append(msg)
                self._cond.notify_all()
        else:
            with self._cond:
                if cmd == self._awaiting and not self._replies:
                    self._replies.append((cmd, payload))
                    self._cond.notify_all()
                    return
            self._unexpected_package(f"package of type {_COMMAND_NAMES.get(cmd, cmd)} nobody asked for "
                                     f"({len(payload) + 3} bytes)", cmd)

    def _data_package(self, payload: bytes) -> None:
        if self.protocol_version >= 2:
            if not payload:
                raise RTDEError(f"RTDE {self.address} sent an empty data package")
            recipe = self._outputs.get(payload[0])
            if recipe is None:
                self._unexpected_package(f"data package for unknown recipe {payload[0]}", "unknown recipe")
                return
            values = recipe.unpack(payload, 1)
        else:
            recipe = self._v1_output
            if recipe is None:
                return
            values = recipe.unpack(payload, 0)
        bad = first_non_finite(values)
        now = time.monotonic()
        with self._cond:
            self._count += 1
            self._last_rx = now
            if bad is not None and self._data_fault is None:
                name, index, value = bad
                where = name if index is None else f"{name}[{index}]"
                self._data_fault = RTDEValueError(
                    f"RTDE {self.address} sent a non-finite number: {where} = {safe_text(value, 40)} in data package "
                    f"{self._count} while {self._activity}; no value from this connection is trusted after it",
                    field=name, index=index, value=value, package=self._count,
                )
                log.error("%s", self._data_fault)
            if self._data_fault is None:  # after a non-finite value nothing more is kept: every reader raises
                self._latest.update(values)
                if len(self._buffer) == self._buffer.maxlen:
                    self._dropped += 1
                self._buffer.append(values)
            self._cond.notify_all()

    def _unexpected_package(self, what: str, kind: object) -> None:
        """Count a package nobody asked for, log the first of its kind; past the bound the connection fails."""
        self._unexpected += 1
        if self._log_once.admit(kind):
            log.warning("RTDE %s: %s (logged once per kind; more are counted)", self.address, what)
        if self._unexpected > MAX_UNEXPECTED_PACKAGES:
            raise RTDEFloodError(
                f"RTDE {self.address} flooded the connection: {self._unexpected} packages nobody asked for "
                f"(more than {MAX_UNEXPECTED_PACKAGES}; the last: {what}) while {self._activity}"
            )
