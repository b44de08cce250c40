"""The URScript servo-streaming program and the secondary-interface sender.

:func:`streaming_program` generates a URScript program that follows joint
setpoints streamed over RTDE. The register layout (fixed; fieldbuses own
registers 0-23, so everything lives in 24-47):

=========================  =====================================================
RTDE field                 meaning
=========================  =====================================================
input_int_register_24      sequence counter: the client increments it with every
                           setpoint (one setpoint = 2 ms of trajectory); it is
                           the RTDE watchdog variable
input_int_register_25      command: 0 = stream, 1 = done (decelerate with
                           ``stopj`` and end the program)
input_int_register_26      session id chosen by the client (non-zero); echoed in
                           output_int_register_26 once the program streams
input_double_register_24   joint 0 (base) target [rad]
 … _29                     … joint 5 (wrist 3) target [rad]
input_double_register_30   gripper opening [m] (finger gap)
output_int_register_24     last sequence number the program applied
output_int_register_25     program state, see :class:`ProgramState`
output_int_register_26     session id the program read at start
output_double_register_24  gripper opening last applied [m]
=========================  =====================================================

The program

1. writes state STARTING (0) and arms ``rtde_set_watchdog("input_int_register_24",
   min_hz, "stop")`` — the controller stops the program if the client sends no
   update of the counter for longer than ``1/min_hz`` s, so the client must
   already be streaming (hold setpoints) when the program is sent;
2. refuses to start (state START_REJECTED, 4) if the first target is more than
   ``max_start_deviation_rad`` from the actual joint positions on any joint;
3. every 2 ms: reads the counter; on a new value it reads the six targets and
   reports the counter in output_int_register_24; if the counter has not changed
   for longer than ``1/min_hz`` s it writes state STALLED (3) and ``stopj``'s
   (this also catches a client that keeps sending the same counter); applies the
   gripper opening when it changed (``gripper_hook``); calls
   ``servoj(q, t=0.002, lookahead_time=…, gain=…)``;
4. on command 1 writes state DONE (2) and ends with ``stopj(a)``.

:func:`send_program` sends program text to the secondary interface (port 30002);
the controller runs it only in remote control mode.
"""

from __future__ import annotations

import math
import re
import socket
import time
from dataclasses import dataclass
from enum import IntEnum
from typing import Any, Mapping, Sequence

from robocritics.errors import DeployError, RTDEError
from robocritics.robot.arms import UR3E

__all__ = [
    "SECONDARY_PORT",
    "PROGRAM_MARKER",
    "SEQ_REGISTER",
    "COMMAND_REGISTER",
    "SESSION_REGISTER",
    "TARGET_Q_REGISTERS",
    "GRIPPER_REGISTER",
    "APPLIED_SEQ_REGISTER",
    "STATE_REGISTER",
    "SESSION_ECHO_REGISTER",
    "GRIPPER_APPLIED_REGISTER",
    "INPUT_FIELDS",
    "OUTPUT_FIELDS",
    "ProgramState",
    "Command",
    "StreamingProgramParams",
    "ProgramStatus",
    "program_status",
    "streaming_program",
    "parse_streaming_program",
    "setpoint",
    "send_program",
]

SECONDARY_PORT = 30002
PROGRAM_MARKER = "# robocritics-stream-program v1"
"""First line of every generated program; the loopback controller recognises programs by it."""

SEQ_REGISTER = 24
COMMAND_REGISTER = 25
SESSION_REGISTER = 26
TARGET_Q_REGISTERS = tuple(range(24, 30))
GRIPPER_REGISTER = 30
APPLIED_SEQ_REGISTER = 24
STATE_REGISTER = 25
SESSION_ECHO_REGISTER = 26
GRIPPER_APPLIED_REGISTER = 24

INPUT_FIELDS: tuple[str, ...] = (
    f"input_int_register_{SEQ_REGISTER}",
    f"input_int_register_{COMMAND_REGISTER}",
    f"input_int_register_{SESSION_REGISTER}",
    *(f"input_double_register_{r}" for r in TARGET_Q_REGISTERS),
    f"input_double_register_{GRIPPER_REGISTER}",
)
"""The input recipe a streaming client sets up (pass to ``RTDEClient.setup_inputs``)."""

OUTPUT_FIELDS: tuple[str, ...] = (
    f"output_int_register_{APPLIED_SEQ_REGISTER}",
    f"output_int_register_{STATE_REGISTER}",
    f"output_int_register_{SESSION_ECHO_REGISTER}",
    f"output_double_register_{GRIPPER_APPLIED_REGISTER}",
)
"""The program's progress outputs (add to the client's output recipe)."""

WATCHDOG_VARIABLE = f"input_int_register_{SEQ_REGISTER}"


class ProgramState(IntEnum):
    """Values of output_int_register_25."""

    STARTING = 0
    STREAMING = 1
    DONE = 2
    STALLED = 3
    START_REJECTED = 4


class Command(IntEnum):
    """Values of input_int_register_25."""

    STREAM = 0
    DONE = 1


@dataclass(frozen=True)
class StreamingProgramParams:
    """The parameters of a generated streaming program (as written in its text)."""

    name: str
    servo_t_s: float
    lookahead_time_s: float
    gain: float
    watchdog_min_hz: float
    watchdog_action: str
    stall_limit_cycles: int
    max_start_deviation_rad: float
    stop_deceleration_rad_s2: float
    gripper_close_below_m: float | None
    """Threshold of the placeholder gripper hook; None when a custom hook is used."""


def _num(x: float) -> str:
    return repr(float(x))


def _register_layout() -> list[str]:
    """The comment at the top of the streaming program: which register carries what."""
    return [
        "# Generated by robocritics.deploy.urscript.streaming_program; edit the generator, not this text.",
        f"# inputs : input_int_register_{SEQ_REGISTER} sequence counter (watchdog variable),",
        f"#          input_int_register_{COMMAND_REGISTER} command (0 stream, 1 done),",
        f"#          input_int_register_{SESSION_REGISTER} session id,",
        f"#          input_double_register_{TARGET_Q_REGISTERS[0]}..{TARGET_Q_REGISTERS[-1]} joint targets [rad],",
        f"#          input_double_register_{GRIPPER_REGISTER} gripper opening [m]",
        f"# outputs: output_int_register_{APPLIED_SEQ_REGISTER} applied sequence, output_int_register_{STATE_REGISTER} state",
        "#          (0 starting, 1 streaming, 2 done, 3 stalled, 4 start rejected),",
        f"#          output_int_register_{SESSION_ECHO_REGISTER} session id, output_double_register_{GRIPPER_APPLIED_REGISTER} gripper opening [m]",
    ]


def _refuse_a_far_start(i: str) -> list[str]:
    """URScript lines (indented by ``i``) that halt the program when a joint's first target is farther than
    ``max_start_dev`` from where it is."""
    return [
        f"{i}local j = 0",
        f"{i}while j < 6:",
        f"{i*2}if norm(q[j] - q_actual[j]) > max_start_dev:",
        f"{i*3}write_output_integer_register({STATE_REGISTER}, {int(ProgramState.START_REJECTED)})",
        f'{i*3}textmsg("robocritics: first setpoint is too far from the actual joint positions; not starting")',
        f"{i*3}halt",
        f"{i*2}end",
        f"{i*2}j = j + 1",
        f"{i}end",
    ]


def _gripper_lines(gripper_hook: str | None, gripper_close_below_m: float) -> list[str]:
    """The URScript lines that set the gripper to ``opening_m``: the given hook, or tool output 0 (closed below
    ``gripper_close_below_m``, m)."""
    if gripper_hook is None:
        return [f"set_tool_digital_out(0, opening_m < {_num(gripper_close_below_m)})"]
    return [ln.strip() for ln in gripper_hook.strip().splitlines() if ln.strip()]


def _check_program_options(lookahead_time_s: float, gain: float, watchdog_min_hz: float, servo_t_s: float,
                           stop_deceleration_rad_s2: float, max_start_deviation_rad: float,
                           gripper_close_below_m: float, name: str) -> None:
    """DeployError naming the first option of :func:`streaming_program` out of its range."""
    checks = [
        (0.03 <= lookahead_time_s <= 0.2, f"lookahead_time_s must be in [0.03, 0.2] s, got {lookahead_time_s}"),
        (100 <= gain <= 2000, f"gain must be in [100, 2000], got {gain}"),
        (UR3E.control_period_s <= servo_t_s <= 0.2,
         f"servo_t_s must be in [{UR3E.control_period_s:g}, 0.2] s, got {servo_t_s}"),
        (0 < watchdog_min_hz <= 1.0 / servo_t_s, f"watchdog_min_hz must be in (0, {1.0 / servo_t_s:g}] Hz, got {watchdog_min_hz}"),
        (0 < stop_deceleration_rad_s2 <= 40, f"stop_deceleration_rad_s2 must be in (0, 40] rad/s², got {stop_deceleration_rad_s2}"),
        (0 < max_start_deviation_rad <= 0.5, f"max_start_deviation_rad must be in (0, 0.5] rad, got {max_start_deviation_rad}"),
        (0 <= gripper_close_below_m <= 0.2, f"gripper_close_below_m must be in [0, 0.2] m, got {gripper_close_below_m}"),
        (re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]{0,30}", name) is not None, f"program name must be an identifier, got {name!r}"),
    ]
    for ok, msg in checks:
        if not ok:
            raise DeployError(f"streaming program: {msg}")


def streaming_program(
    lookahead_time_s: float = 0.1,
    gain: float = 300,
    watchdog_min_hz: float = 10.0,
    *,
    servo_t_s: float = UR3E.control_period_s,
    stop_deceleration_rad_s2: float = 2.0,
    max_start_deviation_rad: float = 0.05,
    gripper_close_below_m: float = 0.0425,
    gripper_hook: str | None = None,
    name: str = "robocritics_stream",
) -> str:
    """Generate the URScript servo-streaming program (layout in the module docstring).

    Parameters
    ----------
    lookahead_time_s:
        ``servoj`` lookahead time [s], 0.03-0.2; longer is smoother but lags more.
    gain:
        ``servoj`` proportional gain, 100-2000.
    watchdog_min_hz:
        Minimum update rate of the sequence counter [Hz]; slower (or a counter
        that stops changing for ``1/watchdog_min_hz`` s) stops the program.
    servo_t_s:
        ``servoj`` blocking time = control period [s] (``UR3E.control_period_s``, 2 ms on e-series).
    stop_deceleration_rad_s2:
        Joint deceleration of the final ``stopj`` [rad/s²].
    max_start_deviation_rad:
        Largest allowed distance between the first target and the actual joint
        positions, per joint [rad]; more refuses to start.
    gripper_close_below_m:
        The placeholder gripper hook sets tool digital output 0 when the
        commanded opening is below this [m] (a 2F-85 opens 0-0.085 m).
    gripper_hook:
        URScript statement(s) to run when the commanded opening changes; the
        opening is in the variable ``opening_m`` [m]. Replaces the placeholder,
        e.g. ``"rq_move_mm(opening_m * 1000)"`` with the Robotiq URCap installed.
    name:
        Name of the URScript function (an identifier).
    """
    _check_program_options(lookahead_time_s, gain, watchdog_min_hz, servo_t_s, stop_deceleration_rad_s2,
                           max_start_deviation_rad, gripper_close_below_m, name)  # fmt: skip
    stall_limit = max(1, math.ceil(1.0 / (watchdog_min_hz * servo_t_s) - 1e-9))
    hook_lines = _gripper_lines(gripper_hook, gripper_close_below_m)
    read_q = "[" + ", ".join(f"read_input_float_register({r})" for r in TARGET_Q_REGISTERS) + "]"
    servo = f"servoj(q, t={_num(servo_t_s)}, lookahead_time={_num(lookahead_time_s)}, gain={_num(gain)})"
    i = "  "
    lines = [
        PROGRAM_MARKER,
        *_register_layout(),
        f"def {name}():",
        f"{i}local stall_limit = {stall_limit}",
        f"{i}local max_start_dev = {_num(max_start_deviation_rad)}",
        f"{i}write_output_integer_register({STATE_REGISTER}, {int(ProgramState.STARTING)})",
        f'{i}rtde_set_watchdog("{WATCHDOG_VARIABLE}", {_num(watchdog_min_hz)}, "stop")',
        f"{i}local session = read_input_integer_register({SESSION_REGISTER})",
        f"{i}local q = {read_q}",
        f"{i}local q_actual = get_actual_joint_positions()",
        *_refuse_a_far_start(i),
        f"{i}local last_seq = read_input_integer_register({SEQ_REGISTER})",
        f"{i}local stall = 0",
        f"{i}local opening_m = read_input_float_register({GRIPPER_REGISTER})",
        f"{i}local last_opening_m = -1.0",
        f"{i}write_output_integer_register({APPLIED_SEQ_REGISTER}, last_seq)",
        f"{i}write_output_integer_register({SESSION_ECHO_REGISTER}, session)",
        f"{i}write_output_integer_register({STATE_REGISTER}, {int(ProgramState.STREAMING)})",
        f"{i}while True:",
        f"{i*2}if read_input_integer_register({COMMAND_REGISTER}) == {int(Command.DONE)}:",
        f"{i*3}write_output_integer_register({STATE_REGISTER}, {int(ProgramState.DONE)})",
        f"{i*3}stopj({_num(stop_deceleration_rad_s2)})",
        f"{i*3}break",
        f"{i*2}end",
        f"{i*2}local seq = read_input_integer_register({SEQ_REGISTER})",
        f"{i*2}if seq != last_seq:",
        f"{i*3}q = {read_q}",
        f"{i*3}last_seq = seq",
        f"{i*3}stall = 0",
        f"{i*3}write_output_integer_register({APPLIED_SEQ_REGISTER}, seq)",
        f"{i*2}else:",
        f"{i*3}stall = stall + 1",
        f"{i*3}if stall > stall_limit:",
        f"{i*4}write_output_integer_register({STATE_REGISTER}, {int(ProgramState.STALLED)})",
        f'{i*4}textmsg("robocritics: sequence counter stalled; stopping")',
        f"{i*4}stopj({_num(stop_deceleration_rad_s2)})",
        f"{i*4}break",
        f"{i*3}end",
        f"{i*2}end",
        f"{i*2}opening_m = read_input_float_register({GRIPPER_REGISTER})",
        f"{i*2}if opening_m != last_opening_m:",
        *(f"{i*3}{ln}" for ln in hook_lines),
        f"{i*3}write_output_float_register({GRIPPER_APPLIED_REGISTER}, opening_m)",
        f"{i*3}last_opening_m = opening_m",
        f"{i*2}end",
        f"{i*2}{servo}",
        f"{i}end",
        "end",
        "",
    ]
    return "\n".join(lines)


_FLOAT = r"([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)"


def parse_streaming_program(text: str) -> StreamingProgramParams:
    """Recover the parameters of a program made by :func:`streaming_program`.

    Raises :class:`DeployError` naming what is missing if ``text`` is not such a
    program (the loopback controller uses this to refuse other scripts).
    """
    lines = text.lstrip().splitlines()
    if not lines or lines[0].strip() != PROGRAM_MARKER:
        raise DeployError(f"not a robocritics streaming program: first line is not {PROGRAM_MARKER!r}")

    def find(pattern: str, what: str) -> re.Match[str]:
        m = re.search(pattern, text, flags=re.MULTILINE)
        if m is None:
            raise DeployError(f"robocritics streaming program is missing {what}")
        return m

    name = find(r"^def\s+([A-Za-z_]\w*)\(\):\s*$", "its 'def name():' line").group(1)
    find(r"^end\s*$", "its closing 'end'")
    wd = find(
        r'rtde_set_watchdog\("' + WATCHDOG_VARIABLE + r'",\s*' + _FLOAT + r',\s*"(\w+)"\)',
        f'rtde_set_watchdog("{WATCHDOG_VARIABLE}", min_hz, action)',
    )
    sv = find(
        r"servoj\(q,\s*t=" + _FLOAT + r",\s*lookahead_time=" + _FLOAT + r",\s*gain=" + _FLOAT + r"\)",
        "servoj(q, t=…, lookahead_time=…, gain=…)",
    )
    stall = find(r"local stall_limit = (\d+)", "its stall_limit")
    dev = find(r"local max_start_dev = " + _FLOAT, "its max_start_dev")
    stop = find(r"stopj\(" + _FLOAT + r"\)", "stopj(a)")
    grip = re.search(r"set_tool_digital_out\(0, opening_m < " + _FLOAT + r"\)", text)
    return StreamingProgramParams(
        name=name,
        servo_t_s=float(sv.group(1)),
        lookahead_time_s=float(sv.group(2)),
        gain=float(sv.group(3)),
        watchdog_min_hz=float(wd.group(1)),
        watchdog_action=wd.group(2),
        stall_limit_cycles=int(stall.group(1)),
        max_start_deviation_rad=float(dev.group(1)),
        stop_deceleration_rad_s2=float(stop.group(1)),
        gripper_close_below_m=float(grip.group(1)) if grip else None,
    )


def setpoint(
    seq: int,
    q: Sequence[float],
    gripper_opening_m: float = 0.085,
    *,
    done: bool = False,
    session: int = 1,
) -> dict[str, Any]:
    """The input values of one setpoint, ready for ``RTDEClient.send``.

    ``seq`` is the sequence counter (int32, increment by one per 2 ms sample),
    ``q`` six joint targets [rad], ``gripper_opening_m`` the finger gap [m],
    ``done`` asks the program to stop, ``session`` is echoed back by the program.
    """
    if len(q) != 6:
        raise DeployError(f"setpoint needs 6 joint targets, got {len(q)}")
    values: dict[str, Any] = {
        INPUT_FIELDS[0]: int(seq),
        INPUT_FIELDS[1]: int(Command.DONE if done else Command.STREAM),
        INPUT_FIELDS[2]: int(session),
    }
    for field_name, value in zip(INPUT_FIELDS[3:9], q):
        values[field_name] = float(value)
    values[INPUT_FIELDS[9]] = float(gripper_opening_m)
    return values


@dataclass(frozen=True)
class ProgramStatus:
    """The streaming program's progress as reported in its output registers."""

    applied_seq: int
    """Last sequence number the program applied (output_int_register_24)."""
    state: ProgramState
    """output_int_register_25."""
    session: int
    """Session id the program read at start (output_int_register_26)."""
    gripper_opening_m: float
    """Gripper opening last applied [m] (output_double_register_24)."""


def program_status(values: Mapping[str, Any]) -> ProgramStatus:
    """Decode :data:`OUTPUT_FIELDS` from an RTDE state dict (e.g. ``RTDEClient.latest()``).

    Raises :class:`DeployError` if a field is missing or the state register holds
    a value no streaming program writes (another program owns the registers?).
    """
    try:
        raw_state = values[OUTPUT_FIELDS[1]]
        status = ProgramStatus(
            applied_seq=int(values[OUTPUT_FIELDS[0]]),
            state=ProgramState(raw_state),
            session=int(values[OUTPUT_FIELDS[2]]),
            gripper_opening_m=float(values[OUTPUT_FIELDS[3]]),
        )
    except KeyError as exc:
        raise DeployError(f"RTDE state lacks {exc.args[0]!r}; add urscript.OUTPUT_FIELDS to the output recipe") from None
    except ValueError:
        raise DeployError(
            f"{OUTPUT_FIELDS[1]} = {values[OUTPUT_FIELDS[1]]!r} is not a streaming-program state "
            f"({', '.join(f'{s.value} {s.name}' for s in ProgramState)}); is another program using registers 24-26?"
        ) from None
    return status


def send_program(host: str, program: str, port: int = SECONDARY_PORT, timeout_s: float = 2.0) -> None:
    """Send URScript ``program`` to the secondary interface (default port 30002).

    The controller does not answer; whether the program runs shows up in RTDE
    (``runtime_state`` 2 = PLAYING, and the program's own state register).
    A robot in local control silently ignores programs: check
    ``DashboardClient.is_in_remote_control()`` first. Raises :class:`RTDEError`
    if the connection cannot be made or the send times out [s].
    """
    data = program.encode("utf-8")
    if not data.endswith(b"\n"):
        data += b"\n"
    where = f"{host}:{port}"
    try:
        sock = socket.create_connection((host, port), timeout=timeout_s)
    except socket.timeout:
        raise RTDEError(f"cannot connect to the secondary interface at {where}: no answer within {timeout_s:g} s") from None
    except (OSError, UnicodeError, OverflowError) as exc:  # also a bad host label or port number
        raise RTDEError(f"cannot connect to the secondary interface at {where}: {getattr(exc, 'strerror', None) or exc}") from None
    try:
        sock.sendall(data)
        sock.shutdown(socket.SHUT_WR)
        # The controller streams binary state packages on this port; read and drop
        # them briefly so closing does not reset the connection before our text is read.
        deadline = time.monotonic() + min(0.1, timeout_s)
        while (remaining := deadline - time.monotonic()) > 0:
            sock.settimeout(remaining)
            try:
                if not sock.recv(65536):
                    break
            except socket.timeout:
                break
    except socket.timeout:
        raise RTDEError(f"sending the program to {where} timed out after {timeout_s:g} s") from None
    except OSError as exc:
        raise RTDEError(f"sending the program to {where} failed: {getattr(exc, 'strerror', None) or exc}") from None
    finally:
        sock.close()
