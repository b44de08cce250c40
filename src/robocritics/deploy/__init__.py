"""Deployment to a Universal Robots arm: RTDE and Dashboard clients, the URScript
streaming program, the gate and the paced servo stream.

The loopback controller used by tests and demos is :mod:`robocritics.testing.ursim`;
this package never imports it.

* :class:`RTDEClient` — RTDE protocol v2/v1 client with a background reader.
* :class:`DashboardClient` — Dashboard Server (port 29999) commands.
* :func:`streaming_program`, :func:`send_program`, :func:`setpoint` — the servo
  streaming program, its register layout and the secondary-interface sender.
* :class:`URArm` — the deploy gate and the paced servo stream (:meth:`URArm.deploy`,
  :meth:`URArm.approach`, :class:`DeployResult`, :class:`DeployRefused`, :class:`DeployFault`).
"""

from robocritics.deploy.dashboard import DASHBOARD_PORT, DashboardClient
from robocritics.deploy.stream import (
    Approach,
    DeployFault,
    DeployRefused,
    DeployResult,
    StreamPlan,
    URArm,
    resample,
)
from robocritics.deploy.rtde import (
    RTDE_PORT,
    InputRecipe,
    MessageLevel,
    OutputRecipe,
    RTDEClient,
    TextMessage,
)
from robocritics.deploy.urscript import (
    INPUT_FIELDS,
    OUTPUT_FIELDS,
    SECONDARY_PORT,
    ProgramState,
    ProgramStatus,
    StreamingProgramParams,
    program_status,
    parse_streaming_program,
    send_program,
    setpoint,
    streaming_program,
)

__all__ = [
    "RTDE_PORT",
    "DASHBOARD_PORT",
    "SECONDARY_PORT",
    "RTDEClient",
    "InputRecipe",
    "OutputRecipe",
    "MessageLevel",
    "TextMessage",
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
    "DeployResult",
    "DeployRefused",
    "DeployFault",
    "Approach",
    "StreamPlan",
    "resample",
]
