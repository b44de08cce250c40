"""Arm facts, in one place: DH tables, joint limits with their sources, the control period.

Everything else reads these: the URDF generator (``tools/make_ur3e_urdf.py``), the
robot model's acceleration and jerk limits, closed-form IK, the loopback
controller (:mod:`robocritics.testing.ursim`), the deploy gate and the scene's
default workspace centre. Units: m, rad, s, kg, N·m.

Kinematic convention (standard Denavit-Hartenberg, as Universal Robots publish it)::

    A_i(theta_i) = Rz(theta_i) · Tz(d_i) · Tx(a_i) · Rx(alpha_i)
    T_06(q)      = A_1(q_1) · A_2(q_2) · ... · A_6(q_6)     (flange pose in the base frame)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType
from typing import Mapping

from ..errors import RobotModelError

__all__ = ["DH", "ModifiedDH", "ArmSpec", "UR3E", "UR5E", "UR10E", "UR16E", "ARMS", "PANDA", "DEFAULT_ARM"]

_HALF_PI = 0.5 * math.pi
_UR_ALPHA = (_HALF_PI, 0.0, 0.0, _HALF_PI, -_HALF_PI, 0.0)


@dataclass(frozen=True)
class DH:
    """Standard Denavit-Hartenberg parameters of a 6-joint serial arm.

    ``A_i = Rz(theta_i) Tz(d[i]) Tx(a[i]) Rx(alpha[i])``; ``d`` and ``a`` in
    metres, ``alpha`` in radians, all three tuples of six floats (joint 1 first).
    ``theta_i`` is the joint angle ``q_i`` (UR arms have no angle offsets).
    Use :meth:`ur` to build a UR-like set from its six non-zero lengths.
    """

    d: tuple[float, ...]
    a: tuple[float, ...]
    alpha: tuple[float, ...]
    name: str = "arm"

    def __post_init__(self) -> None:
        for field_name in ("d", "a", "alpha"):
            raw = getattr(self, field_name)
            try:
                values = tuple(float(v) for v in raw)
            except (TypeError, ValueError) as exc:
                raise RobotModelError(f"DH {field_name}: expected 6 numbers, got {raw!r}") from exc
            if len(values) != 6:
                raise RobotModelError(f"DH {field_name}: expected 6 values, got {len(values)}")
            if not all(math.isfinite(v) for v in values):
                raise RobotModelError(f"DH {field_name}: values must be finite, got {values}")
            object.__setattr__(self, field_name, values)

    @classmethod
    def ur(
        cls, d1: float, a2: float, a3: float, d4: float, d5: float, d6: float, name: str = "ur"
    ) -> DH:
        """A UR-family parameter set: ``d = (d1, 0, 0, d4, d5, d6)``,
        ``a = (0, a2, a3, 0, 0, 0)``, ``alpha = (pi/2, 0, 0, pi/2, -pi/2, 0)`` (m, rad)."""
        return cls(
            d=(d1, 0.0, 0.0, d4, d5, d6),
            a=(0.0, a2, a3, 0.0, 0.0, 0.0),
            alpha=_UR_ALPHA,
            name=name,
        )

    # Named accessors for the UR lengths (m).
    d1 = property(lambda self: self.d[0], doc="Base to shoulder height d1 (m).")
    a2 = property(lambda self: self.a[1], doc="Upper-arm length a2 (m, negative for UR).")
    a3 = property(lambda self: self.a[2], doc="Forearm length a3 (m, negative for UR).")
    d4 = property(lambda self: self.d[3], doc="Shoulder-to-wrist lateral offset d4 (m).")
    d5 = property(lambda self: self.d[4], doc="Wrist 1 to wrist 2 offset d5 (m).")
    d6 = property(lambda self: self.d[5], doc="Wrist 2 to flange offset d6 (m).")

    @property
    def is_ur_like(self) -> bool:
        """True when the closed form of :func:`ur_ik_all` applies: UR twist
        angles, ``a1 = a4 = a5 = a6 = 0`` (``d2``, ``d3`` may be non-zero)."""
        return (
            all(abs(x - y) < 1e-12 for x, y in zip(self.alpha, _UR_ALPHA))
            and self.a[0] == 0.0
            and self.a[3] == 0.0
            and self.a[4] == 0.0
            and self.a[5] == 0.0
            and self.a[1] != 0.0
            and self.a[2] != 0.0
        )

    def flange_pose(self, q) -> list[list[float]]:
        """``T_06(q) = A_1(q_1) ... A_6(q_6)`` (the module docstring's convention) as four rows of four floats: the
        flange pose in the base frame (m) at joint angles ``q`` (6, rad). The plain product, on Python floats."""
        T = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
        for theta, d, a, alpha in zip(q, self.d, self.a, self.alpha):
            ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
            A = [[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0.0, sa, ca, d], [0.0, 0.0, 0.0, 1.0]]
            T = [[sum(T[i][k] * A[k][j] for k in range(4)) for j in range(4)] for i in range(4)]
        return T

    def __hash__(self) -> int:
        # IK caches per-arm models keyed by the DH set; hash the 19 fields once, not per lookup
        return self._hash

    @cached_property
    def _hash(self) -> int:
        return hash((self.d, self.a, self.alpha, self.name))

    @cached_property
    def _ur(self) -> tuple[float, ...]:
        """Constants of the closed form: d1, a2, a3, d2+d3+d4, d5, d6, a2²+a3², 2 a2 a3."""
        if not self.is_ur_like:
            raise RobotModelError(
                f"DH {self.name!r} is not UR-like (need alpha = (pi/2, 0, 0, pi/2, -pi/2, 0), "
                f"a1 = a4 = a5 = a6 = 0, a2, a3 != 0): use numeric_ik instead"
            )
        d1, d2, d3, d4, d5, d6 = self.d
        a2, a3 = self.a[1], self.a[2]
        return (d1, a2, a3, d2 + d3 + d4, d5, d6, a2 * a2 + a3 * a3, 2.0 * a2 * a3)


@dataclass(frozen=True)
class ModifiedDH:
    """Modified (Craig) Denavit-Hartenberg parameters, as Franka Emika publish the Panda's.

    ``T_i(q_i) = Rx(alpha[i]) Tx(a[i]) Rz(q_i) Tz(d[i])`` per joint (m, rad), then the
    fixed flange ``Tz(flange_d_m)``: ``T_flange(q) = T_1(q_1) ... T_n(q_n) Tz(flange_d_m)``.
    """

    a: tuple[float, ...]
    d: tuple[float, ...]
    alpha: tuple[float, ...]
    flange_d_m: float
    name: str = "arm"


def _per_joint(name: str, values, n: int) -> tuple[float, ...]:
    out = tuple(float(v) for v in values)
    if len(out) != n or not all(math.isfinite(v) for v in out):
        raise RobotModelError(f"arm spec {name}: expected {n} finite numbers (one per joint), got {values!r}")
    return out


@dataclass(frozen=True)
class ArmSpec:
    """Published facts of one arm (per joint, base first). Immutable: share it freely.

    ``dh`` is the standard-DH table of a UR arm (closed-form IK); other arms give None and
    their ``modified_dh`` (the Panda).
    """

    name: str
    dh: DH | None
    joint_names: tuple[str, ...]
    lower_rad: tuple[float, ...]
    upper_rad: tuple[float, ...]
    velocity_rad_s: tuple[float, ...]
    acceleration_rad_s2: tuple[float, ...]
    jerk_rad_s3: tuple[float, ...]
    effort_nm: tuple[float, ...]
    link_masses_kg: tuple[float, ...]
    """Masses of the moving links, base joint's first (shoulder ... wrist 3 on a UR) [kg]."""
    control_period_s: float
    """Controller cycle: one servo setpoint per period [s]."""
    reach_m: float
    """Published reach [m]: the radius of the default workspace sphere around the shoulder."""
    sources: Mapping[str, str] = field(default_factory=dict)
    """Where each group of numbers comes from (field name -> citation or reason)."""
    modified_dh: ModifiedDH | None = None
    """The kinematics of an arm published in modified DH (``dh`` is None then)."""
    rated_payload_kg: float | None = None
    """Rated payload at the tool flange (tool plus workpiece) [kg]; None where not recorded here."""
    payload_full_offset_m: float | None = None
    """Centre-of-gravity offset from the flange up to which the rated payload holds [m]; beyond it the allowed
    payload falls as ``rated * offset_full / offset`` (a constant wrist moment). None where not recorded."""
    stopping_time_s: tuple[float, ...] = ()
    """Published stopping times of the first three joints (base, shoulder, elbow) [s]."""
    stopping_distance_rad: tuple[float, ...] = ()
    """Published stopping distances of the first three joints (base, shoulder, elbow) [rad]."""
    pose_repeatability_m: float | None = None
    """Published pose repeatability (ISO 9283) [m]."""

    def __post_init__(self) -> None:
        n = len(self.joint_names)
        for f in ("lower_rad", "upper_rad", "velocity_rad_s", "acceleration_rad_s2", "jerk_rad_s3", "effort_nm",
                  "link_masses_kg"):
            object.__setattr__(self, f, _per_joint(f, getattr(self, f), n))
        object.__setattr__(self, "sources", MappingProxyType(dict(self.sources)))

    @property
    def dashboard_model(self) -> str:
        """What the controller's dashboard answers to ``get robot model`` for this arm: ``"UR3"`` for the
        UR3e (the dashboard names the size, not the series)."""
        return self.name[:-1].upper() if self.name.endswith("e") else self.name.upper()

    @property
    def control_rate_hz(self) -> float:
        """Controller cycles per second [Hz]."""
        return 1.0 / self.control_period_s


_UR_E_SERIES_SOURCES = {
    "dh": "Universal Robots, 'DH parameters for calculations of kinematics and dynamics' (e-series table)",
    "lower_rad": "UR e-series user manual: every joint +-360 deg; the elbow is limited to +-180 deg by its cable",
    "velocity_rad_s": "UR3e technical specification: base, shoulder, elbow 180 deg/s; wrists 360 deg/s",
    "acceleration_rad_s2": "not published by UR; chosen below movej's practical maxima so a jerk-limited profile "
    "stays inside what the controller accepts without a protective stop",
    "jerk_rad_s3": "not published by UR; 10x the acceleration limit (a ramp of 0.1 s)",
    "effort_nm": "UR3e technical specification: joint torques 56/56/28/12/12/12 N m",
    "link_masses_kg": "Universal Robots, 'DH parameters for calculations of kinematics and dynamics' (masses)",
    "control_period_s": "UR e-series: 500 Hz controller cycle (RTDE up to 500 Hz, servoj t = 0.002 s)",
    "reach_m": "UR e-series technical specifications: reach 500 / 850 / 1300 / 900 mm (UR3e / UR5e / UR10e / UR16e)",
    "rated_payload_kg": "UR e-series technical specifications: payload 3 / 5 / 12.5 / 16 kg (UR3e / UR5e / "
    "UR10e / UR16e)",
    "payload_full_offset_m": "UR3e user manual (e-Series), 'Maximum payload': the figure of rated payload against "
    "centre-of-gravity offset; its knee read off the figure (approximate: UR publishes the figure, not a table)",
    "stopping_time_s": "UR3/CB3 user manual v3.10, Appendix A.1, Stop Category 0 at 100 % extension, 100 % speed "
    "(183 deg/s), 3 kg payload: base 159 ms, shoulder 154 ms, elbow 92 ms. UR publishes the UR3e's (e-Series "
    "manual, chapter 'Stopping time and stopping distance') as graphs only; the CB3 table of the same size of arm "
    "is the numeric table we have",
    "stopping_distance_rad": "UR3/CB3 user manual v3.10, Appendix A.1 (as stopping_time_s): base 0.18, shoulder "
    "0.20, elbow 0.15 rad",
    "pose_repeatability_m": "UR3e technical specification: pose repeatability per ISO 9283 +-0.03 mm",
}

UR3E = ArmSpec(
    name="ur3e",
    dh=DH.ur(d1=0.15185, a2=-0.24355, a3=-0.2132, d4=0.13105, d5=0.08535, d6=0.0921, name="ur3e"),
    joint_names=(
        "shoulder_pan_joint",
        "shoulder_lift_joint",
        "elbow_joint",
        "wrist_1_joint",
        "wrist_2_joint",
        "wrist_3_joint",
    ),
    lower_rad=(-2 * math.pi, -2 * math.pi, -math.pi, -2 * math.pi, -2 * math.pi, -2 * math.pi),
    upper_rad=(2 * math.pi, 2 * math.pi, math.pi, 2 * math.pi, 2 * math.pi, 2 * math.pi),
    velocity_rad_s=(math.pi, math.pi, math.pi, 2 * math.pi, 2 * math.pi, 2 * math.pi),
    acceleration_rad_s2=(10.0, 10.0, 10.0, 20.0, 20.0, 20.0),
    jerk_rad_s3=(100.0, 100.0, 100.0, 200.0, 200.0, 200.0),
    effort_nm=(56.0, 56.0, 28.0, 12.0, 12.0, 12.0),
    link_masses_kg=(1.98, 3.4445, 1.437, 0.871, 0.805, 0.261),
    control_period_s=0.002,
    reach_m=0.5,
    sources=_UR_E_SERIES_SOURCES,
    rated_payload_kg=3.0,
    payload_full_offset_m=0.15,
    stopping_time_s=(0.159, 0.154, 0.092),
    stopping_distance_rad=(0.18, 0.20, 0.15),
    pose_repeatability_m=0.00003,
)
"""The UR3e (e-series)."""

# the sources that hold for the whole family (the stopping and payload-curve data above are the UR3e's only)
_FAMILY_SOURCES = {"dh", "lower_rad", "acceleration_rad_s2", "jerk_rad_s3", "link_masses_kg", "control_period_s",
                   "reach_m", "rated_payload_kg"}


def _ur_e_series(name: str, dh: DH, reach_m: float, velocity_rad_s, effort_nm, link_masses_kg, velocity_source: str,
                 effort_source: str, rated_payload_kg: float) -> ArmSpec:
    """An e-series arm: the family shares joint names, ranges, acceleration/jerk choices and the 500 Hz cycle."""
    return ArmSpec(
        name=name,
        dh=dh,
        joint_names=UR3E.joint_names,
        lower_rad=UR3E.lower_rad,
        upper_rad=UR3E.upper_rad,
        velocity_rad_s=velocity_rad_s,
        acceleration_rad_s2=UR3E.acceleration_rad_s2,
        jerk_rad_s3=UR3E.jerk_rad_s3,
        effort_nm=effort_nm,
        link_masses_kg=link_masses_kg,
        control_period_s=UR3E.control_period_s,
        reach_m=reach_m,
        sources={**{k: v for k, v in _UR_E_SERIES_SOURCES.items() if k in _FAMILY_SOURCES},
                 "velocity_rad_s": velocity_source, "effort_nm": effort_source},
        rated_payload_kg=rated_payload_kg,
    )


_DEG = math.pi / 180.0
# The speed and torque limits below were checked against UR's e-series user manuals v5.8 as transcribed
# in Universal Robots' own ROS description (Universal_Robots_ROS2_Description, config/<arm>/joint_limits.yaml,
# "Universal Robots e-Series, User Manual, <arm>, Version 5.8" and UR's support article "Max. joint torques");
# e.g. the UR10e's shoulder_pan_joint max_velocity 2.0944 rad/s (120 deg/s), max_effort 330 N m.
UR5E = _ur_e_series(
    "ur5e",
    DH.ur(d1=0.1625, a2=-0.425, a3=-0.3922, d4=0.1333, d5=0.0997, d6=0.0996, name="ur5e"),
    reach_m=0.85,
    velocity_rad_s=(180 * _DEG,) * 6,
    effort_nm=(150.0, 150.0, 150.0, 28.0, 28.0, 28.0),
    link_masses_kg=(3.761, 8.058, 2.846, 1.37, 1.3, 0.365),
    velocity_source="UR5e technical specification / user manual v5.8: every joint 180 deg/s",
    effort_source="UR support article 'Max. joint torques': UR5e 150/150/150/28/28/28 N m",
    rated_payload_kg=5.0,
)
"""The UR5e (e-series), 850 mm reach."""

UR10E = _ur_e_series(
    "ur10e",
    DH.ur(d1=0.1807, a2=-0.6127, a3=-0.57155, d4=0.17415, d5=0.11985, d6=0.11655, name="ur10e"),
    reach_m=1.3,
    velocity_rad_s=(120 * _DEG, 120 * _DEG, 180 * _DEG, 180 * _DEG, 180 * _DEG, 180 * _DEG),
    effort_nm=(330.0, 330.0, 150.0, 56.0, 56.0, 56.0),
    link_masses_kg=(7.369, 13.051, 3.989, 2.1, 1.98, 0.615),
    velocity_source="UR10e technical specification / user manual v5.8: base, shoulder 120 deg/s; elbow, "
    "wrists 180 deg/s",
    effort_source="UR support article 'Max. joint torques': UR10e 330/330/150/56/56/56 N m",
    rated_payload_kg=12.5,
)
"""The UR10e (e-series), 1300 mm reach."""

UR16E = _ur_e_series(
    "ur16e",
    DH.ur(d1=0.1807, a2=-0.4784, a3=-0.36, d4=0.17415, d5=0.11985, d6=0.11655, name="ur16e"),
    reach_m=0.9,
    velocity_rad_s=(120 * _DEG, 120 * _DEG, 180 * _DEG, 180 * _DEG, 180 * _DEG, 180 * _DEG),
    effort_nm=(330.0, 330.0, 150.0, 56.0, 56.0, 56.0),
    link_masses_kg=(7.369, 10.45, 4.321, 2.18, 2.033, 0.907),
    velocity_source="UR16e technical specification / user manual v5.8: base, shoulder 120 deg/s; elbow, "
    "wrists 180 deg/s",
    effort_source="UR support article 'Max. joint torques': UR16e 330/330/150/56/56/56 N m",
    rated_payload_kg=16.0,
)
"""The UR16e (e-series), 900 mm reach."""

ARMS: Mapping[str, ArmSpec] = MappingProxyType({arm.name: arm for arm in (UR3E, UR5E, UR10E, UR16E)})

#: The arm a run uses when none is given (the bundled scenes are laid out for it): the one place this is said.
#: :func:`robocritics.robot.model.default_robot` loads it, :func:`robocritics.robot.model.default_workspace` is
#: its reach sphere.
DEFAULT_ARM: ArmSpec = UR3E
"""The UR e-series arms, by name: what ``Robot.ur(name)``, deploy and the loopback controller know."""

PANDA = ArmSpec(
    name="panda",
    dh=None,
    modified_dh=ModifiedDH(
        a=(0.0, 0.0, 0.0, 0.0825, -0.0825, 0.0, 0.088),
        d=(0.333, 0.0, 0.316, 0.0, 0.384, 0.0, 0.0),
        alpha=(0.0, -_HALF_PI, _HALF_PI, _HALF_PI, -_HALF_PI, _HALF_PI, _HALF_PI),
        flange_d_m=0.107,
        name="panda",
    ),
    joint_names=tuple(f"panda_joint{i}" for i in range(1, 8)),
    lower_rad=(-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973),
    upper_rad=(2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973),
    velocity_rad_s=(2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61),
    acceleration_rad_s2=(15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0),
    jerk_rad_s3=(7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0),
    effort_nm=(87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0),
    link_masses_kg=(2.74, 2.74, 2.38, 2.38, 2.74, 1.55, 0.54),
    control_period_s=0.001,
    reach_m=0.855,
    sources={
        "modified_dh": "Franka Control Interface documentation, 'Robot and interface specifications': "
        "Denavit-Hartenberg parameters (Craig's convention) of the Panda, flange d = 0.107 m",
        "lower_rad": "Franka FCI documentation, 'Limits for Panda': q_min / q_max per joint",
        "velocity_rad_s": "Franka FCI documentation, 'Limits for Panda': dq_max 2.175 (joints 1-4), 2.61 rad/s (5-7)",
        "acceleration_rad_s2": "Franka FCI documentation, 'Limits for Panda': ddq_max",
        "jerk_rad_s3": "Franka FCI documentation, 'Limits for Panda': dddq_max",
        "effort_nm": "Franka FCI documentation, 'Limits for Panda': tau_j_max 87 (joints 1-4), 12 N m (5-7)",
        "link_masses_kg": "not published per link by Franka; rough values (the arm's 18 kg spread by size)",
        "control_period_s": "Franka FCI: 1 kHz control loop",
        "reach_m": "Franka Emika Panda datasheet: reach 855 mm",
        "gripper": "Franka Hand: 0.08 m stroke (0.04 m per finger), TCP 0.1034 m from the flange, the hand turned "
        "-45 deg about the flange z",
    },
)
"""The Franka Emika Panda (7 joints) with the Franka Hand; not a UR, so not in :data:`ARMS`."""

#: Every bundled arm's name: what ``--robot NAME``, a batch row's ``"robot"`` and :meth:`Robot.bundled` take.
BUNDLED_ARM_NAMES: tuple[str, ...] = (*ARMS, PANDA.name)
