"""The channels to one UR controller and their state: what the servo stream (:mod:`robocritics.deploy.stream`)
works over, without knowing the :class:`~robocritics.deploy.URArm` that opened them.

:class:`URConnection` holds the RTDE client with its input recipe and output rate, the Dashboard client (with the
lock its users share and whether an exchange on it failed), the setpoint sequence counter, the controller's text
messages, and where the controller is (host, ports, the request timeout [s]). ``URArm.connect()`` fills it in;
``URArm.close()`` empties it.
"""

from __future__ import annotations

import collections
import threading
from dataclasses import dataclass, field

from robocritics.deploy.dashboard import DashboardClient
from robocritics.deploy.rtde import InputRecipe, RTDEClient, TextMessage
from robocritics.errors import DeployError

__all__ = ["URConnection"]


@dataclass
class URConnection:
    """One UR controller's channels (see the module docstring); ``rtde`` and ``dashboard`` raise when closed."""

    host: str
    rtde_port: int
    dashboard_port: int
    secondary_port: int
    timeout_s: float
    frequency_hz: float
    rtde_client: RTDEClient | None = None
    dashboard_client: DashboardClient | None = None
    #: An exchange on the dashboard failed: reconnect it before the next (:meth:`healthy_dashboard`).
    dashboard_broken: bool = False
    #: Held by whoever talks to the dashboard (the deploy's monitor thread, a stop, the caller).
    dash_lock: threading.Lock = field(default_factory=threading.Lock)
    inputs: InputRecipe | None = None
    #: The last setpoint's sequence number (int32, wrapping).
    seq: int = 0
    #: The output rate the controller granted [Hz].
    out_freq: float = 0.0
    messages: collections.deque[TextMessage] = field(default_factory=lambda: collections.deque(maxlen=256))

    def __post_init__(self) -> None:
        self.out_freq = self.out_freq or self.frequency_hz

    @property
    def rtde(self) -> RTDEClient:
        """The RTDE client (raises if not connected)."""
        if self.rtde_client is None:
            raise DeployError(f"URArm {self.host} is not connected; use 'with URArm(...) as arm:' or connect()")
        return self.rtde_client

    @property
    def dashboard(self) -> DashboardClient:
        """The dashboard client (raises if not connected)."""
        if self.dashboard_client is None:
            raise DeployError(f"URArm {self.host} is not connected; use 'with URArm(...) as arm:' or connect()")
        return self.dashboard_client

    def healthy_dashboard(self) -> DashboardClient:
        """The dashboard client, reconnected if an earlier exchange failed (caller holds ``dash_lock``)."""
        dash = self.dashboard
        if self.dashboard_broken:
            dash.close()
            dash = DashboardClient(self.host, self.dashboard_port, timeout_s=self.timeout_s)
            dash.connect()
            self.dashboard_client = dash
            self.dashboard_broken = False
        return dash
