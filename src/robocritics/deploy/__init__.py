"""Deployment to a Universal Robots arm: RTDE and Dashboard clients, the URScript
streaming program, the gate and the paced servo stream — typed on
:class:`~robocritics.trajectory.Trajectory` and :class:`~robocritics.critic.report.Report`.

* :mod:`~robocritics.deploy.rtde` — :class:`RTDEClient`, RTDE protocol v2/v1 with a background reader;
  the mode tables :class:`RobotMode`, :class:`SafetyMode`, :class:`RuntimeState`.
* :mod:`~robocritics.deploy.dashboard` — :class:`DashboardClient`, Dashboard Server (port 29999) commands.
* :mod:`~robocritics.deploy.urscript` — :func:`streaming_program`, :func:`send_program`, :func:`setpoint`:
  the servo streaming program, its register layout and the secondary-interface sender.
* :mod:`~robocritics.deploy.gate` — the rules a motion and the arm must pass; :class:`DeployRefused`.
* :mod:`~robocritics.deploy.stream` — :func:`resample`, the paced stream, :class:`DeployResult`,
  :class:`DeployFault`.
* :mod:`~robocritics.deploy.arm` — :class:`URArm` (:meth:`URArm.deploy`, :meth:`URArm.approach`) and
  :func:`approach_trajectory`.

The loopback controller used by tests and demos is :mod:`robocritics.testing.ursim`;
this package never imports it.
"""

from robocritics.deploy.arm import URArm, approach_trajectory
from robocritics.deploy.backend import Backend
from robocritics.deploy.dashboard import DASHBOARD_PORT, DashboardClient
from robocritics.deploy.gate import DeployRefused
from robocritics.deploy.rtde import (
    RTDE_PORT,
    InputRecipe,
    MessageLevel,
    OutputRecipe,
    RobotMode,
    RTDEClient,
    RuntimeState,
    SafetyMode,
    TextMessage,
)
from robocritics.deploy.stream import DeployFault, DeployProgress, DeployResult, StreamPlan, resample
from robocritics.deploy.urscript import (
    INPUT_FIELDS,
    OUTPUT_FIELDS,
    SECONDARY_PORT,
    ProgramState,
    ProgramStatus,
    StreamingProgramParams,
    parse_streaming_program,
    program_status,
    send_program,
    setpoint,
    streaming_program,
)

__all__ = [
    "Backend",
    "RTDE_PORT",
    "DASHBOARD_PORT",
    "SECONDARY_PORT",
    "RTDEClient",
    "InputRecipe",
    "OutputRecipe",
    "MessageLevel",
    "TextMessage",
    "RobotMode",
    "SafetyMode",
    "RuntimeState",
    "DashboardClient",
    "streaming_program",
    "parse_streaming_program",
    "StreamingProgramParams",
    "ProgramState",
    "ProgramStatus",
    "program_status",
    "INPUT_FIELDS",
    "OUTPUT_FIELDS",
    "setpoint",
    "send_program",
    "URArm",
    "approach_trajectory",
    "DeployResult",
    "DeployRefused",
    "DeployFault",
    "DeployProgress",
    "StreamPlan",
    "resample",
]
