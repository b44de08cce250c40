"""What a robot that runs verified motion offers, whatever it is: the small protocol the deploy side is written
against. :class:`~robocritics.deploy.URArm` (RTDE + URScript servo stream) implements it; the deploy gate
(:mod:`robocritics.deploy.gate`) and the resampling to the control rate (:func:`robocritics.deploy.stream.resample`)
are shared by any backend.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["Backend"]


@runtime_checkable
class Backend(Protocol):
    """A robot the verified trace is deployed to.

    * ``actual_q()`` — the joint angles now, rad (where the next motion must be planned from);
    * ``approach(execution)`` — a slow motion from there to the start of ``execution``, to critique and deploy first;
    * ``deploy(motion, report, **options)`` — run the motion (an Execution or a Trajectory) if its report (bound to
      it by the trajectory hash) and the robot's state pass the gate; returns a result with the timing and the
      final pose, raises :class:`~robocritics.errors.DeployError` (a refusal, or a fault after which the robot
      was stopped).
    """

    def actual_q(self) -> np.ndarray: ...

    def approach(self, execution: Any, speed_fraction: float = 0.1) -> Any: ...

    def deploy(self, motion: Any, report: Any, **options: Any) -> Any: ...
