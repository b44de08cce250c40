"""Tools (grippers) that mount on an arm's flange: TCP, finger axis, opening range, mass and capsules.

A tool is described in its mount frame, which is the arm's flange (``tool0``: +z out of the flange). Its
TCP sits at the fingertip centre with **+z the finger direction** and the fingers closing along the TCP's
**y** axis (robocritics' TCP convention, docs/robots.md). The gripper body is the tool's links, never a guess
from link names: every capsule a tool brings is in the ``gripper`` group, the arm's are ``arm``.

Bundled (:data:`TOOLS`): ``robotiq_2f85``, ``robotiq_hande``, ``franka_hand`` and ``none`` (no gripper: the
TCP is the flange; a grasp is refused). ``tool=PATH.urdf`` loads a tool from a URDF: its root link mounts on
the flange, it needs a ``tcp`` link, and a ``<gripper max_opening="..." fingers="..."/>`` element when it
grasps (see docs/robots.md, "Tools").
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

from ..errors import RobotModelError

__all__ = ["Tool", "TOOLS", "tool_named"]


@dataclass(frozen=True)
class Tool:
    """A gripper on the flange. Lengths in m, mass in kg; capsules ``(link, p0, p1, radius_m)`` in the link's
    frame; the body link sits at the flange turned ``mount_yaw_rad`` about its z axis."""

    name: str
    mass_kg: float
    max_opening_m: float
    tcp_from_flange_m: float
    finger_length_m: float
    finger_radius_m: float
    body: tuple[tuple[tuple[float, float, float], tuple[float, float, float], float], ...]
    mount_yaw_rad: float = 0.0
    source: str = ""
    sources: dict = field(default_factory=dict)

    @property
    def grasps(self) -> bool:
        return self.max_opening_m > 0

    def elements(self, flange: str, mount_rpy: tuple[float, float, float] | None = None) -> list[ET.Element]:
        """URDF ``<link>``/``<joint>`` elements (and the ``<gripper>``) that mount this tool on ``flange``: its mount
        frame is the flange frame, or turned by ``mount_rpy`` (rad; where the flange's outward axis is not its z,
        :func:`~robocritics.robot.vendor.flange_mount_rpy`), then ``mount_yaw_rad`` about the tool's z."""
        out: list[ET.Element] = []

        def link(name, capsules=()):
            element = ET.Element("link", name=name)
            for p0, p1, r in capsules:
                element.append(_cylinder(p0, p1, r))
            out.append(element)

        def joint(name, parent, child, xyz, yaw=0.0, turn=None):
            element = ET.Element("joint", name=name, type="fixed")
            ET.SubElement(element, "parent", link=parent)
            ET.SubElement(element, "child", link=child)
            ET.SubElement(element, "origin", xyz=" ".join(repr(float(v)) for v in xyz),
                          rpy=f"0 0 {yaw!r}" if turn is None else _turned_rpy(turn, yaw))
            out.append(element)

        link("gripper_body", self.body)
        joint("tool_mount", flange, "gripper_body", (0, 0, 0), self.mount_yaw_rad, mount_rpy)
        link("tcp")
        joint("tcp_joint", "gripper_body", "tcp", (0, 0, self.tcp_from_flange_m))
        links = ["gripper_body"]
        if self.grasps:
            r, length = self.finger_radius_m, self.finger_length_m
            finger_y = self.max_opening_m / 2 + r  # finger axis at full opening: inner face at opening / 2
            finger_z = self.tcp_from_flange_m - r - length
            for side, sign in (("left_finger", 1.0), ("right_finger", -1.0)):
                link(side, [((0.0, 0.0, 0.0), (0.0, 0.0, length), r)])
                joint(f"{side}_joint", "gripper_body", side, (0, sign * finger_y, finger_z))
                links.append(side)
            out.append(ET.Element("gripper", name=self.name, max_opening=repr(self.max_opening_m), tcp="tcp",
                                  fingers="left_finger right_finger", links=" ".join(links),
                                  finger_axis="0 0 1", closing_axis="0 1 0", mass=repr(self.mass_kg)))
        else:
            out.append(ET.Element("gripper", name=self.name, max_opening="0", tcp="tcp", fingers="", links=" ".join(links),
                                  mass=repr(self.mass_kg)))
        return out


def _turned_rpy(rpy, yaw: float) -> str:
    """The URDF ``rpy`` of the rotation ``rpy`` followed by ``yaw`` about the turned frame's z (rad)."""
    import numpy as np
    import pinocchio as pin

    R = pin.rpy.rpyToMatrix(*rpy) @ pin.rpy.rpyToMatrix(0.0, 0.0, yaw)
    return " ".join(repr(float(v)) for v in pin.rpy.matrixToRpy(np.asarray(R)))


def _cylinder(p0, p1, radius) -> ET.Element:
    """A ``<collision>`` whose cylinder is the capsule segment ``p0``-``p1`` of ``radius`` (robocritics' reading)."""
    import numpy as np
    import pinocchio as pin

    a, b = np.asarray(p0, float), np.asarray(p1, float)
    mid, d = (a + b) / 2, b - a
    length = float(np.linalg.norm(d))
    collision = ET.Element("collision")
    if length < 1e-12:
        ET.SubElement(collision, "origin", xyz=" ".join(repr(float(v)) for v in mid), rpy="0 0 0")
        geometry = ET.SubElement(collision, "geometry")
        ET.SubElement(geometry, "sphere", radius=repr(float(radius)))
        return collision
    z = d / length
    helper = np.eye(3)[int(np.argmin(np.abs(z)))]
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    R = np.column_stack([x, np.cross(z, x), z])
    rpy = pin.rpy.matrixToRpy(R)
    ET.SubElement(collision, "origin", xyz=" ".join(repr(float(v)) for v in mid), rpy=" ".join(repr(float(v)) for v in rpy))
    geometry = ET.SubElement(collision, "geometry")
    ET.SubElement(geometry, "cylinder", radius=repr(float(radius)), length=repr(length))
    return collision


TOOLS: dict[str, Tool] = {
    "robotiq_2f85": Tool(
        name="robotiq_2f85",
        mass_kg=0.925,
        max_opening_m=0.085,
        tcp_from_flange_m=0.15,
        finger_length_m=0.04,
        finger_radius_m=0.009,
        body=(((0.0, 0.0, 0.02), (0.0, 0.0, 0.055), 0.040),),
        source="Robotiq 2F-85 & 2F-140 instruction manual, 'Technical specifications': stroke 85 mm, mass 925 g; "
        "TCP at the fingertip centre, 0.15 m from the flange with the coupling (robocritics' bundled UR arms carry the same)",
    ),
    "robotiq_hande": Tool(
        name="robotiq_hande",
        mass_kg=1.0,
        max_opening_m=0.05,
        tcp_from_flange_m=0.146,
        finger_length_m=0.035,
        finger_radius_m=0.009,
        body=(((0.0, -0.03, 0.05), (0.0, 0.03, 0.05), 0.045),),
        source="Robotiq Hand-E instruction manual, 'Technical specifications': stroke 50 mm, mass 1 kg; "
        "fingertip 146 mm from the flange with the coupling",
    ),
    "franka_hand": Tool(
        name="franka_hand",
        mass_kg=0.73,
        max_opening_m=0.08,
        tcp_from_flange_m=0.1034,
        finger_length_m=0.04,
        finger_radius_m=0.009,
        body=(((0.0, -0.07, 0.035), (0.0, 0.07, 0.035), 0.03),),
        mount_yaw_rad=-math.pi / 4,
        source="Franka Control Interface documentation, 'Robot and interface specifications': Franka Hand stroke "
        "80 mm (40 mm per finger), mass 0.73 kg, TCP 0.1034 m from the flange, the hand turned -45 deg about it",
    ),
    "none": Tool(
        name="none",
        mass_kg=0.0,
        max_opening_m=0.0,
        tcp_from_flange_m=0.0,
        finger_length_m=0.0,
        finger_radius_m=0.0,
        body=(),
        source="no tool: the TCP is the flange; grasping is refused",
    ),
}
"""The bundled tools by name."""


def tool_named(name: str) -> Tool:
    """The bundled tool ``name``; a :class:`RobotModelError` listing the bundled ones otherwise."""
    try:
        return TOOLS[name]
    except (KeyError, TypeError):
        raise RobotModelError(f"no bundled tool {name!r}; the bundled tools are {', '.join(TOOLS)}, or give tool=PATH.urdf") from None
