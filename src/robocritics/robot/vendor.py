"""A vendor URDF, as shipped, turned into the arm robocritics plans with (see :meth:`Robot.from_urdf`).

:func:`arm_tree` reads the file (:mod:`.urdf`: bounded, every number checked), keeps the serial chain from the
root to the tip (and the fixed parts hanging off it), replaces each link's collision geometry by capsules
(its cylinders and spheres as they are, its meshes and boxes by fitted capsules, :mod:`.fit`), mounts the
base where ``base_pose`` says in the world and the tool on the tip. The result is a URDF tree in
robocritics' own contract (capsule cylinders, a ``tcp`` link, a ``<gripper>`` element), which the
:class:`~robocritics.robot.model.Robot` constructor reads like a bundled file.

:func:`infer` then settles what the file does not say: the links whose height never changes (they stand on the
table by construction), the reach (the farthest the flange gets from the shoulder over sampled
configurations, the way makers publish reach), and a home pose inside the limits and free of collision.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..errors import RobotModelError
from . import urdf as _urdf
from .fit import FittedCapsule, Mesh, box_mesh, fit_capsules, load_mesh
from .approach import infer_tilts, turn_rates
from .tools import Tool, tool_named, _cylinder

__all__ = ["arm_tree", "infer", "base_pose_matrix", "REACH_SAMPLES"]

#: Configurations sampled to find the reach and a home pose (seeded, so every load gives the same).
REACH_SAMPLES = 4096


def base_pose_matrix(base_pose) -> np.ndarray:
    """``base_pose`` as a 4x4 transform: a 4x4 matrix, or ``(x, y, z)`` m, or ``(x, y, z, roll, pitch, yaw)``
    m and rad (URDF's fixed-axis roll-pitch-yaw)."""
    import pinocchio as pin

    try:
        values = np.array(base_pose, dtype=float)
    except (TypeError, ValueError):
        raise RobotModelError(f"base_pose must be a 4x4 transform or (x, y, z[, roll, pitch, yaw]), got {base_pose!r}") from None
    if not np.isfinite(values).all():
        raise RobotModelError(f"base_pose must be finite, got {values.tolist()}")
    pose = np.eye(4)
    if values.shape == (4, 4):
        R = values[:3, :3]
        if not (np.allclose(R.T @ R, np.eye(3), atol=1e-6) and np.linalg.det(R) > 0 and np.allclose(values[3], (0, 0, 0, 1))):
            raise RobotModelError("base_pose: the 4x4 matrix is not a rigid transform (rotation and translation)")
        pose[:] = values
    elif values.shape in ((3,), (6,)):
        pose[:3, 3] = values[:3]
        if values.shape == (6,):
            pose[:3, :3] = pin.rpy.rpyToMatrix(*values[3:])
    else:
        raise RobotModelError(f"base_pose must be a 4x4 transform or (x, y, z[, roll, pitch, yaw]), got shape {values.shape}")
    if np.abs(pose[:3, 3]).max() > 100.0:
        raise RobotModelError(f"base_pose puts the base {np.abs(pose[:3, 3]).max():.1f} m away; at most 100 m")
    return pose


def arm_tree(
    path: Path,
    *,
    tool: str | Path | Tool | None,
    tip: str | None,
    base_pose,
    joint_limits: dict | None,
    package_paths: tuple[Path, ...] = (),
    name: str | None = None,
    tcp_frame: str = "tcp",
) -> tuple[ET.Element, dict]:
    """The contract URDF tree of the vendor file at ``path`` and facts about it: ``tip``, ``tool``, and the
    fitted geometry of :func:`_capsule_link` (``slack_m`` and ``mesh`` by capsule name, ``link_mesh`` by link). Raises :class:`RobotModelError` naming element, link or joint and line."""
    doc = _urdf.read_urdf(path)
    _override_limits(doc, joint_limits or {})
    _urdf.check_numbers(doc)
    tree = _urdf.kinematic_tree(doc)
    # a file in robocritics' own contract (a <gripper> element, or its own TCP link) keeps its tool
    contract = tool is None and (doc.root.find("gripper") is not None or tcp_frame in tree.links)
    joints, tip = _urdf.chain(tree, tip)
    keep = [tree.root] + [j.find("child").get("link") for j in joints]
    kept_joints = list(joints)
    # fixed parts hanging off the chain (covers, sensors, a contract file's gripper) come along unless they move
    todo = list(keep)
    while todo:
        link = todo.pop()
        for joint in tree.children.get(link, ()):
            child = joint.find("child").get("link")
            if child in keep or joint in kept_joints:
                continue
            if link == tip and not contract:
                continue  # the tool replaces whatever the vendor hung on the flange
            if joint.get("type") == "fixed" and not tree.subtree_moves(child):
                keep.append(child)
                kept_joints.append(joint)
                todo.append(child)
    out = ET.Element("robot", name=name or doc.root.get("name") or path.stem)
    fitted: dict[str, dict] = {"slack_m": {}, "mesh": {}, "link_mesh": {}}
    root_name = tree.root
    if base_pose is not None:
        import pinocchio as pin

        pose = base_pose_matrix(base_pose)
        if "world" in tree.links:
            raise RobotModelError(f"{path}: base_pose= mounts the arm on a 'world' link, and the file has its own")
        out.append(ET.Element("link", name="world"))
        mount = ET.SubElement(out, "joint", name="base_mount", type="fixed")
        ET.SubElement(mount, "parent", link="world")
        ET.SubElement(mount, "child", link=root_name)
        ET.SubElement(mount, "origin", xyz=" ".join(repr(float(v)) for v in pose[:3, 3]),
                      rpy=" ".join(repr(float(v)) for v in pin.rpy.matrixToRpy(pose[:3, :3])))
    for link_name in keep:
        out.append(_capsule_link(doc, tree.links[link_name], package_paths, fitted))
    for joint in kept_joints:
        out.append(_clean_joint(joint))
    if contract:
        if doc.root.find("gripper") is not None:
            out.append(doc.root.find("gripper"))
        return out, {"tip": tip, "tool": "(the file's own)", **fitted}
    tool_obj = _tool(tool, path, package_paths, fitted)
    mount_rpy = flange_mount_rpy(doc, joints)
    if isinstance(tool_obj, Tool):
        out.extend(tool_obj.elements(tip, mount_rpy))
        tool_name = tool_obj.name
    else:  # a tool URDF: its tree mounted on the tip
        tool_tree, tool_name = tool_obj
        taken = {e.get("name") for e in out if e.tag in ("link", "joint")}
        for element in tool_tree:
            if element.tag == "joint" and element.get("name") == "tool_mount":
                element.find("parent").set("link", tip)
                if mount_rpy is not None:
                    element.find("origin").set("rpy", " ".join(repr(float(v)) for v in mount_rpy))
            if element.tag in ("link", "joint") and element.get("name") in taken:
                raise RobotModelError(f"tool {tool_name}: its {element.tag} {element.get('name')!r} has the name of one of the arm's")
            out.append(element)
    return out, {"tip": tip, "tool": tool_name, **fitted}


#: The tool mount's rpy (rad) that turns its z onto each of the flange's axes but +z (``Rx``/``Ry`` by +-pi/2, pi).
_MOUNT_RPY = {(1, 0, 0): (0.0, math.pi / 2, 0.0), (-1, 0, 0): (0.0, -math.pi / 2, 0.0),
              (0, 1, 0): (-math.pi / 2, 0.0, 0.0), (0, -1, 0): (math.pi / 2, 0.0, 0.0), (0, 0, -1): (math.pi, 0.0, 0.0)}


def flange_mount_rpy(doc: _urdf.UrdfDocument, joints: list[ET.Element]) -> tuple[float, float, float] | None:
    """How a tool turns to stand out of the flange, as the tool mount's rpy (rad), or None when the flange's
    outward axis is its z (ROS-Industrial's ``tool0``, and most vendor flanges).

    The outward direction, in the tip frame: the last moving joint's axis, signed to point from that joint to
    the tip, when the fixed joints between them offset the tip along it (a wrist roll, as Unitree's Z1 rolls
    about x); the offset's direction when it is not along the axis. A tip at the last joint itself (no fixed
    offset) is signed by the offset from the joint before, whose axis passes through the last joint's parent
    frame: the SO-100's wrist roll sits 6 cm out along its -y from the wrist flex, so its tool faces -y, not
    back through the wrist. The axis as it is when neither offset says; then snapped to the nearest of the tip
    frame's six axis directions."""
    import pinocchio as pin

    moving = [k for k, j in enumerate(joints) if j.get("type") in _urdf.MOVING_JOINT_TYPES]
    last = moving[-1]
    axis_element = joints[last].find("axis")
    axis = np.array(_urdf.floats(doc, axis_element, "xyz", 3, f"joint {joints[last].get('name')!r}", default=(1, 0, 0))
                    if axis_element is not None else (1.0, 0.0, 0.0), dtype=float)
    steps = []  # the pose of each joint's frame in its parent's, from the last moving joint on
    for joint in joints[last:]:
        origin = joint.find("origin")
        step = np.eye(4)
        if origin is not None:
            owner = f"joint {joint.get('name')!r}"
            step[:3, :3] = pin.rpy.rpyToMatrix(*_urdf.floats(doc, origin, "rpy", 3, owner, default=(0, 0, 0), bound=100.0))
            step[:3, 3] = _urdf.floats(doc, origin, "xyz", 3, owner, default=(0, 0, 0))
        steps.append(step)
    pose = np.eye(4)  # the tip in the last moving joint's frame
    for step in steps[1:]:
        pose = pose @ step
    R = pose[:3, :3]
    axis_t, offset_t = R.T @ (axis / np.linalg.norm(axis)), R.T @ pose[:3, 3]
    if np.linalg.norm(offset_t) >= 1e-3:
        unit = offset_t / np.linalg.norm(offset_t)
        out = axis_t * math.copysign(1.0, axis_t @ unit) if abs(axis_t @ unit) >= 0.5 else unit
    else:  # the tip at the last joint: the axis, signed by the last joint's offset from its parent frame
        before = (steps[0][:3, :3] @ R).T @ (steps[0] @ pose)[:3, 3]
        along = float(axis_t @ before)
        out = axis_t * math.copysign(1.0, along) if abs(along) >= 0.5 * np.linalg.norm(before) > 0 else axis_t
    k = int(np.argmax(np.abs(out)))
    snapped = [0, 0, 0]
    snapped[k] = 1 if out[k] > 0 else -1
    return _MOUNT_RPY.get(tuple(snapped))


def _tool(tool, path: Path, package_paths, fitted: dict) -> Tool | tuple[list[ET.Element], str]:
    """A bundled tool, or a tool URDF's elements (its fitted geometry added to ``fitted``) and its name."""
    if tool is None:
        return tool_named("none")
    if isinstance(tool, Tool):
        return tool
    text = str(tool)
    if not text.lower().endswith(".urdf"):
        return tool_named(text)
    tool_path = Path(text)
    doc = _urdf.read_urdf(tool_path)
    _urdf.check_numbers(doc)
    tree = _urdf.kinematic_tree(doc)
    if any(j.get("type") != "fixed" for j in tree.joints.values()):
        moving = next(j for j in tree.joints.values() if j.get("type") != "fixed")
        raise doc.error(moving, f"tool joint {moving.get('name')!r} is {moving.get('type')}; a tool's joints are fixed "
                                "(the fingers' opening is the <gripper> element's)")
    if "tcp" not in tree.links:
        raise doc.error(doc.root, "a tool needs a link named 'tcp' (+z the finger direction, fingers closing along y)")
    gripper = doc.root.find("gripper")
    elements: list[ET.Element] = []
    for link in tree.links.values():
        elements.append(_capsule_link(doc, link, package_paths, fitted))
    for joint in tree.joints.values():
        elements.append(_clean_joint(joint))
    mount = ET.Element("joint", name="tool_mount", type="fixed")
    ET.SubElement(mount, "parent", link="__TIP__")
    ET.SubElement(mount, "child", link=tree.root)
    ET.SubElement(mount, "origin", xyz="0 0 0", rpy="0 0 0")
    elements.append(mount)
    links = " ".join(tree.links)
    if gripper is None:
        elements.append(ET.Element("gripper", name=tool_path.stem, max_opening="0", tcp="tcp", fingers="", links=links))
    else:
        fingers = gripper.get("fingers", "").split()
        for finger in fingers:
            if finger not in tree.links:
                raise doc.error(gripper, f"<gripper fingers=...> names {finger!r}, not a link of the tool")
        if len(fingers) not in (0, 2):
            raise doc.error(gripper, "<gripper fingers=...> names two finger links (or none)")
        opening = _urdf.floats(doc, gripper, "max_opening", 1, "the tool's <gripper>", default=(0.0,), bound=1.0)[0]
        if opening < 0:
            raise doc.error(gripper, "<gripper max_opening> must not be negative")
        elements.append(ET.Element("gripper", name=gripper.get("name", tool_path.stem), max_opening=repr(opening),
                                   tcp="tcp", fingers=" ".join(fingers), links=links))
    return elements, tool_path.stem


def _override_limits(doc: _urdf.UrdfDocument, joint_limits: dict) -> None:
    """Write ``joint_limits`` (``{joint: (lower, upper)}`` rad or m, or ``(lower, upper, velocity)`` with the speed
    limit in rad/s or m/s) into the file's ``<limit>`` elements before they are checked: a file that ships a
    zero speed limit (rtb-data's Puma560) loads with the speeds given here."""
    moving = {j.get("name"): j for j in doc.root.findall("joint") if j.get("type") in _urdf.MOVING_JOINT_TYPES}
    for name, values in joint_limits.items():
        if name not in moving:
            raise RobotModelError(f"joint_limits names {name!r}, not a moving joint of {doc.path.name} "
                                  f"({', '.join(list(moving)[:20])})")
        try:
            numbers = [float(v) for v in values]
        except (TypeError, ValueError):
            numbers = []
        if len(numbers) not in (2, 3) or not all(math.isfinite(v) for v in numbers) or numbers[0] > numbers[1] \
                or max(abs(numbers[0]), abs(numbers[1])) > 100 or (len(numbers) == 3 and not 0 < numbers[2] <= 1e6):
            raise RobotModelError(f"joint_limits[{name!r}] = {values!r}: give (lower, upper) rad or m, lower <= upper, "
                                  "at most 100 in size, or (lower, upper, velocity) with a positive speed limit")
        joint = moving[name]
        limit = joint.find("limit")
        if limit is None:
            limit = ET.SubElement(joint, "limit", effort="0")
        limit.set("lower", repr(numbers[0]))
        limit.set("upper", repr(numbers[1]))
        if len(numbers) == 3:
            limit.set("velocity", repr(numbers[2]))
        if joint.get("type") == "continuous":
            joint.set("type", "revolute")


def _clean_joint(joint: ET.Element) -> ET.Element:
    """The joint with only what Pinocchio and robocritics read (no transmissions, no foreign attributes)."""
    out = ET.Element("joint", name=joint.get("name"), type=joint.get("type"))
    for tag in ("parent", "child"):
        ET.SubElement(out, tag, link=joint.find(tag).get("link"))
    origin = joint.find("origin")
    if origin is not None:
        ET.SubElement(out, "origin", xyz=origin.get("xyz", "0 0 0"), rpy=origin.get("rpy", "0 0 0"))
    axis = joint.find("axis")
    if axis is not None:
        ET.SubElement(out, "axis", xyz=axis.get("xyz", "1 0 0"))
    limit = joint.find("limit")
    if limit is not None:
        attrs = {k: limit.get(k) for k in ("lower", "upper", "velocity", "effort") if limit.get(k) is not None}
        attrs.setdefault("effort", "0")
        ET.SubElement(out, "limit", **attrs)
    return out


def _capsule_link(doc: _urdf.UrdfDocument, link: ET.Element, package_paths, fitted: dict) -> ET.Element:
    """The link with its collision geometry as capsules: cylinders, capsules and spheres as they are, meshes
    and boxes (all of them together, in the link frame) enclosed by fitted capsules. Into ``fitted``: each
    fitted capsule's ``slack_m`` and ``mesh`` (the piece it encloses) by capsule name, and the link's whole
    ``link_mesh`` (link frame) by link name."""
    import pinocchio as pin

    name = link.get("name")
    owner = f"link {name!r}"
    out = ET.Element("link", name=name)
    meshes: list[Mesh] = []
    for collision in link.findall("collision"):
        origin = collision.find("origin")
        xyz = _urdf.floats(doc, origin, "xyz", 3, owner, default=(0, 0, 0)) if origin is not None else (0, 0, 0)
        rpy = _urdf.floats(doc, origin, "rpy", 3, owner, default=(0, 0, 0), bound=100.0) if origin is not None else (0, 0, 0)
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = pin.rpy.rpyToMatrix(*rpy), xyz
        shape = collision.find("geometry")[0]
        if shape.tag in ("cylinder", "capsule", "sphere"):
            clean = ET.SubElement(out, "collision")
            ET.SubElement(clean, "origin", xyz=" ".join(map(repr, map(float, xyz))), rpy=" ".join(map(repr, map(float, rpy))))
            geometry = ET.SubElement(clean, "geometry")
            attrs = {"radius": shape.get("radius")}
            if shape.tag != "sphere":
                attrs["length"] = shape.get("length")
            ET.SubElement(geometry, "sphere" if shape.tag == "sphere" else "cylinder", **attrs)
        elif shape.tag == "box":
            meshes.append(box_mesh(_urdf.floats(doc, shape, "size", 3, owner)).transformed(pose))
        else:
            file = _urdf.resolve_mesh(doc, shape, owner, package_paths)
            scale = _urdf.floats(doc, shape, "scale", 3, owner, default=(1.0, 1.0, 1.0))
            try:
                meshes.append(_cached_mesh(file, scale).transformed(pose))
            except RobotModelError as exc:
                raise doc.error(shape, f"<mesh> of {owner}: {exc}") from None
    if meshes:
        whole = fitted["link_mesh"][name] = Mesh.union(meshes)
        capsules: list[FittedCapsule] = fit_capsules(whole)
        k = len(out.findall("collision"))
        for i, capsule in enumerate(capsules):
            out.append(_cylinder(capsule.p0, capsule.p1, capsule.radius_m))
            fitted["slack_m"][f"{name}#{k + i}" if k + i else name] = capsule.slack_m
            fitted["mesh"][f"{name}#{k + i}" if k + i else name] = capsule.mesh
    return out


_MESHES: dict[tuple, Mesh] = {}


def _cached_mesh(file: Path, scale) -> Mesh:
    """:func:`load_mesh`, once per file, size, modification time and scale in a process."""
    stat = file.stat()
    key = (str(file.resolve()), stat.st_size, stat.st_mtime_ns, tuple(scale))
    mesh = _MESHES.get(key)
    if mesh is None:
        if len(_MESHES) > 256:
            _MESHES.clear()
        mesh = _MESHES[key] = load_mesh(file, scale)
    return mesh


# --- what the file does not say ---------------------------------------------------------------------------


def height_invariant_links(robot) -> tuple[str, ...]:
    """Links whose height never changes: every moving joint above them turns about the world's vertical (and
    all joints above those do too). Their distance to the table is constant, so it is not reported."""
    import pinocchio as pin

    model = robot.model
    data = model.createData()
    pin.forwardKinematics(model, data, np.clip(np.zeros(model.nq), robot.lower, robot.upper))
    invariant = [True] * model.njoints
    for j in range(1, model.njoints):
        kind, axis = robot._joint_motion[j]
        world_axis = data.oMi[j].rotation @ (axis / np.linalg.norm(axis))
        invariant[j] = invariant[model.parents[j]] and kind == "revolute" and abs(abs(world_axis[2]) - 1.0) < 1e-9
    return tuple(f.name for f in model.frames if f.type == pin.FrameType.BODY and invariant[f.parentJoint]
                 and f.name != "universe")


def _axis_housings(robot) -> np.ndarray:
    """Per capsule, whether it is the housing of a joint whose axis is horizontal and never changes height (a UR
    shoulder): on that joint's child link, both ends within half its radius of the axis. Its lowest point moves
    by no more than that offset as the joint turns, and its table distance is the vendor's design, not the
    program's (as a fixed link's is)."""
    import pinocchio as pin

    model = robot.model
    data = model.createData()
    pin.forwardKinematics(model, data, np.asarray(robot.lower + robot.upper, float) / 2)
    invariant = set(height_invariant_links(robot))
    parent_joint = {f.name: f.parentJoint for f in model.frames if f.type == pin.FrameType.BODY}
    out = np.zeros(len(robot.capsules), dtype=bool)
    for k, capsule in enumerate(robot.capsules):
        j = parent_joint[capsule.frame]
        kind, axis = robot._joint_motion[j] if j > 0 else ("fixed", None)
        parent = next((f.name for f in model.frames if f.type == pin.FrameType.BODY and f.parentJoint == model.parents[j]), None)
        if kind != "revolute" or parent not in invariant:
            continue
        unit = np.asarray(axis, float) / np.linalg.norm(axis)
        if abs((data.oMi[j].rotation @ unit)[2]) > 1e-6:
            continue
        frame = model.frames[model.getFrameId(capsule.frame, pin.FrameType.BODY)]
        ends = [frame.placement.act(np.asarray(p, float)) for p in (capsule.p0, capsule.p1)]  # in the joint frame
        off_axis = [np.linalg.norm(e - (e @ unit) * unit) for e in ends]
        out[k] = max(off_axis) <= 0.5 * capsule.radius_m
    return out


def infer(robot, *, tip: str, reach_m: float | None, home_q, fixed_links, approach_tilts_rad=None) -> None:
    """Set ``robot``'s fixed links, reach, home and approach tilts (each unless given), its pinch pairs at the
    home pose, and how its base and wrist turn (:func:`~robocritics.robot.approach.turn_rates`)."""
    from ..geometry.kernels import capsule_capsule

    robot.fixed_links = tuple(fixed_links) if fixed_links is not None else height_invariant_links(robot)
    rng = np.random.default_rng(0)
    samples = rng.uniform(robot.lower, robot.upper, size=(REACH_SAMPLES, robot.n))
    frames, p0, p1 = robot.forward_with_capsules(samples)
    tip_index = robot.frame_names.index(tip)
    flange = frames[:, tip_index, :3, 3]
    if reach_m is None:
        reach_m = float(np.linalg.norm(flange - robot.shoulder_m, axis=1).max())
        if not reach_m > 0:
            raise RobotModelError(f"{robot.urdf_path}: the flange {tip!r} does not move away from the shoulder")
    robot.reach_m = float(reach_m)
    # a capsule whose lowest point keeps its height (a housing centred on a horizontal shoulder axis) stands
    # where the file put it: its table distance is as constant as a fixed link's
    lowest = np.minimum(p0[..., 2], p1[..., 2]) - robot.capsule_radii
    housings = _axis_housings(robot)
    steady = (np.ptp(lowest, axis=0) < 1e-3) | housings
    robot.table_fixed_capsules = tuple(name for name, still in zip(robot.capsule_names, steady) if still)
    structural = _structural_pairs(robot, p0, p1, capsule_capsule)
    if home_q is None:
        home_q = _home(robot, samples, frames, p0, p1, capsule_capsule, structural)
    robot.home_q = home_q
    robot.base_turn_sign, robot.wrist_yaw_per_rad = turn_rates(robot, robot.home_q)
    robot.approach_tilts_rad = _tilts(approach_tilts_rad) if approach_tilts_rad is not None else infer_tilts(robot)
    # a joint's housing that stands where the file put it (_axis_housings) against the links below it: the vendor's
    # design, whatever the program does, so no pinch point
    standing = {c.name for c, housing in zip(robot.capsules, housings) if housing or c.frame in robot.fixed_links}
    robot.self_pairs = tuple(pair for pair in robot._default_self_pairs(robot.home_q)
                             if pair not in structural and not set(pair) <= standing)


def _tilts(values) -> tuple[float, ...]:
    """``approach_tilts_rad=`` checked: one tilt or a sequence of them, each in [0, pi/2] rad."""
    try:
        tilts = tuple(float(v) for v in (values if np.ndim(values) else (values,)))
    except (TypeError, ValueError):
        tilts = ()
    if not tilts or not all(0.0 <= t <= math.pi / 2 for t in tilts):
        raise RobotModelError(f"approach_tilts_rad = {values!r}: give one or more tilts from straight down, each "
                              "in [0, pi/2] rad (0: fingers down, pi/2: horizontal)")
    return tilts


def _structural_pairs(robot, p0, p1, capsule_capsule) -> set[tuple[str, str]]:
    """Capsule pairs of non-adjacent links that touch in at least half the sampled configurations: parts of one
    housing (a fitted capsule around a joint's housing reaches into the next link but one), not pinch points."""
    names = robot.capsule_names
    out = set()
    for a, b in robot._default_self_pairs(None) + _close_pairs(robot):
        i, j = names.index(a), names.index(b)
        d = capsule_capsule(p0[:, i], p1[:, i], robot.capsule_radii[i], p0[:, j], p1[:, j], robot.capsule_radii[j])
        if np.mean(d <= 0.0) >= 0.5:
            out.add((a, b))
    return out


def _close_pairs(robot) -> tuple[tuple[str, str], ...]:
    """Every capsule pair the default filter may drop at q = 0 but that the home pose might keep."""
    import pinocchio as pin

    parent_of = {f.name: f.parentJoint for f in robot.model.frames if f.type == pin.FrameType.BODY}
    out = []
    caps = robot.capsules
    for i in range(len(caps)):
        for j in range(i + 1, len(caps)):
            if caps[i].group == "gripper" and caps[j].group == "gripper":
                continue
            ji, jj = parent_of[caps[i].frame], parent_of[caps[j].frame]
            if ji == jj or robot.model.parents[ji] == jj or robot.model.parents[jj] == ji:
                continue
            out.append((caps[i].name, caps[j].name))
    return tuple(out)


#: Sampled configurations refined by IK to the home point; the refined one farthest from the joint limits wins.
HOME_CANDIDATES = 12


def elbow_heights(robot, frames: np.ndarray) -> np.ndarray:
    """Per configuration (``frames (T, L, 4, 4)`` of :meth:`Robot.forward`), how high the elbow stands above the
    straight line from the shoulder to the wrist (m; negative: elbow down).

    Shoulder: the origin of the second moving joint. Elbow: of the joints between it and the last, the origin
    farthest from both ends of the chain (the larger of the two least distances, stretched out at the
    clipped zero configuration). Wrist: the first origin after the elbow at least 1 cm from it (vendors put
    a joint's origin anywhere on its axis, an iiwa's in pairs at one point), else the last joint's. The height
    is the elbow's z minus the line's z where the elbow is nearest the line. Fewer than three joints: zero."""
    origins = _joint_origins(robot, frames)
    n = origins.shape[1]
    if n < 3:
        return np.zeros(len(frames))
    zero = _joint_origins(robot, robot.forward(np.clip(np.zeros(robot.n), robot.lower, robot.upper))[None])[0]
    reach = [min(np.linalg.norm(zero[k] - zero[1]), np.linalg.norm(zero[k] - zero[-1])) for k in range(2, n - 1)]
    elbow = 2 + int(np.argmax(reach))
    wrist = next((k for k in range(elbow + 1, n) if np.linalg.norm(zero[k] - zero[elbow]) >= 0.01), n - 1)
    shoulder, line = origins[:, 1], origins[:, wrist] - origins[:, 1]
    t = np.einsum("ti,ti->t", origins[:, elbow] - shoulder, line) / np.maximum(np.einsum("ti,ti->t", line, line), 1e-12)
    return origins[:, elbow, 2] - (shoulder[:, 2] + t * line[:, 2])


def _joint_origins(robot, frames: np.ndarray) -> np.ndarray:
    """``(T, n, 3)`` m: each moving joint's origin (its child link's frame) in the base frame."""
    import pinocchio as pin

    child = {}
    for f in robot.model.frames:
        if f.type == pin.FrameType.BODY and f.parentJoint > 0 and f.parentJoint not in child:
            child[f.parentJoint] = robot.frame_names.index(f.name)
    return frames[:, [child[j] for j in range(1, robot.model.njoints)]][..., :3, 3]


def _clearance(robot, p0, p1, capsule_capsule, structural) -> np.ndarray:
    """Per configuration, the least distance (m) of a moving capsule to the table and of a non-adjacent capsule
    pair (not ``structural``) to each other, from the capsule ends ``p0``, ``p1`` ``(T, C, 3)``."""
    movable = np.array([c.frame not in robot.fixed_links and c.name not in robot.table_fixed_capsules for c in robot.capsules])
    lowest = np.minimum(p0[..., 2], p1[..., 2]) - robot.capsule_radii
    clearance = lowest[:, movable].min(axis=1) if movable.any() else np.full(len(p0), np.inf)
    names = robot.capsule_names
    for a, b in robot._default_self_pairs(None):
        if (a, b) in structural:
            continue
        i, j = names.index(a), names.index(b)
        d = capsule_capsule(p0[:, i], p1[:, i], robot.capsule_radii[i], p0[:, j], p1[:, j], robot.capsule_radii[j])
        clearance = np.minimum(clearance, d)
    return clearance


def _limit_margin(robot, q: np.ndarray) -> np.ndarray:
    """Per configuration ``q (T, n)``, the least distance of a joint from its nearer limit as a fraction of its
    range (0 at a limit, 0.5 mid-range)."""
    span = np.maximum(robot.upper - robot.lower, 1e-9)
    return np.min(np.minimum(q - robot.lower, robot.upper - q) / span, axis=1)


def _home(robot, samples, frames, p0, p1, capsule_capsule, structural) -> np.ndarray:
    """A home pose as an engineer would choose one: the TCP in front of the shoulder at half the reach (as high
    above the table), fingers down, elbow up (:func:`elbow_heights`), free of collision (:func:`_clearance`),
    away from the joint limits.

    The sampled configurations that are clear (elbow up where any clear one is) are ranked by their TCP's
    distance from that point, its fingers' lean from down and their joint margin (:func:`_limit_margin`); the
    best :data:`HOME_CANDIDATES` are each refined by IK to the point, and of the refined ones still clear and
    elbow up, the one farthest from the joint limits is home (a base joint at mid-range leaves it room to turn
    either way). When none refines, the best sample itself."""
    tcp = frames[:, robot.tcp_index]
    clearance = _clearance(robot, p0, p1, capsule_capsule, structural)
    up = elbow_heights(robot, frames) >= 0.0
    target = robot.shoulder_m + np.array([0.5 * robot.reach_m, 0.0, -robot.shoulder_m[2] + 0.5 * robot.reach_m])
    down = -tcp[:, :3, 2] @ np.array([0.0, 0.0, 1.0])
    score = -np.linalg.norm(tcp[:, :3, 3] - target, axis=1) / robot.reach_m + 0.5 * down + _limit_margin(robot, samples)
    clear = clearance > 0
    if (clear & up).any():
        clear &= up
    if clear.any():
        score[~clear] = -np.inf
    else:  # nothing sampled is clear: the least colliding one (the critics will say where it touches)
        return samples[int(np.argmax(clearance))]
    ranked = np.argsort(-score, kind="stable")[: min(HOME_CANDIDATES, int(clear.sum()))]
    refined = []
    for k in ranked.tolist():
        try:
            refined.append(robot.ik(target, seed=samples[k]))
        except Exception:  # this sample does not reach the point fingers down; the next may
            continue
    if refined:
        q = np.array(refined)
        r_frames, r0, r1 = robot.forward_with_capsules(q)
        good = (_clearance(robot, r0, r1, capsule_capsule, structural) > 0) & (elbow_heights(robot, r_frames) >= 0.0)
        if good.any():
            # the base joint's room counts twice: every placement the program asks for turns it first, and a base
            # near its limit sends the posture seeds of targets on that side to far solutions
            base = np.minimum(q[:, 0] - robot.lower[0], robot.upper[0] - q[:, 0]) / max(robot.upper[0] - robot.lower[0], 1e-9)
            margin = np.where(good, _limit_margin(robot, q) + base, -np.inf)
            return q[int(np.argmax(margin))]
    return samples[int(ranked[0])]
