"""Write src/robocritics/robot/models/<arm>.urdf for each UR e-series arm from UR's published DH parameters,
and panda.urdf for the Franka Emika Panda from Franka's published (modified DH) parameters.

Link frames follow the DH chain: link i+1's frame is DH frame i rotated by
q_{i+1} about its z axis, so joint i+1's origin is Tz(d_i) Tx(a_i) Rx(alpha_i)
of the previous DH row, and tool0 is exactly DH frame 6 (the flange).

Collision geometry: URDF has no capsule primitive, so each <cylinder> of a
collision element is read by robocritics as the segment of a CAPSULE of the same
radius (hemispherical caps beyond both ends). Sizes follow the real arms: the
shoulder and elbow offsets (the sideways steps of the upper arm and forearm tubes)
are UR's (Universal_Robots_ROS2_Description, config/<arm>/default_kinematics and
visual meshes); housing radii are the UR3e's (0.09-0.095 m across) scaled by the
arm's joint size. Every arm carries the same Robotiq 2F-85 gripper on a short
coupling (TCP 0.15 m from the flange).

The Panda's link frames follow Franka's modified-DH chain (joint i's origin is
Rx(alpha_i) Tx(a_i) Tz(d_i), as in Franka's own description); its capsules enclose
the real links (housings 0.11-0.13 m across) and the Franka Hand (0.08 m stroke,
TCP 0.1034 m from the flange, turned -45 deg about the flange z).

Run: python tools/make_ur3e_urdf.py            (all arms)
     python tools/make_ur3e_urdf.py ur5e       (one)
"""
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
from robocritics._files import write_file_atomically  # noqa: E402  (never writes through a link at a model's name)
from robocritics.robot.arms import ARMS, PANDA  # noqa: E402  (the one source of the arms' numbers)

# Per arm: shoulder offset, elbow offset (m), housing scale vs the UR3e, base mass (kg, not published)
GEOMETRY = {
    "ur3e": (0.1198, 0.0925, 1.0, 2.0),
    "ur5e": (0.138, 0.131, 1.3, 4.0),
    "ur10e": (0.176, 0.137, 1.6, 6.0),
    "ur16e": (0.176, 0.137, 1.6, 6.0),
}
_links = ["base_link", "shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link", "wrist_3_link"]


def _size(ur3e_value: float, scale: float) -> float:
    """A UR3e length scaled to another arm's joint size (mm precision, so the UR3e's stay exact)."""
    return ur3e_value if scale == 1.0 else round(ur3e_value * scale, 3)


MAX_OPENING, FINGER_R, TCP_Z = 0.085, 0.009, 0.15
finger_y = MAX_OPENING / 2 + FINGER_R  # finger axis at full opening, inner face at opening/2
finger_seg = ((0, 0, 0.0), (0, 0, 0.04))  # in the finger frame, which sits at z = 0.101
FINGER_Z = TCP_Z - FINGER_R - 0.04


def fmt(v):
    return " ".join(f"{x:.17g}" for x in v)


def capsule_xml(p0, p1, r):
    import numpy as np

    p0, p1 = np.array(p0, float), np.array(p1, float)
    mid, d = (p0 + p1) / 2, p1 - p0
    length = float(np.linalg.norm(d))
    u = d / length
    # rpy rotating z onto u
    pitch = math.atan2(math.hypot(u[0], u[1]), u[2])
    yaw = math.atan2(u[1], u[0])
    return (
        f'    <collision>\n      <origin xyz="{fmt(mid)}" rpy="0 {pitch:.17g} {yaw:.17g}"/>\n'
        f'      <geometry><cylinder radius="{r}" length="{length:.17g}"/></geometry>\n    </collision>\n'
    )


def inertial(mass, p0, p1, r):
    mid = [(a + b) / 2 for a, b in zip(p0, p1)]
    i = mass * (3 * r * r) / 12 + 1e-4
    return (
        f'    <inertial>\n      <origin xyz="{fmt(mid)}" rpy="0 0 0"/>\n      <mass value="{mass}"/>\n'
        f'      <inertia ixx="{i:.6g}" ixy="0" ixz="0" iyy="{i:.6g}" iyz="0" izz="{i:.6g}"/>\n    </inertial>\n'
    )


def urdf_text(arm: str) -> str:
    """The URDF of ``arm`` (a name in robocritics.robot.arms.ARMS)."""
    spec = ARMS[arm]
    dh = spec.dh
    d1, d4, d5, d6 = (dh.d[i] for i in (0, 3, 4, 5))
    a2, a3 = dh.a[1], dh.a[2]
    masses = list(spec.link_masses_kg)
    SHOULDER_OFFSET, ELBOW_OFFSET, k, base_mass = GEOMETRY[arm]
    # joint i + 1 sits at the fixed part Tz(d_i) Tx(a_i) Rx(alpha_i) of DH row i: URDF origin
    # xyz (a_i, 0, d_i), rpy (alpha_i, 0, 0); before joint 1 there is no row (the identity)
    _rows = [(0.0, 0.0, 0.0)] + list(zip(dh.a, dh.d, dh.alpha))
    # (parent, child, origin xyz, origin rpy) per joint; limits, speeds and torques from the spec
    _chain = [(_links[i], _links[i + 1], (a, 0, d), (alpha, 0, 0)) for i, (a, d, alpha) in enumerate(_rows[:6])]
    # (name, parent, child, origin xyz, origin rpy, lower, upper, velocity rad/s, effort N m)
    joints = [
        (name, parent, child, xyz, rpy, lo, hi, vel, eff)
        for name, (parent, child, xyz, rpy), lo, hi, vel, eff in zip(
            spec.joint_names, _chain, spec.lower_rad, spec.upper_rad, spec.velocity_rad_s, spec.effort_nm
        )
    ]
    # capsule segments (p0, p1) in the link frame and radius, m
    capsules = {
        "base_link": ((0, 0, 0.0), (0, 0, _size(0.045, k)), _size(0.064, k)),
        "shoulder_link": ((0, 0, _size(0.075, k)), (0, 0, d1), _size(0.046, k)),
        "upper_arm_link": ((0, 0, SHOULDER_OFFSET), (a2, 0, SHOULDER_OFFSET), _size(0.044, k)),
        "forearm_link": ((0, 0, SHOULDER_OFFSET - ELBOW_OFFSET), (a3, 0, SHOULDER_OFFSET - ELBOW_OFFSET), _size(0.036, k)),
        "wrist_1_link": ((0, 0, _size(0.045, k)), (0, 0, d4 - _size(0.01, k)), _size(0.032, k)),
        "wrist_2_link": ((0, 0, 0.0), (0, 0, d5 - _size(0.025, k)), _size(0.032, k)),
        "wrist_3_link": ((0, 0, 0.0), (0, 0, d6 - _size(0.035, k)), _size(0.032, k)),
        "gripper_body": ((0, 0, 0.02), (0, 0, 0.055), 0.040),
    }
    out = ['<?xml version="1.0"?>\n',
           f"<!-- {spec.name[:-1].upper()}e (e-series DH) with a Robotiq 2F-85-sized gripper; written by robocritics' tools/make_ur3e_urdf.py.\n"
           "     Collision <cylinder>s are capsule segments (hemispherical caps), see robocritics.robot.model.\n"
           "     The finger direction is the +z axis of the tcp frame; the fingers close along its y axis. -->\n",
           f'<robot name="{spec.name}">\n']
    link_mass = dict(zip(["shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link", "wrist_3_link"], masses))
    link_mass.update({"base_link": base_mass, "gripper_body": 0.9})
    for name in ["base_link", "shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link", "wrist_3_link", "gripper_body"]:
        p0, p1, r = capsules[name]
        out.append(f'  <link name="{name}">\n' + inertial(link_mass[name], p0, p1, r) + capsule_xml(p0, p1, r) + "  </link>\n")
    for side, sign in (("left_finger", 1), ("right_finger", -1)):
        out.append(f'  <link name="{side}">\n' + inertial(0.05, *finger_seg, FINGER_R) + capsule_xml(*finger_seg, FINGER_R) + "  </link>\n")
    out.append('  <link name="tool0"/>\n  <link name="tcp"/>\n')
    for name, parent, child, xyz, rpy, lo, hi, vel, eff in joints:
        out.append(
            f'  <joint name="{name}" type="revolute">\n    <parent link="{parent}"/>\n    <child link="{child}"/>\n'
            f'    <origin xyz="{fmt(xyz)}" rpy="{fmt(rpy)}"/>\n    <axis xyz="0 0 1"/>\n'
            f'    <limit lower="{lo:.17g}" upper="{hi:.17g}" velocity="{vel:.17g}" effort="{eff:g}"/>\n  </joint>\n'
        )
    a6, _, alpha6 = _rows[6]  # the flange: DH row 6's fixed part (tool0 is DH frame 6)
    fixed = [
        ("flange_joint", "wrist_3_link", "tool0", (a6, 0, d6), (alpha6, 0, 0)),
        ("gripper_mount_joint", "tool0", "gripper_body", (0, 0, 0), (0, 0, 0)),
        ("left_finger_joint", "gripper_body", "left_finger", (0, finger_y, FINGER_Z), (0, 0, 0)),
        ("right_finger_joint", "gripper_body", "right_finger", (0, -finger_y, FINGER_Z), (0, 0, 0)),
        ("tcp_joint", "gripper_body", "tcp", (0, 0, TCP_Z), (0, 0, 0)),
    ]
    for name, parent, child, xyz, rpy in fixed:
        out.append(
            f'  <joint name="{name}" type="fixed">\n    <parent link="{parent}"/>\n    <child link="{child}"/>\n'
            f'    <origin xyz="{fmt(xyz)}" rpy="{fmt(rpy)}"/>\n  </joint>\n'
        )
    out.append(
        f'  <!-- robocritics gripper: fingers at full opening {MAX_OPENING} m; they move along tcp y. -->\n'
        f'  <gripper name="robotiq_2f85" max_opening="{MAX_OPENING}" finger_axis="0 0 1" closing_axis="0 1 0" '
        f'tcp="tcp" fingers="left_finger right_finger"/>\n'
    )
    out.append("</robot>\n")
    return "".join(out)


# Panda capsules (p0, p1, radius) in each link frame, m; link0 is the base
PANDA_CAPSULES = {
    "link0": ((0, 0, 0.03), (0, 0, 0.14), 0.08),
    "link1": ((0, 0, -0.19), (0, 0, -0.06), 0.065),
    "link2": ((0, 0, -0.05), (0, -0.12, 0.0), 0.065),
    "link3": ((0, 0, -0.22), (0, 0, -0.09), 0.06),
    "link4": ((0, 0, -0.05), (-0.0825, 0.12, 0.0), 0.065),
    "link5": ((0, 0, -0.25), (0, 0.06, -0.11), 0.055),
    "link6": ((0, 0, -0.03), (0.088, 0, 0.0), 0.05),
    "link7": ((0, 0, -0.02), (0, 0, 0.08), 0.045),
    "gripper_body": ((0, -0.07, 0.035), (0, 0.07, 0.035), 0.03),  # the hand, across the fingers' stroke
}
PANDA_BASE_MASS, PANDA_HAND_MASS, PANDA_FINGER_MASS = 3.0, 0.73, 0.015
HAND_OPENING, HAND_TCP_Z, HAND_YAW = 0.08, 0.1034, -math.pi / 4


def panda_urdf_text() -> str:
    """The Panda's URDF (Franka Hand, TCP at the fingertip centre)."""
    mdh = PANDA.modified_dh
    links = [f"link{i}" for i in range(8)]
    out = ['<?xml version="1.0"?>\n',
           "<!-- Franka Emika Panda (Franka's modified DH) with the Franka Hand; written by robocritics'\n"
           "     tools/make_ur3e_urdf.py. Collision <cylinder>s are capsule segments, see robocritics.robot.model.\n"
           "     The finger direction is the +z axis of the tcp frame; the fingers close along its y axis. -->\n",
           '<robot name="panda">\n']
    for i, name in enumerate(links):
        p0, p1, r = PANDA_CAPSULES[name]
        mass = PANDA.link_masses_kg[i - 1] if i else PANDA_BASE_MASS
        out.append(f'  <link name="{name}">\n' + inertial(mass, p0, p1, r) + capsule_xml(p0, p1, r) + "  </link>\n")
    p0, p1, r = PANDA_CAPSULES["gripper_body"]
    out.append('  <link name="link8"/>\n  <link name="tool0"/>\n')
    out.append('  <link name="gripper_body">\n' + inertial(PANDA_HAND_MASS, p0, p1, r) + capsule_xml(p0, p1, r) + "  </link>\n")
    finger_y = HAND_OPENING / 2 + FINGER_R
    finger_z = HAND_TCP_Z - FINGER_R - 0.04
    for side in ("left_finger", "right_finger"):
        out.append(f'  <link name="{side}">\n' + inertial(PANDA_FINGER_MASS, *finger_seg, FINGER_R)
                   + capsule_xml(*finger_seg, FINGER_R) + "  </link>\n")
    out.append('  <link name="tcp"/>\n')
    for i, (a, d, alpha) in enumerate(zip(mdh.a, mdh.d, mdh.alpha)):
        # Rx(alpha) Tx(a) Tz(d): the z step is taken in the twisted frame
        xyz = (a, -d * math.sin(alpha), d * math.cos(alpha))
        out.append(
            f'  <joint name="{PANDA.joint_names[i]}" type="revolute">\n    <parent link="{links[i]}"/>\n'
            f'    <child link="{links[i + 1]}"/>\n    <origin xyz="{fmt(xyz)}" rpy="{fmt((alpha, 0, 0))}"/>\n'
            f'    <axis xyz="0 0 1"/>\n    <limit lower="{PANDA.lower_rad[i]:.17g}" upper="{PANDA.upper_rad[i]:.17g}" '
            f'velocity="{PANDA.velocity_rad_s[i]:.17g}" effort="{PANDA.effort_nm[i]:g}"/>\n  </joint>\n'
        )
    fixed = [
        ("flange_joint", "link7", "link8", (0, 0, mdh.flange_d_m), (0, 0, 0)),
        ("tool0_joint", "link8", "tool0", (0, 0, 0), (0, 0, HAND_YAW)),
        ("hand_joint", "tool0", "gripper_body", (0, 0, 0), (0, 0, 0)),
        ("left_finger_joint", "gripper_body", "left_finger", (0, finger_y, finger_z), (0, 0, 0)),
        ("right_finger_joint", "gripper_body", "right_finger", (0, -finger_y, finger_z), (0, 0, 0)),
        ("tcp_joint", "gripper_body", "tcp", (0, 0, HAND_TCP_Z), (0, 0, 0)),
    ]
    for name, parent, child, xyz, rpy in fixed:
        out.append(
            f'  <joint name="{name}" type="fixed">\n    <parent link="{parent}"/>\n    <child link="{child}"/>\n'
            f'    <origin xyz="{fmt(xyz)}" rpy="{fmt(rpy)}"/>\n  </joint>\n'
        )
    out.append(
        f'  <gripper name="franka_hand" max_opening="{HAND_OPENING}" finger_axis="0 0 1" closing_axis="0 1 0" '
        'tcp="tcp" fingers="left_finger right_finger"/>\n</robot>\n'
    )
    return "".join(out)


def main(argv: list[str]) -> None:
    models = Path(__file__).resolve().parents[1] / "src/robocritics/robot/models"
    for arm in argv or [*GEOMETRY, "panda"]:
        write_file_atomically(models / f"{arm}.urdf", panda_urdf_text() if arm == "panda" else urdf_text(arm), "model")


if __name__ == "__main__":
    main(sys.argv[1:])
