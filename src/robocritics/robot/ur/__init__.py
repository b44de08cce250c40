"""Universal Robots deployment layer: RTDE and Dashboard clients, the URScript
streaming program, and a loopback controller for tests.

* :class:`RTDEClient` — RTDE protocol v2/v1 client with a background reader.
* :class:`DashboardClient` — Dashboard Server (port 29999) commands.
* :func:`streaming_program`, :func:`send_program`, :func:`setpoint` — the servo
  streaming program, its register layout and the secondary-interface sender.
* :class:`URSim` — a loopback UR3e controller (real TCP servers on 127.0.0.1).
* :class:`URArm` — the deploy gate and the paced servo stream (:meth:`URArm.deploy`,
  :meth:`URArm.approach`, :class:`DeployResult`, :class:`DeployRefused`, :class:`DeployFault`).
"""

from robocritics.robot.ur.dashboard import DASHBOARD_PORT, DashboardClient
from robocritics.robot.ur.deploy import (
    Approach,
    DeployFault,
    DeployRefused,
    DeployResult,
    StreamPlan,
    URArm,
    resample,
)
from robocritics.robot.ur.rtde import (
    RTDE_PORT,
    InputRecipe,
    MessageLevel,
    OutputRecipe,
    RTDEClient,
    TextMessage,
)
from robocritics.robot.ur.sim import SimEvent, SimSnapshot, URSim
from robocritics.robot.ur.urscript import (
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
    "URSim",
    "SimSnapshot",
    "SimEvent",
    "URArm",
    "DeployResult",
    "DeployRefused",
    "DeployFault",
    "Approach",
    "StreamPlan",
    "resample",
]
