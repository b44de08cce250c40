"""Reading URDF files as vendors ship them: bounded, validated, every refusal naming the element and line.

A URDF is untrusted input (a file from a package, a download, an LLM's edit). :func:`read_urdf` reads at most
:data:`MAX_URDF_BYTES` with expat and no DTD: a ``<!DOCTYPE>`` or ``<!ENTITY>`` (entity expansion, external
entities) is refused before anything is expanded; at most :data:`MAX_ELEMENTS` elements, nested at most
:data:`MAX_DEPTH` deep, at most :data:`MAX_LINKS` links and :data:`MAX_JOINTS` joints (an 800-joint file is
refused here, before Pinocchio allocates for it). Namespaces are not processed, so a vendor's
``drake:acceleration="..."`` is an attribute like any other, and ignored. Every number robocritics reads is
checked here (:func:`check_numbers`): a count of values, finite, within a bound; a cylinder without a length,
a negative radius, a two-value origin, a zero velocity limit are :class:`RobotModelError`\\ s that name the
file, the line, the element and its joint or link.

:func:`kinematic_tree` gives the links and joints as a tree (one root, no link with two parents, no cycle);
:func:`chain` picks the serial arm in it (refusing a branching one unless ``tip=`` names the branch);
:func:`resolve_mesh` finds a ``<mesh filename=...>`` (``package://``, ``file://``, relative paths).
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from xml.parsers import expat

from ..errors import RobotModelError

__all__ = [
    "UrdfDocument",
    "read_urdf",
    "check_numbers",
    "KinematicTree",
    "kinematic_tree",
    "chain",
    "resolve_mesh",
    "MAX_URDF_BYTES",
    "MAX_ELEMENTS",
    "MAX_DEPTH",
    "MAX_LINKS",
    "MAX_JOINTS",
    "MAX_MESH_BYTES",
    "MOVING_JOINT_TYPES",
]

#: Largest URDF read [bytes]. The largest vendor arm descriptions are a few hundred kB (a humanoid with
#: hands, about 300 kB); a 50 MB file is refused before it is read.
MAX_URDF_BYTES = 4_000_000
#: Most XML elements in a URDF (a 30-link arm with visuals, inertials and transmissions has ~1,000).
MAX_ELEMENTS = 50_000
#: Deepest element nesting (a URDF is 4-5 deep).
MAX_DEPTH = 32
#: Most ``<link>``\\ s and ``<joint>``\\ s: whole humanoids with hands have ~100; an arm has 10-30.
MAX_LINKS = 256
MAX_JOINTS = 256
#: Largest mesh file loaded [bytes] (vendor collision meshes are 10 kB-2 MB, visual OBJs up to ~10 MB).
MAX_MESH_BYTES = 32_000_000
#: Largest length or position [m] and joint limit [rad or m] read from a URDF: anything larger is a typo
#: or an attack (``1e308`` overflows the first product it enters).
MAX_LENGTH_M = 1000.0
#: Largest speed limit [rad/s or m/s] and effort [N m or N] read.
MAX_RATE = 1e6

MOVING_JOINT_TYPES = ("revolute", "continuous", "prismatic")
_JOINT_TYPES = (*MOVING_JOINT_TYPES, "fixed", "floating", "planar", "spherical")


class _Refused(Exception):
    """Raised inside an expat handler to stop the parse; turned into a RobotModelError."""


@dataclass
class UrdfDocument:
    """A parsed URDF: its root ``<robot>`` element and the line each element starts on."""

    path: Path
    root: ET.Element
    lines: dict[int, int] = field(default_factory=dict)

    def line(self, element: ET.Element) -> int:
        """The line ``element`` starts on (0 for an element robocritics made)."""
        return self.lines.get(id(element), 0)

    def error(self, element: ET.Element | None, what: str) -> RobotModelError:
        """A :class:`RobotModelError` for ``element``: ``"<path>, line N: <what>"``."""
        line = self.line(element) if element is not None else 0
        return RobotModelError(f"{self.path}, line {line}: {what}" if line else f"{self.path}: {what}")


def read_urdf(path: str | Path, text: str | bytes | None = None) -> UrdfDocument:
    """Parse the URDF at ``path`` (or the given ``text``, with ``path`` for messages) within the bounds above.

    Raises :class:`RobotModelError` naming the file (and the line, where there is one) for a file that is
    missing, too large, not XML, has a DTD or entities, too many elements, links or joints, or a root that
    is not ``<robot>``. The numbers are checked separately (:func:`check_numbers`).
    """
    path = Path(path)
    if text is None:
        try:
            with open(path, "rb") as f:
                size = os.fstat(f.fileno()).st_size
                if size > MAX_URDF_BYTES:
                    raise RobotModelError(
                        f"cannot load URDF {str(path)!r}: {size:,} bytes is more than the {MAX_URDF_BYTES:,} a robot "
                        "description needs (robocritics.robot.urdf.MAX_URDF_BYTES)"
                    )
                data = f.read(MAX_URDF_BYTES + 1)
        except OSError as exc:
            raise RobotModelError(f"cannot load URDF {str(path)!r}: {exc.strerror or exc}") from None
    else:
        data = text.encode() if isinstance(text, str) else bytes(text)
    if len(data) > MAX_URDF_BYTES:
        raise RobotModelError(f"cannot load URDF {str(path)!r}: more than {MAX_URDF_BYTES:,} bytes")
    root, lines = _parse(data, path)
    doc = UrdfDocument(path, root, lines)
    if root.tag != "robot":
        raise doc.error(root, f"the root element is <{root.tag}>, a URDF's is <robot>")
    for tag, bound in (("link", MAX_LINKS), ("joint", MAX_JOINTS)):
        count = len(root.findall(tag))
        if count > bound:
            raise doc.error(root, f"{count} <{tag}> elements; robocritics reads at most {bound} (an arm has 10-30)")
    return doc


def _parse(data: bytes, path: Path) -> tuple[ET.Element, dict[int, int]]:
    """Elements and their start lines from expat, with every DTD feature refused and size bounds enforced."""
    parser = expat.ParserCreate()  # no namespace processing: foreign prefixes are plain attribute names
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    stack: list[ET.Element] = []
    lines: dict[int, int] = {}
    roots: list[ET.Element] = []
    count = 0

    def refuse_dtd(*_args):
        raise _Refused("has a DOCTYPE or ENTITY declaration; a URDF needs neither (entities are refused, not expanded)")

    def start(tag, attrib):
        nonlocal count
        count += 1
        if count > MAX_ELEMENTS:
            raise _Refused(f"has more than {MAX_ELEMENTS:,} elements")
        if len(stack) >= MAX_DEPTH:
            raise _Refused(f"nests elements more than {MAX_DEPTH} deep")
        element = ET.Element(tag, attrib) if not stack else ET.SubElement(stack[-1], tag, attrib)
        if not stack:
            roots.append(element)
        lines[id(element)] = parser.CurrentLineNumber
        stack.append(element)

    def end(_tag):
        stack.pop()

    parser.StartDoctypeDeclHandler = refuse_dtd
    parser.EntityDeclHandler = refuse_dtd
    parser.ExternalEntityRefHandler = refuse_dtd
    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(data, True)
    except _Refused as exc:
        raise RobotModelError(f"cannot load URDF {str(path)!r}, line {parser.CurrentLineNumber}: it {exc}") from None
    except expat.ExpatError as exc:
        raise RobotModelError(f"cannot load URDF {str(path)!r}: {exc}") from None
    if not roots:
        raise RobotModelError(f"cannot load URDF {str(path)!r}: no root element")
    return roots[0], lines


# --- numbers ------------------------------------------------------------------------------------------


def floats(doc: UrdfDocument, element: ET.Element, attr: str, count: int, owner: str, *, default=None, bound: float = MAX_LENGTH_M) -> tuple[float, ...]:
    """The ``count`` numbers of ``element``'s attribute ``attr`` (``default`` when it is absent), each finite
    and at most ``bound`` in size; a :class:`RobotModelError` naming ``owner`` (``"joint 'elbow'"``) and the line
    otherwise."""
    text = element.get(attr)
    if text is None:
        if default is not None:
            return tuple(default)
        raise doc.error(element, f"<{element.tag}> of {owner} needs {attr}=\"...\" ({count} number{'s' if count > 1 else ''})")
    parts = text.split()
    if len(parts) != count:
        raise doc.error(element, f"<{element.tag} {attr}={_clip(text)!r}> of {owner}: {attr} needs {count} number{'s' if count > 1 else ''}, got {len(parts)}")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise doc.error(element, f"<{element.tag} {attr}={_clip(text)!r}> of {owner}: not a number") from None
    for v in values:
        if not (math.isfinite(v) and abs(v) <= bound):
            raise doc.error(element, f"<{element.tag} {attr}={_clip(text)!r}> of {owner}: {v!r} is not a finite number of at most {bound:g}")
    return values


def _clip(text: str, limit: int = 60) -> str:
    return text if len(text) <= limit else text[:limit] + "..."


def _positive(doc: UrdfDocument, element: ET.Element, attr: str, owner: str, *, bound: float = MAX_LENGTH_M) -> float:
    (value,) = floats(doc, element, attr, 1, owner, bound=bound)
    if not value > 0:
        raise doc.error(element, f"<{element.tag} {attr}=\"{element.get(attr)}\"> of {owner}: {attr} must be positive")
    return value


def check_numbers(doc: UrdfDocument) -> None:
    """Check every number robocritics or Pinocchio reads from ``doc``: origins (3 + 3 values), axes (3, not
    zero), limits (finite, lower <= upper, a positive velocity on every moving joint), collision geometry
    (a cylinder's radius and length, a sphere's radius, a box's three sizes, all positive; a mesh's scale),
    inertials (a non-negative mass). Raises :class:`RobotModelError` naming the element, its link or joint and
    the line; the joint type must be one URDF defines."""
    for link in doc.root.findall("link"):
        owner = f"link {link.get('name')!r}"
        if link.get("name") is None:
            raise doc.error(link, "a <link> needs a name")
        for collision in link.findall("collision"):
            _check_origin(doc, collision.find("origin"), owner)
            geometry = collision.find("geometry")
            shapes = list(geometry) if geometry is not None else []
            if len(shapes) != 1:
                raise doc.error(collision, f"<collision> of {owner} needs one shape in its <geometry>, has {len(shapes)}")
            _check_shape(doc, shapes[0], owner)
        inertial = link.find("inertial")
        if inertial is not None:
            _check_origin(doc, inertial.find("origin"), owner)
            mass = inertial.find("mass")
            if mass is not None and floats(doc, mass, "value", 1, owner, bound=1e6)[0] < 0:
                raise doc.error(mass, f"<mass> of {owner} is negative")
            inertia = inertial.find("inertia")
            if inertia is not None:
                for attr in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"):
                    floats(doc, inertia, attr, 1, owner, default=(0.0,), bound=1e6)
    for joint in doc.root.findall("joint"):
        name = joint.get("name")
        owner = f"joint {name!r}"
        if name is None:
            raise doc.error(joint, "a <joint> needs a name")
        kind = joint.get("type")
        if kind not in _JOINT_TYPES:
            raise doc.error(joint, f"{owner} has type {kind!r}; URDF's are {', '.join(_JOINT_TYPES)}")
        for role in ("parent", "child"):
            element = joint.find(role)
            if element is None or not element.get("link"):
                raise doc.error(joint, f"{owner} needs <{role} link=\"...\"/>")
        _check_origin(doc, joint.find("origin"), owner)
        axis = joint.find("axis")
        if axis is not None:
            values = floats(doc, axis, "xyz", 3, owner, default=(1.0, 0.0, 0.0))
            if kind in MOVING_JOINT_TYPES and not any(values):
                raise doc.error(axis, f"<axis> of {owner} is zero")
        if kind in MOVING_JOINT_TYPES:
            _check_limit(doc, joint, kind, owner)


def _check_origin(doc: UrdfDocument, origin: ET.Element | None, owner: str) -> None:
    if origin is not None:
        floats(doc, origin, "xyz", 3, owner, default=(0.0, 0.0, 0.0))
        floats(doc, origin, "rpy", 3, owner, default=(0.0, 0.0, 0.0), bound=100.0)


def _check_shape(doc: UrdfDocument, shape: ET.Element, owner: str) -> None:
    if shape.tag == "cylinder":
        _positive(doc, shape, "radius", owner)
        _positive(doc, shape, "length", owner)
    elif shape.tag == "sphere":
        _positive(doc, shape, "radius", owner)
    elif shape.tag == "box":
        if not all(v > 0 for v in floats(doc, shape, "size", 3, owner)):
            raise doc.error(shape, f"<box size=\"{shape.get('size')}\"> of {owner}: every size must be positive")
    elif shape.tag == "mesh":
        if not shape.get("filename"):
            raise doc.error(shape, f"<mesh> of {owner} needs filename=\"...\"")
        if not all(v != 0 for v in floats(doc, shape, "scale", 3, owner, default=(1.0, 1.0, 1.0))):
            raise doc.error(shape, f"<mesh scale=\"{shape.get('scale')}\"> of {owner}: a scale of 0 flattens the mesh")
    elif shape.tag == "capsule":  # a common extension (Drake, Gazebo); read as what it is
        _positive(doc, shape, "radius", owner)
        _positive(doc, shape, "length", owner)
    else:
        raise doc.error(shape, f"<{shape.tag}> of {owner} is not a URDF collision shape (cylinder, sphere, box, mesh)")


def _check_limit(doc: UrdfDocument, joint: ET.Element, kind: str, owner: str) -> None:
    limit = joint.find("limit")
    if limit is None:
        raise doc.error(joint, f"{owner} ({kind}) needs <limit velocity=\"...\" effort=\"...\"/> (rad/s or m/s)")
    velocity = _positive(doc, limit, "velocity", owner, bound=MAX_RATE)
    del velocity
    floats(doc, limit, "effort", 1, owner, default=(0.0,), bound=MAX_RATE)
    if kind != "continuous":
        lower = floats(doc, limit, "lower", 1, owner, default=(0.0,))[0]
        upper = floats(doc, limit, "upper", 1, owner, default=(0.0,))[0]
        if not lower <= upper:
            raise doc.error(limit, f"<limit> of {owner}: lower {lower!r} is above upper {upper!r}")


# --- the tree and the arm in it ------------------------------------------------------------------------


@dataclass
class KinematicTree:
    """Links and joints of a URDF as a tree: ``root`` the one link that is no joint's child."""

    doc: UrdfDocument
    root: str
    links: dict[str, ET.Element]
    joints: dict[str, ET.Element]
    parent_joint: dict[str, ET.Element]  # child link -> the joint that moves it
    children: dict[str, list[ET.Element]]  # link -> the joints it is the parent of

    def path_to(self, link: str) -> list[ET.Element]:
        """The joints from the root to ``link``, root first."""
        joints: list[ET.Element] = []
        while link != self.root:
            joint = self.parent_joint[link]
            joints.append(joint)
            link = joint.find("parent").get("link")
        return joints[::-1]

    def subtree_moves(self, link: str) -> bool:
        """True when a moving joint is at or below ``link``."""
        todo = [link]
        while todo:
            for joint in self.children.get(todo.pop(), ()):
                if joint.get("type") in MOVING_JOINT_TYPES:
                    return True
                todo.append(joint.find("child").get("link"))
        return False


def kinematic_tree(doc: UrdfDocument) -> KinematicTree:
    """The tree of ``doc`` (numbers already checked): one root, every joint's links exist, no link has two
    parents, no cycle; otherwise a :class:`RobotModelError` naming the joint or link and the line."""
    links: dict[str, ET.Element] = {}
    for link in doc.root.findall("link"):
        name = link.get("name")
        if name in links:
            raise doc.error(link, f"link {name!r} is declared twice (first on line {doc.line(links[name])})")
        links[name] = link
    joints: dict[str, ET.Element] = {}
    parent_joint: dict[str, ET.Element] = {}
    children: dict[str, list[ET.Element]] = {}
    for joint in doc.root.findall("joint"):
        name = joint.get("name")
        if name in joints:
            raise doc.error(joint, f"joint {name!r} is declared twice (first on line {doc.line(joints[name])})")
        joints[name] = joint
        parent, child = joint.find("parent").get("link"), joint.find("child").get("link")
        for role, link in (("parent", parent), ("child", child)):
            if link not in links:
                raise doc.error(joint, f"joint {name!r}: its {role} link {link!r} is not declared")
        if child in parent_joint:
            first = parent_joint[child]
            raise doc.error(joint, f"joint {name!r}: link {child!r} already has a parent (joint {first.get('name')!r}, "
                                   f"line {doc.line(first)}); a URDF is a tree")
        parent_joint[child] = joint
        children.setdefault(parent, []).append(joint)
    roots = [name for name in links if name not in parent_joint]
    if not links:
        raise doc.error(doc.root, "no <link> elements")
    if len(roots) != 1:
        what = "no root link: the joints form a cycle" if not roots else f"{len(roots)} root links ({', '.join(roots[:5])}); a URDF has one"
        raise doc.error(doc.root, what)
    tree = KinematicTree(doc, roots[0], links, joints, parent_joint, children)
    reached, todo = {roots[0]}, [roots[0]]
    while todo:
        for joint in children.get(todo.pop(), ()):
            child = joint.find("child").get("link")
            reached.add(child)
            todo.append(child)
    if len(reached) != len(links):
        stray = next(name for name in links if name not in reached)
        raise doc.error(links[stray], f"link {stray!r} is on a cycle of joints, not below the root {roots[0]!r}")
    return tree


#: Names of the flange frame, most specific first, that tip inference looks for below the last moving joint.
FLANGE_NAMES = ("tool0", "flange", "ee_link", "end_effector")


def chain(tree: KinematicTree, tip: str | None = None) -> tuple[list[ET.Element], str]:
    """``(joints, tip)``: the joints from the root to the arm's tip (its flange), root first, and the tip link.

    With ``tip`` the chain ends at that link; moving joints off it are dropped. Without, the moving joints
    must form one path (a hand's finger joints branch off it: a :class:`RobotModelError` names the branch
    and asks for ``tip=``); the tip is the last moving joint's child, or the link below it through fixed
    joints named like a flange (:data:`FLANGE_NAMES`, ``tool0`` first).
    """
    doc = tree.doc
    if tip is not None:
        if tip not in tree.links:
            raise RobotModelError(f"{doc.path}: tip={tip!r} is not a link; links are {', '.join(list(tree.links)[:40])}")
        joints = tree.path_to(tip)
    else:
        moving = [j for j in tree.joints.values() if j.get("type") in MOVING_JOINT_TYPES]
        if not moving:
            raise doc.error(doc.root, "no moving joint (revolute, continuous or prismatic): nothing here is an arm")
        ends = [j for j in moving if not tree.subtree_moves(j.find("child").get("link"))]
        if len(ends) > 1:
            names = ", ".join(f"{j.get('name')!r} (line {doc.line(j)})" for j in ends[:4])
            raise doc.error(ends[1], f"the chain branches: moving joints {names} end separate branches (a hand's "
                                     "fingers, a second arm); name the arm's last link with tip=... (its flange), "
                                     "and a tool with tool=...")
        last = ends[0].find("child").get("link")
        tip = _flange_below(tree, last) or last
        joints = tree.path_to(tip)
    if not any(j.get("type") in MOVING_JOINT_TYPES for j in joints):
        raise doc.error(doc.root, f"no moving joint between the root {tree.root!r} and the tip {tip!r}: nothing here is an arm")
    for joint in joints:
        if joint.get("type") not in (*MOVING_JOINT_TYPES, "fixed"):
            raise doc.error(joint, f"joint {joint.get('name')!r} is {joint.get('type')}; robocritics plans revolute and "
                                   "prismatic joints (a floating or planar base is not an arm's)")
    return joints, tip


def _flange_below(tree: KinematicTree, link: str) -> str | None:
    """A link below ``link`` through fixed joints named like a flange (:data:`FLANGE_NAMES` order)."""
    below: list[str] = []
    todo = [link]
    while todo:
        for joint in tree.children.get(todo.pop(), ()):
            if joint.get("type") == "fixed":
                child = joint.find("child").get("link")
                below.append(child)
                todo.append(child)
    for wanted in FLANGE_NAMES:
        for name in below:
            if name == wanted or name.endswith("_" + wanted):
                return name
    return None


# --- meshes ---------------------------------------------------------------------------------------------


def resolve_mesh(doc: UrdfDocument, mesh: ET.Element, owner: str, package_paths: tuple[Path, ...] = ()) -> Path:
    """The file a ``<mesh filename=...>`` names.

    ``package://NAME/REST``: a directory ``NAME`` (or one whose ``package.xml`` names it) among the URDF's
    ancestors, their children, and ``package_paths`` (and ``ROS_PACKAGE_PATH``); failing that, ``REST`` below one
    of the URDF's ancestors (a package installed under another directory name, as pip packages do).
    ``file://PATH`` and plain paths: as given, relative to the URDF's directory. A missing file, or one larger
    than :data:`MAX_MESH_BYTES`, is a :class:`RobotModelError` naming the link, the file and the line.
    """
    filename = mesh.get("filename", "")
    base = doc.path.resolve().parent
    candidates: list[Path] = []
    if filename.startswith("package://"):
        package, _, rest = filename[len("package://"):].partition("/")
        roots = [*package_paths, *(Path(p) for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p)]
        ancestors = [base, *base.parents][:8]
        for directory in [*ancestors, *roots]:
            if directory.name == package:
                candidates.append(directory / rest)
            candidates.append(directory / package / rest)
        candidates += [directory / rest for directory in ancestors]
    elif filename.startswith("file://"):
        candidates.append(Path(filename[len("file://"):]))
    else:
        candidates.append(base / filename)
    for candidate in candidates:
        try:
            if candidate.is_file():
                size = candidate.stat().st_size
                if size > MAX_MESH_BYTES:
                    raise doc.error(mesh, f"<mesh filename={_clip(filename)!r}> of {owner}: {size:,} bytes is more than "
                                          f"{MAX_MESH_BYTES:,} (robocritics.robot.urdf.MAX_MESH_BYTES)")
                return candidate
        except OSError:
            continue
    raise doc.error(mesh, f"<mesh filename={_clip(filename)!r}> of {owner}: no such file (looked in the URDF's "
                          "package, its directory and package_paths=)")
