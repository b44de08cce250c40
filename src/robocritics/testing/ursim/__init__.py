"""A loopback UR controller: real TCP servers on 127.0.0.1 speaking RTDE, Dashboard and the secondary interface.

:class:`URSim` is what the tests and benchmarks deploy to. It is not a physics
simulator and does not interpret URScript; it is a protocol-exact stand-in for
an e-series controller that runs *our* streaming program. Every UR3e number it
uses (control period, joint speed limits, DH table for ``actual_TCP_pose``) comes
from :data:`robocritics.robot.arms.UR3E`, its forward kinematics from
:func:`robocritics.robot.ik.dh_forward`, its mode numbers from the tables in
:mod:`robocritics.deploy.rtde`; it starts at the robot model's home pose, in robot
mode RUNNING.

* **Time** is control cycles × 2 ms, and every rule below runs on it. With
  ``clock="realtime"`` (the default; ``robocritics ursim``) a thread runs a cycle
  every 2 ms of wall time. With ``clock="stepped"`` the time is simulated: one
  cycle per RTDE input data package (a streaming client's setpoints clock the
  controller) plus :meth:`URSim.step`, so tests are deterministic on a loaded host.

* **RTDE** (default port 30004): protocol versions 2 and 1 byte for byte —
  version negotiation, controller version, output recipes (v2 with a frequency
  up to 500 Hz; v1 at 125 Hz without recipe ids), input recipes, start/pause,
  data packages, text messages. It knows the real field names and types
  (``timestamp``, ``actual_q``, ``actual_TCP_pose`` from UR3e forward kinematics,
  ``robot_mode``, ``safety_mode``, ``runtime_state``, all registers, …), answers
  ``NOT_FOUND`` for unknown fields and ``IN_USE`` for inputs another client holds
  (or registers 0-23 when ``fieldbus_registers=True``). Output packages are
  produced by the control cycles (a recipe at f Hz gets f of every 500
  cycles). A client that does not read its data for ``slow_client_timeout_s``
  is disconnected, as a real controller does.
* **Dashboard** (default 29999): greeting, power on/off, brake release, load,
  play, stop, pause, robotmode, safetystatus, unlock protective stop (refused for
  ``unlock_delay_s`` of controller time after the stop, 5 s like the real controller),
  is in remote control, programState, running, quit.
* **Secondary interface** (default 30002): accepts program text. Programs made
  by :func:`~robocritics.deploy.urscript.streaming_program` (recognised by their
  marker line, parameters parsed from the text) are simulated; anything else is
  rejected with an RTDE text message (level ERROR) and an event.

The simulated streaming program follows :mod:`~robocritics.deploy.urscript`
statement by statement, once per 2 ms control cycle:

* ``servoj`` tracking: joint velocity = setpoint velocity (difference of the
  last two setpoints over their sequence distance × 2 ms; applied in the cycle a
  new setpoint arrives) + (target − q)/τ with τ = lookahead_time × 300 / gain
  (at least 2 ms), clipped to the joint speed limits (``UR3E.velocity_rad_s``
  unless ``speed_limits`` says otherwise). No acceleration limit, no dynamics.
* RTDE watchdog: no update of ``input_int_register_24`` for longer than
  ``1/min_hz`` s → the controller stops the program (``runtime_state`` STOPPED,
  joints decelerate at 4 rad/s²) and sends a text message.
* Stall check (the program's own): the counter's *value* unchanged for more than
  ``stall_limit`` cycles → state STALLED, ``stopj``.
* **Protective stop rule**: when a new setpoint arrives, the speed it asks for is
  |Δq_j| / (Δseq × 2 ms) (each sequence step is 2 ms of trajectory). If that
  exceeds ``jump_margin`` (default 1.5) × the joint's speed limit on any joint,
  the controller protective-stops: ``safety_mode`` 3 (PROTECTIVE_STOP), the
  program is stopped, the joints decelerate at 10 rad/s².
* ``stopj(a)`` on the done command, then the program ends (STOPPED).

Fault injection: :meth:`URSim.inject_drop`, :meth:`URSim.trigger_protective_stop`,
:meth:`URSim.set_slow`, :meth:`URSim.set_silent`, :meth:`URSim.set_remote_control`,
:meth:`URSim.corrupt_output` (NaN, ±inf or any value in an output field),
:meth:`URSim.inject_packages` (raw packages: floods, unknown types, truncated
ones), the constructor's ``fieldbus_registers`` — now, or at a known point of a
deployment with :meth:`URSim.at_program_time`.

Run it from a shell with ``python -m robocritics.testing.ursim`` (or the
``robocritics ursim`` command); Ctrl-C stops it.

The modules: :mod:`~robocritics.testing.ursim.controller` (:class:`URSim`, the RTDE server, the control loop,
fault injection), :mod:`~robocritics.testing.ursim.state` (what it knows, its RTDE fields),
:mod:`~robocritics.testing.ursim.servo` (the streaming program it runs),
:mod:`~robocritics.testing.ursim.text_servers` (Dashboard and secondary interface),
:mod:`~robocritics.testing.ursim.cli` (the command). For tests and demos; :mod:`robocritics.deploy` never
imports it.
"""

from .cli import main
from .controller import KNOWN_INPUTS, KNOWN_OUTPUTS, SimEvent, SimSnapshot, URSim

__all__ = ["URSim", "SimSnapshot", "SimEvent", "KNOWN_OUTPUTS", "KNOWN_INPUTS", "main"]
