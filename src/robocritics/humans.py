r"""People in the cell: the ISO/TS 15066 body regions, their biomechanical limits, and a capsule body model.

A scene's ``humans`` (:class:`robocritics.scene.Human`: where the feet stand, the direction faced, posture,
stature, floor height) become a :class:`BodyModel`: one or more capsules (segment + radius, m, base frame) per
body region of ISO/TS 15066:2016 Annex A, Table A.1. The collaborative-operation critics (``contact_speed``,
``separation``) read it; a plugin can too (``body_model(human)``, :data:`BODY_REGIONS`,
:func:`transient_speed_limit`).

Limits (ISO/TS 15066:2016, Annex A)
-----------------------------------
Per body region (:data:`BODY_REGIONS`):

* ``force_n``: maximum permissible force for quasi-static contact, Table A.2 [N];
* ``transient_factor``: the multiplier of Table A.2 for transient contact (2; 0 where transient contact is
  not permitted: skull and forehead, face);
* ``spring_n_m``: effective spring constant k of the region, Annex A [N/mm in the standard; N/m here]
  (secondary sources place it in Table A.2 or beside the masses of Table A.3);
* ``mass_kg``: effective mass m_H of the region, Table A.3 [kg].

The speed limit of a transient contact (Annex A, A.3.2, formulae A.6-A.8)::

    mu    = (1/m_H + 1/m_R)^-1           reduced mass of the two-body system [kg]
    m_R   = M/2 + m_L                    effective robot mass: half the moving mass M plus the payload m_L [kg]
    v_max = F_max / sqrt(mu * k)         [m/s], F_max the transient force (2 x Table A.2)

Body model
----------
Segment lengths and heights are fractions of stature H. Heights of the eye, mid-shoulder, waist and buttocks
are the 50th-percentile man of R. L. Huston, *Principles of Biomechanics* (CRC Press, 2009), Table 2 "Standing
and sitting dimensions" (stature 1.759 m; from US military anthropometry); segment lengths and breadths
(shoulder 0.259 H, hip 0.191 H, upper arm 0.186 H, forearm 0.146 H, hand 0.108 H, thigh 0.245 H, knee height
0.285 H, ankle 0.039 H, chin 0.870 H) are Drillis and Contini (1966) as tabulated in D. A. Winter,
*Biomechanics and Motor Control of Human Movement* (4th ed., Wiley 2009), Fig. 4.1. Radii (depths) are
chosen to enclose a 50th-percentile body (chest depth 0.13 H = 0.23 m, abdomen 0.12 H, head breadth 0.09 H):
a capsule model over-covers rather than under-covers. The operator stands at a bench: upper arms hang, elbows
bent 90 degrees, forearms and hands reach forward horizontally at elbow height. Seated: the hips sit at
0.30 H above the floor (popliteal height 0.25 H + thigh), thighs horizontal, lower legs vertical.

The back of the trunk is part of the chest, abdomen and pelvis capsules: at a bench the operator faces the
robot, and the chest's limit (140 N) is below the back's (210 N), so this errs on the safe side.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Mapping

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from .scene import Human, Scene

__all__ = [
    "BodyRegion",
    "BODY_REGIONS",
    "BodyModel",
    "body_model",
    "scene_bodies",
    "reduced_mass_kg",
    "transient_speed_limit",
    "LIMITS_SOURCE",
]

LIMITS_SOURCE = (
    "ISO/TS 15066:2016 Annex A: maximum permissible forces and the transient multiplier, Table A.2; effective "
    "masses, Table A.3; effective spring constants, Annex A (A.3)"
)


@dataclass(frozen=True)
class BodyRegion:
    """One ISO/TS 15066 body region and its biomechanical limits (Annex A)."""

    name: str
    label: str
    force_n: float
    """Maximum permissible force, quasi-static contact, N (Table A.2)."""
    transient_factor: float
    """Multiplier for transient contact (Table A.2): 2, or 0 where transient contact is not permitted."""
    spring_n_m: float
    """Effective spring constant k, N/m (Annex A gives N/mm)."""
    mass_kg: float
    """Effective mass m_H, kg (Table A.3)."""

    @property
    def transient_force_n(self) -> float:
        """Maximum permissible transient force, N: ``transient_factor * force_n`` (0: no contact permitted)."""
        return self.transient_factor * self.force_n

    @property
    def contact_permitted(self) -> bool:
        return self.transient_factor > 0


def _region(name: str, label: str, force_n: float, factor: float, k_n_mm: float, mass_kg: float) -> BodyRegion:
    return BodyRegion(name, label, force_n, factor, k_n_mm * 1000.0, mass_kg)


BODY_REGIONS: Mapping[str, BodyRegion] = MappingProxyType(
    {
        r.name: r
        for r in (
            _region("skull_forehead", "skull and forehead", 130, 0, 150, 4.4),
            _region("face", "face", 65, 0, 75, 4.4),
            _region("neck", "neck", 150, 2, 50, 1.2),
            _region("back_shoulders", "back and shoulders", 210, 2, 35, 40),
            _region("chest", "chest", 140, 2, 25, 40),
            _region("abdomen", "abdomen", 110, 2, 10, 40),
            _region("pelvis", "pelvis", 180, 2, 25, 40),
            _region("upper_arms", "upper arms and elbow joints", 150, 2, 30, 3),
            _region("lower_arms", "lower arms and wrist joints", 160, 2, 40, 2),
            _region("hands", "hands and fingers", 140, 2, 75, 0.6),
            _region("thighs_knees", "thighs and knees", 220, 2, 50, 75),
            _region("lower_legs", "lower legs", 130, 2, 60, 75),
        )
    }
)
"""The twelve body regions of ISO/TS 15066 Annex A with their limits (see the module docstring)."""


def reduced_mass_kg(human_mass_kg: float, robot_mass_kg: float) -> float:
    """``mu = (1/m_H + 1/m_R)^-1``, kg (ISO/TS 15066 Annex A, formula A.6)."""
    return 1.0 / (1.0 / human_mass_kg + 1.0 / robot_mass_kg)


def transient_speed_limit(region: BodyRegion, moving_mass_kg: float, payload_kg: float) -> float:
    """Largest permissible relative speed of a transient contact with ``region``, m/s (Annex A, A.3.2).

    ``v_max = F_max / sqrt(mu k)`` with ``F_max`` the transient force (2 x Table A.2), ``k`` (Annex A),
    ``m_H`` (Table A.3) and ``m_R = M/2 + m_L`` (``moving_mass_kg`` M: the robot's moving parts;
    ``payload_kg`` m_L: tool and workpiece). 0 where transient contact is not permitted (skull and forehead, face).
    """
    if not region.contact_permitted:
        return 0.0
    robot_kg = moving_mass_kg / 2.0 + payload_kg
    return region.transient_force_n / math.sqrt(reduced_mass_kg(region.mass_kg, robot_kg) * region.spring_n_m)


@dataclass(frozen=True)
class BodyModel:
    """Capsules of one person's body regions, m in the base frame: capsule ``i`` is segment ``p0[i]``-``p1[i]``
    of radius ``radius_m[i]``, in region ``regions[i]`` (a key of :data:`BODY_REGIONS`), named ``names[i]``."""

    human: str
    names: tuple[str, ...]
    regions: tuple[str, ...]
    p0: np.ndarray
    p1: np.ndarray
    radius_m: np.ndarray

    def __len__(self) -> int:
        return len(self.names)


# Capsules in the person's frame (x forward, y left, z up from the floor), in units of stature H:
# (name, region, p0, p1, radius). Heights: Huston (2009); lengths and breadths: Drillis and Contini via Winter.
_SHOULDER_Z = 0.821  # mid-shoulder height (Huston: 1.444 / 1.759)
_SHOULDER_Y = 0.259 / 2  # half the shoulder breadth (Winter Fig. 4.1)
_ELBOW_Z = _SHOULDER_Z - 0.186  # upper arm hangs (upper arm 0.186 H)
_WRIST_X = 0.146  # forearm reaches forward (forearm 0.146 H)
_HAND_X = _WRIST_X + 0.108  # hand 0.108 H
_UPPER_BODY = (
    ("skull_forehead", "skull_forehead", (0.0, 0.0, 0.935), (0.0, 0.0, 0.955), 0.045),  # eye 0.935 H, top 1.0 H
    ("face", "face", (0.02, 0.0, 0.89), (0.02, 0.0, 0.915), 0.035),  # chin 0.870 H
    ("neck", "neck", (0.0, 0.0, 0.83), (0.0, 0.0, 0.87), 0.03),
    ("shoulders", "back_shoulders", (0.0, -0.09, 0.80), (0.0, 0.09, 0.80), 0.035),
    ("chest", "chest", (0.0, -0.06, 0.72), (0.0, 0.06, 0.72), 0.065),
    ("abdomen", "abdomen", (0.0, -0.04, 0.60), (0.0, 0.04, 0.60), 0.06),  # waist 0.627 H (Huston)
    ("pelvis", "pelvis", (0.0, -0.04, 0.50), (0.0, 0.04, 0.50), 0.055),  # hip breadth 0.191 H
    ("upper_arm_left", "upper_arms", (0.0, _SHOULDER_Y, 0.81), (0.0, _SHOULDER_Y, _ELBOW_Z), 0.025),
    ("upper_arm_right", "upper_arms", (0.0, -_SHOULDER_Y, 0.81), (0.0, -_SHOULDER_Y, _ELBOW_Z), 0.025),
    ("lower_arm_left", "lower_arms", (0.0, _SHOULDER_Y, _ELBOW_Z), (_WRIST_X, _SHOULDER_Y, _ELBOW_Z), 0.02),
    ("lower_arm_right", "lower_arms", (0.0, -_SHOULDER_Y, _ELBOW_Z), (_WRIST_X, -_SHOULDER_Y, _ELBOW_Z), 0.02),
    ("hand_left", "hands", (_WRIST_X, _SHOULDER_Y, _ELBOW_Z), (_HAND_X, _SHOULDER_Y, _ELBOW_Z), 0.015),
    ("hand_right", "hands", (_WRIST_X, -_SHOULDER_Y, _ELBOW_Z), (_HAND_X, -_SHOULDER_Y, _ELBOW_Z), 0.015),
)
_HIP_Z, _KNEE_Z, _ANKLE_Z, _THIGH_X = 0.47, 0.285, 0.039, 0.245
_STANDING_LEGS = tuple(
    leg
    for side, y in (("left", 0.05), ("right", -0.05))
    for leg in (
        (f"thigh_{side}", "thighs_knees", (0.0, y, _HIP_Z), (0.0, y, _KNEE_Z), 0.045),
        (f"lower_leg_{side}", "lower_legs", (0.0, y, _KNEE_Z), (0.0, y, _ANKLE_Z), 0.03),
    )
)
_SEATED_HIP_Z = 0.30
"""Seated: hip joint height above the floor, in H (popliteal height 0.25 H plus half the thigh's depth)."""
_SEATED_DROP = 0.53 - _SEATED_HIP_Z  # the upper body sits this much lower than standing (hip joint 0.53 H)
_SEATED_LEGS = tuple(
    leg
    for side, y in (("left", 0.05), ("right", -0.05))
    for leg in (
        (f"thigh_{side}", "thighs_knees", (0.0, y, _SEATED_HIP_Z), (_THIGH_X, y, _SEATED_HIP_Z), 0.045),
        (f"lower_leg_{side}", "lower_legs", (_THIGH_X, y, _KNEE_Z), (_THIGH_X, y, _ANKLE_Z), 0.03),
    )
)


def _local_capsules(posture: str) -> tuple[tuple, ...]:
    if posture == "standing":
        return _UPPER_BODY + _STANDING_LEGS
    seated = tuple(
        (n, r, (a[0], a[1], a[2] - _SEATED_DROP), (b[0], b[1], b[2] - _SEATED_DROP), rad)
        for n, r, a, b, rad in _UPPER_BODY
    )
    return seated + _SEATED_LEGS


def body_model(human: "Human") -> BodyModel:
    """The capsules of ``human``'s ISO/TS 15066 body regions, m in the robot base frame."""
    H = float(human.height_m)
    local = _local_capsules(human.posture)
    c, s = math.cos(human.yaw_rad), math.sin(human.yaw_rad)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    origin = np.array([human.position[0], human.position[1], human.floor_z_m], dtype=float)
    p0 = np.array([a for _, _, a, _, _ in local], dtype=float) * H @ rot.T + origin
    p1 = np.array([b for _, _, _, b, _ in local], dtype=float) * H @ rot.T + origin
    return BodyModel(
        human=human.id,
        names=tuple(n for n, *_ in local),
        regions=tuple(r for _, r, *_ in local),
        p0=p0,
        p1=p1,
        radius_m=np.array([rad for *_, rad in local], dtype=float) * H,
    )


def scene_bodies(scene: "Scene") -> list[BodyModel]:
    """The body model of every person in ``scene`` (empty when there is none)."""
    return [body_model(h) for h in getattr(scene, "humans", ())]
