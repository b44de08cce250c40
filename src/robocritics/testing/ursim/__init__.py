"""A loopback UR e-series controller: real RTDE, Dashboard and secondary-interface servers on 127.0.0.1.

For tests and demos (``robocritics ursim``); :mod:`robocritics.deploy` never imports it.
"""

from .controller import KNOWN_INPUTS, KNOWN_OUTPUTS, SimEvent, SimSnapshot, URSim, main

__all__ = ["URSim", "SimSnapshot", "SimEvent", "KNOWN_OUTPUTS", "KNOWN_INPUTS", "main"]
