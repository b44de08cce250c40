"""The loopback controller, :class:`URSim`: its servers, control loop and fault injection. What it simulates
and how is described in :mod:`robocritics.testing.ursim`."""

from __future__ import annotations

import logging
import math
import socket
import struct
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Iterator, Sequence

from robocritics._text import safe_text
from robocritics.deploy import urscript
from robocritics.deploy.rtde import (
    DATA_TYPES,
    MAX_FREQUENCY_HZ,
    V1_FREQUENCY_HZ,
    Command,
    MessageLevel,
    Recipe,
    RobotMode,
    RuntimeState,
    SafetyMode,
    TextMessage,
    decode_text_message,
    encode_text_message,
    pack_package,
)
from robocritics.errors import DeployError
from robocritics.robot.arms import ARMS
from robocritics.testing.ursim.servo import _HoldProgram, _StreamProgram
from robocritics.testing.ursim.state import (
    CONTROLLER_STOP_DECEL,
    DT,
    FIELDBUS_FIELDS,
    KNOWN_INPUTS,
    KNOWN_OUTPUTS,
    PROTECTIVE_STOP_DECEL,
    SimEvent,
    SimSnapshot,
    _apply_pending,
    _extra_getter,
    _Getter,
    _Setter,
    _State,
    ur3e_fk,
)
from robocritics.testing.ursim.text_servers import serve_dashboard, serve_secondary

__all__ = ["URSim", "SimSnapshot", "SimEvent", "KNOWN_OUTPUTS", "KNOWN_INPUTS", "ur3e_fk", "DT"]

log = logging.getLogger(__name__)

DEFAULT_ROBOT_MODE = "RUNNING"
"""Robot mode a new controller starts in (``URSim()`` and ``robocritics ursim``): powered, brakes released."""

CLOCKS = ("realtime", "stepped")
"""How the controller's time advances (see :class:`URSim`)."""



# ---------------------------------------------------------------------------- connections


@dataclass
class _OutRecipe:
    recipe: Recipe
    getters: list[_Getter]
    frequency_hz: float
    acc: float = 0.0


@dataclass
class _InRecipe:
    recipe: Recipe
    setters: list[_Setter]


@dataclass(eq=False)
class _RTDEConn:
    sock: socket.socket
    peer: str
    protocol: int = 1
    outputs: dict[int, _OutRecipe] = field(default_factory=dict)
    inputs: dict[int, _InRecipe] = field(default_factory=dict)
    next_id: int = 1
    started: bool = False
    outbuf: bytearray = field(default_factory=bytearray)
    backlog_since: float | None = None
    lock: threading.Lock = field(default_factory=threading.Lock)
    packages_sent: int = 0
    closed: bool = False


# ---------------------------------------------------------------------------- the controller


class URSim:
    """Loopback UR3e controller. See the module docstring for what it simulates.

    Parameters
    ----------
    host:
        Address to listen on (keep 127.0.0.1).
    rtde_port, dashboard_port, secondary_port:
        Ports; 0 picks a free ephemeral port. The bound ports are in the
        attributes of the same name after :meth:`start`.
    initial_q:
        Joint positions at start [rad]; default the robot model's home pose
        (``Robot.ur(model).home_q``, where :func:`robocritics.simulate` starts).
    robot_mode:
        ``"RUNNING"`` (default: powered, brakes released), ``"IDLE"`` or
        ``"POWER_OFF"`` (like a freshly booted controller).
    remote_control:
        False = local control: the dashboard refuses commands that move the
        robot and the secondary interface refuses programs.
    fieldbus_registers:
        True = a fieldbus owns input registers 0-23 (they answer ``IN_USE``).
    protocol_versions:
        RTDE protocol versions the controller accepts; ``(1,)`` imitates old firmware.
    controller_version:
        (major, minor, bugfix, build) reported by RTDE 'v'.
    jump_margin:
        Protective-stop threshold as a multiple of the joint speed limit (see module doc).
    unlock_delay_s:
        Controller time after a protective stop before ``unlock protective stop`` is accepted [s].
    slow_client_timeout_s:
        A client whose data has been waiting unsent this long (wall time) is disconnected [s].
    extra_outputs, extra_inputs:
        Additional fields, name → RTDE type (e.g. a newer firmware's fields); their
        values are in :attr:`extras` (outputs read it, inputs write it).
    speed_limits:
        Joint speed limits [rad/s], default the model's (``ARMS[model].velocity_rad_s``).
    clock:
        How controller time advances; it is always control cycles × 2 ms, and every
        rule (watchdog, stall, protective stop, unlock delay, output rates, events)
        runs on it.

        * ``"realtime"`` (default): a thread runs one cycle every 2 ms of wall time,
          as a real controller does.
        * ``"stepped"``: simulated time. A cycle runs for every RTDE input data package
          received (a streaming client's setpoints are the controller's clock, one per
          2 ms cycle) and for every cycle asked of :meth:`step`; nothing else moves.
          Deterministic: the same inputs give the same states, however loaded the host.
    idle_after_s:
        ``clock="stepped"`` only: once no input package has arrived for this long
        (wall time, s), cycles also run every 2 ms of wall time until one arrives —
        so a client that only reads still gets data, and the RTDE watchdog still
        stops the program of a client that died. None (default): no idle cycles.
    model:
        Which arm this controller is (a name in :data:`robocritics.robot.arms.ARMS`, default
        ``"ur3e"``): its home pose, speed limits and the dashboard's ``get robot model`` answer
        (``"UR3"``). The simulated TCP pose stays the UR3e's.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        rtde_port: int = 30004,
        dashboard_port: int = 29999,
        secondary_port: int = 30002,
        initial_q: Sequence[float] | None = None,
        robot_mode: str = DEFAULT_ROBOT_MODE,
        remote_control: bool = True,
        fieldbus_registers: bool = False,
        protocol_versions: Iterable[int] = (1, 2),
        controller_version: tuple[int, int, int, int] = (5, 15, 0, 0),
        jump_margin: float = 1.5,
        unlock_delay_s: float = 5.0,
        slow_client_timeout_s: float = 1.0,
        extra_outputs: dict[str, str] | None = None,
        extra_inputs: dict[str, str] | None = None,
        speed_limits: Sequence[float] | None = None,
        clock: str = "realtime",
        idle_after_s: float | None = None,
        model: str = "ur3e",
    ) -> None:
        if model not in ARMS:
            raise DeployError(f"URSim model must be one of {', '.join(ARMS)}, got {model!r}")
        self.model = ARMS[model]
        if speed_limits is None:
            speed_limits = self.model.velocity_rad_s
        if initial_q is None:
            from robocritics.robot.model import Robot

            initial_q = tuple(float(v) for v in Robot.ur(model).home_q)
        if len(initial_q) != 6:
            raise DeployError(f"URSim initial_q needs 6 joint positions [rad], got {len(initial_q)}")
        if robot_mode.upper() not in ("POWER_OFF", "IDLE", "RUNNING"):
            raise DeployError(f"URSim robot_mode must be POWER_OFF, IDLE or RUNNING, got {robot_mode!r}")
        if clock not in CLOCKS:
            raise DeployError(f"URSim clock must be one of {', '.join(CLOCKS)}, got {clock!r}")
        if idle_after_s is not None and (clock != "stepped" or not idle_after_s > 0):
            raise DeployError(f"URSim idle_after_s needs clock='stepped' and a positive number of s, got {idle_after_s!r}")
        for attr, number in (("rtde_port", rtde_port), ("dashboard_port", dashboard_port), ("secondary_port", secondary_port)):
            if not (isinstance(number, int) and 0 <= number <= 65535):
                raise DeployError(f"URSim {attr} must be a TCP port from 0 (any free one) to 65535, got {safe_text(number, 20)}")
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in initial_q):
            raise DeployError(f"URSim initial_q must be 6 finite joint positions [rad], got {safe_text(list(initial_q), 200)}")
        for fields_ in (extra_outputs or {}, extra_inputs or {}):
            for n, t in fields_.items():
                if t not in DATA_TYPES:
                    raise DeployError(f"URSim extra field {n!r} has unknown RTDE type {t!r}")
        self.host = host
        self.rtde_port = rtde_port
        self.dashboard_port = dashboard_port
        self.secondary_port = secondary_port
        self.remote_control = remote_control
        self.fieldbus_registers = fieldbus_registers
        self.protocol_versions = tuple(protocol_versions)
        self.controller_version = tuple(controller_version)
        self.jump_margin = float(jump_margin)
        self.unlock_delay_s = float(unlock_delay_s)
        self.slow_client_timeout_s = float(slow_client_timeout_s)
        self.speed_limits = tuple(float(v) for v in speed_limits)
        self.clock = clock
        self.idle_after_s = idle_after_s
        self._lock = threading.RLock()
        self._state = _State(initial_q, RobotMode[robot_mode.upper()])
        self._outputs = dict(KNOWN_OUTPUTS)
        self._inputs = dict(KNOWN_INPUTS)
        for n, t in (extra_outputs or {}).items():
            self._outputs[n] = (t, _extra_getter(n, t))
        for n, t in (extra_inputs or {}).items():
            self._inputs[n] = (t, lambda s, v, p, n=n: s.extras.__setitem__(n, v))
            self._outputs.setdefault(n, (t, _extra_getter(n, t)))
        self._program: _StreamProgram | _HoldProgram | None = None
        self._program_start_tick = 0
        self._stopping_decel: float | None = None
        self._loaded_program: str | None = None
        self._protective_stop_tick: int | None = None
        self._conns: list[_RTDEConn] = []
        self._input_owner: dict[str, _RTDEConn] = {}
        self._events: list[SimEvent] = []
        self._actions: list[tuple[float, Callable[[], None]]] = []
        self._running = threading.Event()
        self._threads: list[threading.Thread] = []
        self._listeners: list[socket.socket] = []
        self._aux_socks: set[socket.socket] = set()
        self._reply_delay_s = 0.0
        self._rate_factor = 1.0
        self._silent_rtde = False
        self._silent_dashboard = False
        self._drop_after_packages: int | None = None
        self._drop_at_tick: int | None = None
        self._packages_total = 0
        self._corrupt: dict[str, tuple[int | None, Any]] = {}
        self._last_input_wall = time.monotonic()
        self.loop_overruns = 0
        """Control cycles that started more than 2 ms late (the host was busy; ``clock="realtime"``)."""

    # ------------------------------------------------------------------ lifecycle

    def __enter__(self) -> "URSim":
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def start(self) -> "URSim":
        """Bind the three servers and start the control loop (``clock="realtime"``); returns self."""
        if self._running.is_set():
            raise DeployError("URSim is already running")
        bound = []
        try:
            for attr, handler in (
                ("rtde_port", self._serve_rtde),
                ("dashboard_port", lambda sock, peer: serve_dashboard(self, sock, peer)),
                ("secondary_port", lambda sock, peer: serve_secondary(self, sock, peer)),
            ):
                ls = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
                ls.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                try:
                    ls.bind((self.host, getattr(self, attr)))
                except (OSError, OverflowError, UnicodeError, TypeError, ValueError) as exc:  # a bad port, host label, NUL
                    ls.close()
                    raise DeployError(
                        f"URSim cannot listen on {safe_text(self.host, 80)}:{safe_text(getattr(self, attr), 20)} "
                        f"({attr}): {getattr(exc, 'strerror', None) or exc}"
                    ) from None
                ls.listen(8)
                ls.settimeout(0.1)
                setattr(self, attr, ls.getsockname()[1])
                bound.append((ls, handler))
        except BaseException:
            for ls, _ in bound:
                ls.close()
            raise
        self._running.set()
        for ls, handler in bound:
            self._listeners.append(ls)
            self._spawn(self._accept_loop, ls, handler, name=f"ursim-accept-{ls.getsockname()[1]}")
        if self.clock == "realtime":
            self._spawn(self._control_loop, name="ursim-control")
        elif self.idle_after_s is not None:
            self._spawn(self._idle_loop, name="ursim-idle-cycles")
        self._event("started", f"listening on {self.host}: RTDE {self.rtde_port}, dashboard {self.dashboard_port}, secondary {self.secondary_port}")
        return self

    def stop(self) -> None:
        """Close every connection and listener and stop all threads (bounded wait)."""
        if not self._running.is_set():
            return
        self._running.clear()
        for ls in self._listeners:
            ls.close()
        self._listeners.clear()
        with self._lock:
            conns = list(self._conns)
            aux = list(self._aux_socks)
        for c in conns:
            self._close_conn(c, "controller shutting down")
        for s in aux:
            _shutdown(s)
        me = threading.current_thread()
        for t in self._threads:
            if t is not me:
                t.join(timeout=2.0)
        self._threads.clear()

    def _spawn(self, target: Callable[..., None], *args: Any, name: str) -> None:
        t = threading.Thread(target=target, args=args, name=name, daemon=True)
        self._threads = [th for th in self._threads if th.is_alive()]
        self._threads.append(t)
        t.start()

    def _accept_loop(self, ls: socket.socket, handler: Callable[[socket.socket, str], None]) -> None:
        while self._running.is_set():
            try:
                sock, addr = ls.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            sock.settimeout(None)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._spawn(handler, sock, f"{addr[0]}:{addr[1]}", name=f"ursim-conn-{addr[1]}")

    @contextmanager
    def _aux_connection(self, sock: socket.socket) -> Iterator[None]:
        """While a dashboard or secondary-interface connection is served: tracked (so :meth:`stop` closes it),
        an OSError ends it quietly; afterwards it is shut down."""
        with self._lock:
            self._aux_socks.add(sock)
        try:
            yield
        except OSError:
            pass
        finally:
            with self._lock:
                self._aux_socks.discard(sock)
            _shutdown(sock)

    # ------------------------------------------------------------------ inspection

    def snapshot(self) -> SimSnapshot:
        """A consistent copy of the controller state."""
        with self._lock:
            s = self._state
            return SimSnapshot(
                time_s=s.tick * DT,
                q=tuple(s.q),
                qd=tuple(s.qd),
                target_q=tuple(s.target_q),
                robot_mode=s.robot_mode,
                safety_mode=s.safety_mode,
                runtime_state=s.runtime_state,
                program=self._program.name if self._program is not None else None,
                program_state=s.out_int[urscript.STATE_REGISTER],
                applied_seq=s.out_int[urscript.APPLIED_SEQ_REGISTER],
                gripper_opening_m=s.gripper_opening_m,
                digital_out=s.digital_out,
                program_time_s=(s.tick - self._program_start_tick) * DT if self._program is not None else 0.0,
            )

    @property
    def q(self) -> tuple[float, ...]:
        """Actual joint positions [rad]."""
        with self._lock:
            return tuple(self._state.q)

    @property
    def packages_sent(self) -> int:
        """RTDE data packages queued for all clients so far."""
        with self._lock:
            return self._packages_total

    @property
    def extras(self) -> dict[str, Any]:
        """Values of the ``extra_outputs`` / ``extra_inputs`` fields (mutable, guarded by the sim)."""
        return self._state.extras

    def events(self, kind: str | None = None) -> list[SimEvent]:
        """Events so far (all, or those of one ``kind``: started, rtde_connected, rtde_closed,
        program_started, program_rejected, program_ended, start_rejected, done, stalled, watchdog,
        protective_stop, protective_stop_released, dashboard, client_message, stopped)."""
        with self._lock:
            return [e for e in self._events if kind is None or e.kind == kind]

    def wait_for(self, predicate: Callable[[SimSnapshot], bool], timeout_s: float, what: str = "condition") -> SimSnapshot:
        """Poll :meth:`snapshot` until ``predicate`` holds; raises TimeoutError after ``timeout_s`` of wall time [s].

        For a controller whose time others advance (``clock="realtime"``, or stepped
        by a client's inputs or idle cycles); with ``clock="stepped"`` use
        :meth:`step_until` to advance time yourself.
        """
        deadline = time.monotonic() + timeout_s
        while True:
            snap = self.snapshot()
            if predicate(snap):
                return snap
            if time.monotonic() > deadline:
                raise TimeoutError(f"URSim: {what} not reached within {timeout_s:g} s; state {snap}")
            time.sleep(0.002)

    # ------------------------------------------------------------------ simulated time (clock="stepped")

    @property
    def time_s(self) -> float:
        """Controller time: control cycles run so far × 2 ms [s]."""
        with self._lock:
            return self._state.tick * DT

    def step(self, cycles: int = 1) -> float:
        """Run ``cycles`` control cycles now (``clock="stepped"``): the program steps, data packages are
        sent. Returns the controller time [s]."""
        if self.clock != "stepped":
            raise DeployError(f"URSim.step() needs clock='stepped'; this controller's clock is {self.clock!r}")
        if cycles < 0:
            raise DeployError(f"URSim.step(): cycles must be >= 0, got {cycles}")
        for _ in range(int(cycles)):
            self._cycle()
        return self.time_s

    def step_until(self, predicate: Callable[[SimSnapshot], bool], max_s: float, what: str = "condition") -> SimSnapshot:
        """Run cycles (``clock="stepped"``) until ``predicate(snapshot)`` holds; raises TimeoutError after
        ``max_s`` of controller time [s]."""
        end = self.time_s + max_s
        while True:
            snap = self.snapshot()
            if predicate(snap):
                return snap
            if snap.time_s >= end - 1e-12:
                raise TimeoutError(f"URSim: {what} not reached within {max_s:g} s of controller time; state {snap}")
            self.step()

    def at_program_time(self, time_s: float, action: Callable[[], None]) -> None:
        """Run ``action()`` once, in the first control cycle in which the running program has run for
        ``time_s`` of controller time [s] — a fault injected at a known point of a deployment.

        The action runs inside the cycle with the controller's lock held: it may call this object's
        methods (:meth:`trigger_protective_stop`, :meth:`inject_drop`, :meth:`set_silent`, …) but must
        not wait for the controller's own servers (start a thread for a dashboard exchange).
        """
        with self._lock:
            self._actions.append((float(time_s), action))

    # ------------------------------------------------------------------ direct control

    def set_joint_positions(self, q: Sequence[float]) -> None:
        """Teleport the arm to ``q`` [rad] (only while no program runs)."""
        with self._lock:
            if self._program is not None:
                raise DeployError("URSim: cannot set joint positions while a program runs")
            self._state.q = [float(v) for v in q]
            self._state.target_q = list(self._state.q)
            self._state.qd = [0.0] * 6

    def power_on(self, brake_release: bool = True) -> None:
        """Power on (→ IDLE) and by default release the brakes (→ RUNNING), as the dashboard would."""
        with self._lock:
            self._state.robot_mode = RobotMode.RUNNING if brake_release else max(self._state.robot_mode, RobotMode.IDLE)

    def write_output_register(self, kind: str, n: int, value: Any) -> None:
        """Set an output register as a program would: ``kind`` is "int", "double" or "bit"."""
        with self._lock:
            s = self._state
            if kind == "int":
                s.out_int[n] = int(value)
            elif kind == "double":
                s.out_double[n] = float(value)
            elif kind == "bit":
                s.out_bits = (s.out_bits & ~(1 << n)) | ((1 if value else 0) << n)
            else:
                raise DeployError(f"unknown register kind {kind!r}; one of int, double, bit")

    def broadcast_message(self, message: str, level: int = MessageLevel.INFO, source: str = "URSim") -> None:
        """Send an RTDE text message to every connected RTDE client."""
        self._broadcast(TextMessage(message, source, level))

    # ------------------------------------------------------------------ fault injection

    def inject_drop(self, after_packages: int | None = None, after_s: float | None = None) -> None:
        """Close every RTDE connection once ``after_packages`` more data packages have been
        sent (to all clients together) or ``after_s`` seconds of controller time have passed,
        whichever comes first. With neither, drop now. One-shot."""
        with self._lock:
            if after_packages is None and after_s is None:
                self._drop_after_packages = self._packages_total
            else:
                self._drop_after_packages = None if after_packages is None else self._packages_total + int(after_packages)
                self._drop_at_tick = None if after_s is None else self._state.tick + max(1, round(float(after_s) / DT))

    def trigger_protective_stop(self, reason: str = "injected fault") -> None:
        """Protective-stop the robot now (safety_mode 3, program stopped)."""
        with self._lock:
            self._protective_stop(reason)

    def set_slow(self, reply_delay_s: float = 0.0, output_rate_factor: float = 1.0) -> None:
        """Slow controller: delay every RTDE and dashboard reply by ``reply_delay_s`` [s] and
        send data at ``output_rate_factor`` × the requested frequency (0 < factor <= 1)."""
        if not (0 < output_rate_factor <= 1):
            raise DeployError(f"output_rate_factor must be in (0, 1], got {output_rate_factor}")
        self._reply_delay_s = max(0.0, float(reply_delay_s))
        self._rate_factor = float(output_rate_factor)

    def set_silent(self, rtde: bool = True, dashboard: bool = False) -> None:
        """Silent controller: keep connections open but send nothing (no data, no replies)."""
        self._silent_rtde = bool(rtde)
        self._silent_dashboard = bool(dashboard)

    def corrupt_output(self, name: str, value: Any = math.nan, index: int | None = None) -> None:
        """From now on send ``value`` (default NaN; ``math.inf``, ``-math.inf``, …) as output field ``name``, or
        as its element ``index`` for a vector field, in every data package; ``value=None`` ends it. A field sent
        as INT32/UINT32 cannot carry NaN: declare it as DOUBLE with ``extra_outputs`` to send one."""
        if name not in self._outputs:
            raise DeployError(f"URSim has no output field {safe_text(name, 80)!r}")
        if value is not None and DATA_TYPES[self._outputs[name][0]][0] != "d" and not isinstance(value, int):
            raise DeployError(f"URSim output {name!r} is {self._outputs[name][0]} on the wire: it cannot carry {value!r}")
        with self._lock:
            if value is None:
                self._corrupt.pop(name, None)
            else:
                self._corrupt[name] = (index, value)

    def inject_packages(self, command: int, payload: bytes = b"", count: int = 1, raw: bytes | None = None) -> None:
        """Send ``count`` packages of type ``command`` with ``payload`` to every RTDE client now (a flood, an
        unknown type, a reply nobody asked for); ``raw`` sends those bytes as they are instead (a truncated or
        malformed package)."""
        data = raw if raw is not None else pack_package(command, payload)
        with self._lock:
            conns = list(self._conns)
        for c in conns:
            for _ in range(int(count)):
                if c.closed:  # the client gave up on the flood
                    break
                self._queue(c, data)
                if len(c.outbuf) > 1 << 20:
                    self._flush_blocking(c)
            self._flush_blocking(c)

    def _flush_blocking(self, conn: _RTDEConn) -> None:
        """Send everything queued for ``conn`` now, waiting for the client to read (bounded by its timeout)."""
        deadline = time.monotonic() + self.slow_client_timeout_s
        while conn.outbuf and not conn.closed and time.monotonic() < deadline:
            self._flush(conn)
            if conn.outbuf:
                time.sleep(0.001)

    def set_remote_control(self, enabled: bool) -> None:
        """Switch between remote control (True) and local control (False)."""
        self.remote_control = bool(enabled)
        self._event("remote_control", f"remote control {'on' if enabled else 'off'}")

    # ------------------------------------------------------------------ control loop

    def _cycle(self) -> None:
        """One control cycle: the program steps, the data packages due are queued and sent."""
        t0 = time.perf_counter()
        with self._lock:
            self._tick()
            self._publish()
            self._state.exec_time_ms = (time.perf_counter() - t0) * 1000.0
        # A drop due at this tick closes the connections before this cycle's package leaves, so the client
        # sees exactly the packages of the cycles before it (a package sent just before the close may or may
        # not be read: the close's RST can discard it, depending on scheduling).
        self._check_drop(at_tick=True)
        self._flush_all()
        self._check_drop(at_tick=False)

    def _control_loop(self) -> None:
        """``clock="realtime"``: one cycle every 2 ms of wall time."""
        next_t = time.perf_counter()
        while self._running.is_set():
            self._cycle()
            next_t += DT
            delay = next_t - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            elif delay < -DT:
                self.loop_overruns += 1
                if delay < -0.05:  # far behind (host stalled): resynchronise instead of bursting
                    next_t = time.perf_counter()

    def _idle_loop(self) -> None:
        """``clock="stepped"`` with ``idle_after_s``: cycles every 2 ms of wall time while no input arrives."""
        assert self.idle_after_s is not None
        while self._running.is_set():
            time.sleep(DT)
            if time.monotonic() - self._last_input_wall >= self.idle_after_s:
                self._cycle()

    def _tick(self) -> None:
        s = self._state
        s.tick += 1
        if self._actions and self._program is not None:
            ran_s = (s.tick - self._program_start_tick) * DT
            due = [a for a in self._actions if a[0] <= ran_s + 1e-12]
            if due:
                self._actions = [a for a in self._actions if a not in due]
                for _, action in due:
                    action()
        if self._program is not None and s.runtime_state == RuntimeState.PAUSED:
            self._decelerate(s, CONTROLLER_STOP_DECEL)
        elif self._program is not None:
            self._program.step(s)
        elif self._stopping_decel is not None:
            if self._decelerate(s, self._stopping_decel):
                self._stopping_decel = None
        else:
            s.qd = [0.0] * 6
            s.target_qd = [0.0] * 6

    def _decelerate(self, s: _State, decel: float) -> bool:
        """One cycle of braking at ``decel`` [rad/s²]; True once every joint stands still."""
        dv = decel * DT
        still = True
        for j in range(6):
            v = s.qd[j]
            v = v - dv if v > dv else v + dv if v < -dv else 0.0
            s.qd[j] = v
            s.q[j] += v * DT
            if v != 0.0:
                still = False
        s.target_q = list(s.q)
        s.target_qd = list(s.qd)
        return still

    def _end_program(self, kind: str, message: str, decel: float | None) -> None:
        """Stop the running program (lock held); ``decel`` None = joints already still."""
        self._program = None
        self._state.runtime_state = RuntimeState.STOPPED
        self._stopping_decel = decel
        self._event(kind, message)
        level = MessageLevel.INFO if kind in ("program_ended",) else MessageLevel.ERROR
        self._broadcast(TextMessage(message, "Controller", level))

    def _protective_stop(self, reason: str) -> None:
        s = self._state
        s.safety_mode = SafetyMode.PROTECTIVE_STOP
        self._protective_stop_tick = s.tick
        if self._program is not None:
            self._program = None
            s.runtime_state = RuntimeState.STOPPED
        self._stopping_decel = PROTECTIVE_STOP_DECEL
        self._event("protective_stop", f"protective stop: {reason}")
        self._broadcast(TextMessage(f"Protective stop: {reason}", "Controller", MessageLevel.ERROR))

    def _start_program(self, program: _StreamProgram | _HoldProgram) -> None:
        self._program = program
        self._program_start_tick = self._state.tick
        self._stopping_decel = None
        self._state.runtime_state = RuntimeState.PLAYING
        self._event("program_started", f"program {program.name} started")

    def _event(self, kind: str, message: str) -> None:
        with self._lock:
            self._events.append(SimEvent(self._state.tick * DT, kind, message))
        log.info("URSim %s: %s", kind, message)

    # ------------------------------------------------------------------ RTDE server

    def _serve_rtde(self, sock: socket.socket, peer: str) -> None:
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 65536)
        except OSError:
            pass
        conn = _RTDEConn(sock, peer)
        with self._lock:
            self._conns.append(conn)
        self._event("rtde_connected", f"RTDE client {peer} connected")
        buf = bytearray()
        reason = "client closed the connection"
        try:
            while self._running.is_set() and not conn.closed:
                chunk = sock.recv(65536)
                if not chunk:
                    break
                buf += chunk
                pos = 0
                while len(buf) - pos >= 3:
                    size, cmd = struct.unpack_from(">HB", buf, pos)
                    if size < 3:
                        raise ValueError(f"invalid package size {size}")
                    if len(buf) - pos < size:
                        break
                    self._rtde_package(conn, cmd, bytes(buf[pos + 3 : pos + size]))
                    pos += size
                del buf[:pos]
        except (OSError, ValueError) as exc:
            reason = f"{type(exc).__name__}: {exc}"
        finally:
            self._close_conn(conn, reason)

    def _close_conn(self, conn: _RTDEConn, reason: str) -> None:
        with self._lock:
            if conn.closed:
                return
            conn.closed = True
            if conn in self._conns:
                self._conns.remove(conn)
            for name in [n for n, c in self._input_owner.items() if c is conn]:
                del self._input_owner[name]
        _shutdown(conn.sock)
        self._event("rtde_closed", f"RTDE client {conn.peer} disconnected: {reason}")

    def _reply(self, conn: _RTDEConn, cmd: int, payload: bytes) -> None:
        if self._silent_rtde:
            return
        if self._reply_delay_s:
            time.sleep(self._reply_delay_s)
        self._queue(conn, pack_package(cmd, payload))
        self._flush(conn)

    def _send_text(self, conn: _RTDEConn, msg: TextMessage) -> None:
        if self._silent_rtde or conn.closed:
            return
        self._queue(conn, pack_package(Command.TEXT_MESSAGE, encode_text_message(msg, conn.protocol)))
        self._flush(conn)

    def _broadcast(self, msg: TextMessage) -> None:
        with self._lock:
            conns = list(self._conns)
        for c in conns:
            self._send_text(c, msg)

    def _rtde_package(self, conn: _RTDEConn, cmd: int, payload: bytes) -> None:
        if cmd == Command.REQUEST_PROTOCOL_VERSION:
            if len(payload) != 2:
                self._send_text(conn, TextMessage("protocol version request needs a uint16", "RTDE", MessageLevel.ERROR))
                return
            (version,) = struct.unpack(">H", payload)
            ok = version in self.protocol_versions
            if ok:
                conn.protocol = version
            self._reply(conn, cmd, struct.pack(">B", 1 if ok else 0))
        elif cmd == Command.GET_URCONTROL_VERSION:
            self._reply(conn, cmd, struct.pack(">IIII", *self.controller_version))
        elif cmd == Command.CONTROL_PACKAGE_SETUP_OUTPUTS:
            self._setup_outputs(conn, payload)
        elif cmd == Command.CONTROL_PACKAGE_SETUP_INPUTS:
            self._setup_inputs(conn, payload)
        elif cmd == Command.CONTROL_PACKAGE_START:
            with self._lock:
                ok = bool(conn.outputs)
                if ok:
                    for rec in conn.outputs.values():
                        rec.acc = 1.0  # first package on the next cycle
                    conn.started = True
            if not ok:
                self._send_text(conn, TextMessage("start refused: no output recipe set up", "RTDE", MessageLevel.ERROR))
            self._reply(conn, cmd, b"\x01" if ok else b"\x00")
        elif cmd == Command.CONTROL_PACKAGE_PAUSE:
            with self._lock:
                conn.started = False
            self._reply(conn, cmd, b"\x01")
        elif cmd == Command.DATA_PACKAGE:
            self._input_package(conn, payload)
        elif cmd == Command.TEXT_MESSAGE:
            try:
                msg = decode_text_message(payload, conn.protocol)
            except Exception as exc:
                self._send_text(conn, TextMessage(f"malformed text message: {exc}", "RTDE", MessageLevel.ERROR))
                return
            self._event("client_message", safe_text(f"{conn.peer} [{msg.source}] {msg.level_name}: {msg.message}", 600))
        else:
            self._send_text(conn, TextMessage(f"unknown RTDE package type {cmd}", "RTDE", MessageLevel.ERROR))

    def _setup_outputs(self, conn: _RTDEConn, payload: bytes) -> None:
        if conn.protocol >= 2:
            if len(payload) < 8:
                self._send_text(conn, TextMessage("output setup needs a frequency", "RTDE", MessageLevel.ERROR))
                self._reply(conn, Command.CONTROL_PACKAGE_SETUP_OUTPUTS, b"\x00")
                return
            (freq,) = struct.unpack_from(">d", payload)
            text = payload[8:]
        else:
            freq, text = V1_FREQUENCY_HZ, payload
        names = _field_names(text)
        types = [self._outputs[n][0] if n in self._outputs else "NOT_FOUND" for n in names]
        ok = bool(names) and "NOT_FOUND" not in types
        if not (0 < freq <= MAX_FREQUENCY_HZ) or math.isnan(freq):
            clamped = min(max(freq if not math.isnan(freq) else MAX_FREQUENCY_HZ, 1.0), MAX_FREQUENCY_HZ)
            self._send_text(
                conn, TextMessage(f"output frequency {freq} Hz out of range, using {clamped:g} Hz", "RTDE", MessageLevel.WARNING)
            )
            freq = clamped
        rid = 0
        if ok:
            with self._lock:
                if conn.protocol >= 2:
                    rid = conn.next_id
                    conn.next_id += 1
                else:
                    conn.outputs.clear()
                conn.outputs[rid] = _OutRecipe(Recipe(rid, tuple(names), tuple(types)), [self._outputs[n][1] for n in names], freq)
        body = ",".join(types).encode("ascii")
        self._reply(conn, Command.CONTROL_PACKAGE_SETUP_OUTPUTS, (bytes([rid]) + body) if conn.protocol >= 2 else body)

    def _setup_inputs(self, conn: _RTDEConn, payload: bytes) -> None:
        names = _field_names(payload)
        with self._lock:
            types = []
            for n in names:
                if n not in self._inputs:
                    types.append("NOT_FOUND")
                elif (self.fieldbus_registers and n in FIELDBUS_FIELDS) or (
                    n in self._input_owner and self._input_owner[n] is not conn
                ):
                    types.append("IN_USE")
                else:
                    types.append(self._inputs[n][0])
            rid = 0
            if names and "NOT_FOUND" not in types and "IN_USE" not in types:
                rid = conn.next_id
                conn.next_id += 1
                conn.inputs[rid] = _InRecipe(Recipe(rid, tuple(names), tuple(types)), [self._inputs[n][1] for n in names])
                for n in names:
                    self._input_owner[n] = conn
        self._reply(conn, Command.CONTROL_PACKAGE_SETUP_INPUTS, bytes([rid]) + ",".join(types).encode("ascii"))

    def _input_package(self, conn: _RTDEConn, payload: bytes) -> None:
        if not payload:
            self._send_text(conn, TextMessage("empty data package", "RTDE", MessageLevel.ERROR))
            return
        rec = conn.inputs.get(payload[0])
        if rec is None:
            self._send_text(conn, TextMessage(f"data package for unknown input recipe {payload[0]}", "RTDE", MessageLevel.ERROR))
            return
        try:
            values = rec.recipe.unpack(payload, 1)
        except Exception as exc:
            self._send_text(conn, TextMessage(str(exc), "RTDE", MessageLevel.ERROR))
            return
        if not conn.started:
            self._send_text(conn, TextMessage("input ignored: synchronisation not started", "RTDE", MessageLevel.WARNING))
            return
        with self._lock:
            s = self._state
            pending: dict[str, Any] = {}
            for name, setter in zip(rec.recipe.names, rec.setters):
                setter(s, values[name], pending)
                s.input_update_tick[name] = s.tick
            _apply_pending(s, pending)
        if self.clock == "stepped":  # the client's inputs are the controller's clock: one package, one cycle
            self._last_input_wall = time.monotonic()
            self._cycle()

    def _publish(self) -> None:
        """Queue the data packages due this cycle (lock held)."""
        if self._silent_rtde:
            return
        s = self._state
        step = self._rate_factor * DT
        for conn in self._conns:
            if not conn.started:
                continue
            for rid, rec in conn.outputs.items():
                rec.acc += rec.frequency_hz * step
                if rec.acc < 1.0 - 1e-9:
                    continue
                rec.acc -= 1.0
                if rec.acc > 1.0:
                    rec.acc = 0.0
                values = [g(s) for g in rec.getters]
                if self._corrupt:
                    values = self._corrupted(rec.recipe.names, values)
                body = rec.recipe.pack_values(values)
                if conn.protocol >= 2:
                    body = bytes((rid,)) + body
                with conn.lock:
                    conn.outbuf += pack_package(Command.DATA_PACKAGE, body)
                conn.packages_sent += 1
                self._packages_total += 1

    def _corrupted(self, names: Sequence[str], values: list[Any]) -> list[Any]:
        out = list(values)
        for i, name in enumerate(names):
            if name in self._corrupt:
                index, value = self._corrupt[name]
                if index is None:
                    out[i] = value
                else:
                    vec = list(out[i])
                    vec[index] = value
                    out[i] = vec
        return out

    def _queue(self, conn: _RTDEConn, data: bytes) -> None:
        with conn.lock:
            conn.outbuf += data

    def _flush_all(self) -> None:
        with self._lock:
            conns = list(self._conns)
        for c in conns:
            self._flush(c)

    def _flush(self, conn: _RTDEConn) -> None:
        drop = None
        with conn.lock:
            if conn.closed:
                conn.outbuf.clear()
                return
            if conn.outbuf:
                try:
                    n = conn.sock.send(conn.outbuf, socket.MSG_DONTWAIT)
                except (BlockingIOError, InterruptedError):
                    n = 0
                except OSError as exc:
                    n = 0
                    drop = f"send failed: {exc.strerror or exc}"
                if n:
                    del conn.outbuf[:n]
            now = time.monotonic()
            if not conn.outbuf:
                conn.backlog_since = None
            elif conn.backlog_since is None:
                conn.backlog_since = now
            elif now - conn.backlog_since > self.slow_client_timeout_s or len(conn.outbuf) > 8 << 20:
                drop = (
                    f"client not reading: {len(conn.outbuf)} bytes unsent for "
                    f"{now - conn.backlog_since:.2f} s (> {self.slow_client_timeout_s:g} s)"
                )
        if drop:
            self._close_conn(conn, drop)

    def _check_drop(self, at_tick: bool) -> None:
        """Close every RTDE connection if the injected drop is due: by tick (``at_tick``) or by package count."""
        due = False
        with self._lock:
            if at_tick:
                due = self._drop_at_tick is not None and self._state.tick >= self._drop_at_tick
            else:
                due = self._drop_after_packages is not None and self._packages_total >= self._drop_after_packages
            if due:
                self._drop_after_packages = None
                self._drop_at_tick = None
                conns = list(self._conns)
        if due:
            for c in conns:
                self._close_conn(c, f"injected connection drop after {c.packages_sent} data packages")


def _field_names(text: bytes) -> list[str]:
    """The field names of a recipe setup request (comma-separated ASCII)."""
    return [n.strip() for n in text.decode("ascii", "replace").split(",") if n.strip()]


def _shutdown(sock: socket.socket) -> None:
    try:
        sock.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass
    try:
        sock.close()
    except OSError:
        pass
