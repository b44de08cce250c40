"""The scene a robot program runs in: objects, open-top containers, the table, the workspace.

All coordinates are metres in the robot base frame, z up. An object's
``position`` is the centre of its shape; ``rpy`` (rad, roll-pitch-yaw about the
fixed x, y, z axes) orients it. Sizes are full extents in metres:

* ``box``: ``[x, y, z]`` edge lengths;
* ``cylinder``: ``[radius, height]`` (axis along the object's z);
* ``sphere``: ``[radius]``;
* ``mesh``: a fixture from CAD, ``{"shape": "mesh", "file": "jig.stl", "scale": 0.001}``: the triangles of an
  STL, DAE or OBJ file (read with coal's loader, :func:`robocritics.robot.fit.load_mesh`; a DAE with a DOCTYPE
  is refused), ``file`` relative to the scene file (to the working directory for a scene not read from a file),
  ``scale`` the file's unit in metres. ``position`` and ``rpy`` (or ``yaw``, rad about z, instead of ``rpy``)
  place the file's origin (not a centre);
  ``size`` is derived (the scaled mesh's bounding-box extents). A mesh object is a fixture: never graspable.
  The file is bounded (:data:`MAX_MESH_FILE_BYTES`, :data:`MAX_MESH_TRIANGLES`, finite vertices, the placed
  mesh within :data:`MAX_COORD_M`).

A container is an open-top box of outer extents ``size`` whose floor and four
walls are ``wall_m`` thick: its inside is free space, so placing something
*into* it is not a collision. The table top is the plane ``z = table.top_z``
(the robot base stands on it). The allowed workspace is a sphere (by default the
robot's reach around its shoulder) cut by the table top.

Invalid input raises :class:`~robocritics.errors.SceneError` naming the field
path (``objects[2].size[0]``) and the problem, or the file and the problem. A
scene is untrusted input, so everything in it is bounded:

* every number is a finite int or float (not a bool or a string): coordinates
  (positions, centres, the table top) within :data:`MAX_COORD_M` (10 m) of the
  base, lengths (sizes, radii, thicknesses) in (0, :data:`MAX_LENGTH_M`] m, angles
  within :data:`MAX_ANGLE_RAD` (one turn); integers have at most
  :data:`MAX_INT_DIGITS` digits;
* ids are Python identifiers (NFKC-normalised, not starting with ``_``, at most
  :data:`MAX_ID_CHARS` characters) that shadow no name of the program language:
  not a keyword, a builtin of robot programs
  (:data:`robocritics.program.language.SAFE_BUILTINS`, e.g. ``print``) or
  ``table`` (see :func:`reserved_names`). The names of the skill API (``home``,
  ``lib``, ``objects``, ``open``, ...) are checked where a scene meets it, by
  :func:`robocritics.pipeline.check_scene_ids`: the skills are built on scenes,
  so this module cannot import them;
* at most :data:`MAX_ENTITIES` objects and containers; text fields and free
  attributes are bounded in length, nesting and count, and are JSON-like text
  (no unpaired surrogates);
* a scene file is a regular file of at most :data:`MAX_FILE_BYTES` bytes of UTF-8
  JSON nested at most :data:`MAX_JSON_DEPTH` deep (checked before parsing).
"""

from __future__ import annotations

import functools
import json
import keyword
import math
import numbers
import re
import unicodedata
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal, Optional

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError, model_validator

from ._suggest import did_you_mean
from ._files import read_bounded_text
from .errors import SceneError

__all__ = [
    "SceneObject",
    "Container",
    "Table",
    "Workspace",
    "Human",
    "Scene",
    "Shape",
    "rpy_matrix",
    "parse_json",
    "reserved_names",
    "MAX_COORD_M",
    "MAX_LENGTH_M",
    "MAX_ANGLE_RAD",
    "MAX_ENTITIES",
    "MAX_FILE_BYTES",
    "MAX_JSON_DEPTH",
    "MAX_MESH_FILE_BYTES",
    "MAX_MESH_TRIANGLES",
    "mesh_triangles",
]

MAX_COORD_M = 10.0
"""Largest |coordinate| of a scene [m]: ten times a tabletop arm's reach, so millimetres given as metres are caught."""
MAX_LENGTH_M = 2 * MAX_COORD_M
"""Largest size, radius or thickness [m]: anything spanning the coordinate bound."""
MAX_ANGLE_RAD = 2 * math.pi
"""Largest |angle| (rpy, yaw) [rad]: one turn."""
MAX_INT_DIGITS = 20
"""Most digits of an integer anywhere in a scene (a 64-bit integer has 19 or 20)."""
MAX_ENTITIES = 100
"""Most objects plus containers in a scene: a tabletop task has a few dozen; each costs proximity work per sample."""
MAX_ID_CHARS = 64
"""Longest object or container id."""
MAX_NAME_CHARS = 200
"""Longest scene name."""
MAX_TEXT_CHARS = 10_000
"""Longest scene description or attribute string."""
MAX_ATTRIBUTE_DEPTH = 8
"""Deepest nesting of lists/dicts in an entity's attributes."""
MAX_ATTRIBUTE_ITEMS = 1_000
"""Most values (scalars, lists, dicts, dict keys) in one entity's attributes."""
MAX_FILE_BYTES = 1_000_000
"""Largest scene file [bytes]: a hundred richly described objects take some 50 kB."""
MAX_JSON_DEPTH = 32
"""Deepest nesting of a scene file's JSON (a scene needs 4 plus its attributes' depth)."""
MAX_MESH_FILE_BYTES = 32_000_000
"""Largest mesh file of a scene object [bytes]: a binary STL of MAX_MESH_TRIANGLES takes 10 MB."""
MAX_MESH_TRIANGLES = 200_000
"""Most triangles of one scene mesh: a CAD fixture exported for collision checking has thousands."""
MAX_MESH_SCALE = 1000.0
"""Largest mesh ``scale`` (file units to metres; 0.001 for millimetres, 0.0254 for inches)."""


class _LongInt:
    """A JSON integer too long to convert (Python refuses beyond 4300 digits); validation rejects it by field."""

    __slots__ = ("digits",)

    def __init__(self, digits: int):
        self.digits = digits

    def __repr__(self) -> str:
        return f"<a {self.digits}-digit integer>"


def _parse_int(text: str) -> int | _LongInt:
    digits = len(text.lstrip("-"))
    return int(text) if digits <= MAX_INT_DIGITS else _LongInt(digits)


def _json_depth(text: str) -> tuple[int, int]:
    """``(depth, line)``: the deepest nesting of ``[``/``{`` in JSON ``text`` outside strings, and the line where
    it first exceeds :data:`MAX_JSON_DEPTH` (0 if it does not). Linear time and memory, vectorised, no recursion."""
    raw = text.encode("utf-8", "surrogatepass")  # multi-byte characters hold no ASCII bytes
    b = np.frombuffer(raw, dtype=np.uint8)
    if not b.size:
        return 0, 0
    # a quote is escaped when an odd run of backslashes precedes it
    backslash = b == ord("\\")
    index = np.arange(b.size)
    last_other = np.maximum.accumulate(np.where(backslash, -1, index))
    run_before = np.zeros(b.size, dtype=np.int64)
    run_before[1:] = index[:-1] - last_other[:-1]
    quote = (b == ord('"')) & (run_before % 2 == 0)
    outside = np.cumsum(quote) % 2 == 0  # a quote itself counts as inside: it is no bracket anyway
    step = ((b == ord("[")) | (b == ord("{"))).astype(np.int64) - ((b == ord("]")) | (b == ord("}")))
    depth = np.cumsum(step * outside)
    deepest = int(depth.max())
    if deepest <= MAX_JSON_DEPTH:
        return deepest, 0
    at = int(np.argmax(depth > MAX_JSON_DEPTH))
    return deepest, raw.count(b"\n", 0, at) + 1


def parse_json(text: str, what: str) -> Any:
    """Parse untrusted JSON ``text`` with the scene's bounds; :class:`SceneError` naming ``what`` otherwise.

    Nesting is checked before parsing (at most :data:`MAX_JSON_DEPTH`), integers of more than
    :data:`MAX_INT_DIGITS` digits parse to a marker that validation rejects by field, and
    ``NaN``/``Infinity`` parse to floats that validation rejects by field.
    """
    deepest, line = _json_depth(text)
    if line:
        raise SceneError(f"{what}: JSON nested {deepest} deep (from line {line}); the limit is {MAX_JSON_DEPTH}")
    try:
        return json.loads(text, parse_int=_parse_int)
    except json.JSONDecodeError as exc:
        raise SceneError(f"{what}: not valid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}") from None
    except (ValueError, RecursionError) as exc:  # a number Python cannot convert; nesting is checked above
        raise SceneError(f"{what}: not valid JSON: {str(exc)[:200]}") from None


_RANGES = {
    "coordinate": f"coordinates are within {MAX_COORD_M:g} m of the robot base",
    "length": f"lengths are positive and at most {MAX_LENGTH_M:g} m",
    "angle": f"angles are within {MAX_ANGLE_RAD:.4g} rad (one turn)",
}


def _number(value: Any, kind: str) -> float:
    """A scene number of ``kind`` (coordinate, length, angle) as a float; ValueError saying why not."""
    if isinstance(value, _LongInt):
        raise ValueError(f"a {value.digits}-digit integer is out of range ({_RANGES[kind]})")
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        shown = repr(value) if isinstance(value, str) and len(value) <= 40 else type(value).__name__
        raise ValueError(f"{shown} is not a number")
    if isinstance(value, numbers.Integral) and int(value).bit_length() > 64:
        raise ValueError(f"an integer of {int(value).bit_length()} bits is out of range ({_RANGES[kind]})")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{v} is not a finite number")
    if kind == "length" and not v > 0:
        raise ValueError(f"{v:g} is not a positive length in metres")
    bound = {"coordinate": MAX_COORD_M, "length": MAX_LENGTH_M, "angle": MAX_ANGLE_RAD}[kind]
    if abs(v) > bound:
        raise ValueError(f"{v:g} is out of range ({_RANGES[kind]})")
    return v


Coordinate = Annotated[float, BeforeValidator(functools.partial(_number, kind="coordinate"))]
"""A coordinate [m], finite, within MAX_COORD_M of the base."""
Length = Annotated[float, BeforeValidator(functools.partial(_number, kind="length"))]
"""A size, radius or thickness [m], in (0, MAX_LENGTH_M]."""
Angle = Annotated[float, BeforeValidator(functools.partial(_number, kind="angle"))]
"""An angle [rad], within one turn."""
Vec3 = tuple[Coordinate, Coordinate, Coordinate]
Angles3 = tuple[Angle, Angle, Angle]


def _text(value: Any, limit: int) -> str:
    if not isinstance(value, str):
        raise ValueError(f"text expected, got {type(value).__name__}")
    if len(value) > limit:
        raise ValueError(f"text of {len(value):,} characters is longer than the limit of {limit:,}")
    try:
        value.encode("utf-8")
    except UnicodeEncodeError as exc:
        raise ValueError(f"character {exc.start} is an unpaired surrogate {value[exc.start]!r}, not text") from None
    return value


Name = Annotated[str, BeforeValidator(functools.partial(_text, limit=MAX_NAME_CHARS))]
Text = Annotated[str, BeforeValidator(functools.partial(_text, limit=MAX_TEXT_CHARS))]


@functools.cache
def reserved_names() -> dict[str, str]:
    """Names an object or container may not have, each with what it already is in a robot program.

    Python's keywords (soft ones too), the builtins of robot programs
    (:data:`robocritics.program.language.SAFE_BUILTINS`) and ``table``. The names of
    the skill API are checked by :func:`robocritics.pipeline.check_scene_ids`.
    """
    from .program import language  # the program language's names (a leaf module: no import cycle)

    out: dict[str, str] = {name: "a builtin of robot programs" for name in language.SAFE_BUILTINS}
    out.update({name: "a Python keyword" for name in (*keyword.kwlist, *keyword.softkwlist)})
    out["table"] = "the table's id"
    return out


def _entity_id(value: Any) -> str:
    if not isinstance(value, str):
        raise ValueError(f"an id is text, got {type(value).__name__}")
    if not value:
        raise ValueError("an id cannot be empty")
    if len(value) > MAX_ID_CHARS:
        raise ValueError(f"an id of {len(value)} characters is longer than the limit of {MAX_ID_CHARS}")
    shown = repr(value)
    if not value.isidentifier() or value.startswith("_"):
        raise ValueError(
            f"{shown} must be a Python identifier not starting with '_' (programs refer to objects by name)"
        )
    if unicodedata.normalize("NFKC", value) != value:
        raise ValueError(
            f"{shown} is not in normal form: Python reads it as {unicodedata.normalize('NFKC', value)!r} in a program"
        )
    what = reserved_names().get(value)
    if what:
        raise ValueError(f"{shown} is {what}; an object named so would shadow it in programs, choose another id")
    return value


EntityId = Annotated[str, BeforeValidator(_entity_id)]


def _attributes(value: Any) -> dict[str, Any]:
    """Free attributes as JSON-like data (str keys; str, finite numbers, bools, None, lists, dicts), bounded."""
    if not isinstance(value, dict):
        raise ValueError(f"attributes are a JSON object of names to values, got {type(value).__name__}")
    count = 0

    def fail(path: str, problem: str) -> ValueError:
        return ValueError(f"{path}: {problem}" if path else problem)

    def plain(v: Any, path: str, depth: int) -> Any:
        nonlocal count
        count += 1
        if count > MAX_ATTRIBUTE_ITEMS:
            raise fail(path, f"more than {MAX_ATTRIBUTE_ITEMS} attribute values")
        if v is None or isinstance(v, bool):
            return v
        if isinstance(v, _LongInt):
            raise fail(path, f"a {v.digits}-digit integer; the limit is {MAX_INT_DIGITS} digits")
        if isinstance(v, numbers.Integral):
            if int(v).bit_length() > 64:
                raise fail(path, f"an integer of {int(v).bit_length()} bits; the limit is 64")
            return int(v)
        if isinstance(v, numbers.Real):
            if not math.isfinite(float(v)):
                raise fail(path, f"{float(v)} is not a finite number")
            return float(v)
        if isinstance(v, str):
            try:
                return _text(v, MAX_TEXT_CHARS)
            except ValueError as exc:
                raise fail(path, str(exc)) from None
        if isinstance(v, (list, tuple, dict)):
            if depth >= MAX_ATTRIBUTE_DEPTH:
                raise fail(path, f"attributes nest deeper than {MAX_ATTRIBUTE_DEPTH} levels")
            if isinstance(v, dict):
                out = {}
                for k, item in v.items():
                    if not isinstance(k, str):
                        raise fail(path, f"a key is text, got {type(k).__name__}")
                    if len(k) > MAX_ID_CHARS:
                        raise fail(path, f"a key of {len(k):,} characters is longer than the limit of {MAX_ID_CHARS}")
                    count += 1
                    key = _text(k, MAX_ID_CHARS)
                    sub = (f"{path}.{key}" if path else key) if key.isidentifier() else f"{path}[{key!r}]"
                    out[key] = plain(item, sub, depth + 1)
                return out
            return [plain(item, f"{path}[{i}]", depth + 1) for i, item in enumerate(v)]
        raise fail(path, f"a {type(v).__name__} is not JSON-like data (text, a number, true/false, null, a list or an object)")

    return plain(value, "", 0)


def _entities(value: Any) -> Any:
    if isinstance(value, (list, tuple)) and len(value) > MAX_ENTITIES:
        raise ValueError(f"{len(value)} entries; a scene holds at most {MAX_ENTITIES} objects and containers")
    return value


Attributes = Annotated[dict[str, Any], BeforeValidator(_attributes)]


def rpy_matrix(rpy: Vec3) -> np.ndarray:
    """Rotation matrix of roll-pitch-yaw angles (rad), ``Rz(yaw) @ Ry(pitch) @ Rx(roll)``."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


@dataclass(frozen=True)
class Shape:
    """One primitive collision shape of the scene, posed in the base frame.

    ``kind`` is ``box`` (``size`` = full extents), ``cylinder`` (radius, height),
    ``sphere`` (radius) or ``mesh`` (``size`` = bounding-box extents; ``mesh`` =
    ``(vertices (V, 3) m, triangles (F, 3))`` in the shape frame); ``pose`` is a 4x4
    homogeneous transform of the shape's centre (a mesh: its file's origin);
    ``owner`` is the id of the scene entity it belongs to.
    """

    name: str
    owner: str
    kind: str
    size: tuple[float, ...]
    pose: np.ndarray
    mesh: tuple[np.ndarray, np.ndarray] | None = None


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    def __init__(self, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as exc:
            raise _scene_error(exc, type(self).__name__) from None

    @classmethod
    def model_validate(cls, obj: Any, *args: Any, **kwargs: Any):  # type: ignore[override]
        """Validate a dict; raise :class:`SceneError` naming the first bad field."""
        try:
            return super().model_validate(obj, *args, **kwargs)
        except ValidationError as exc:
            raise _scene_error(exc, cls.__name__) from None

    @classmethod
    def model_validate_json(cls, json_data: str | bytes, *args: Any, **kwargs: Any):  # type: ignore[override]
        """Validate JSON text with the bounds of :func:`parse_json`; :class:`SceneError` if bad."""
        if isinstance(json_data, (bytes, bytearray)):
            try:
                json_data = bytes(json_data).decode("utf-8-sig")
            except UnicodeDecodeError as exc:
                raise SceneError(f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None
        if len(json_data) > MAX_FILE_BYTES:
            raise SceneError(f"JSON of {len(json_data):,} characters is longer than the limit of {MAX_FILE_BYTES:,}")
        return cls.model_validate(parse_json(json_data, f"{cls.__name__} JSON"), *args, **kwargs)


class SceneObject(_Model):
    """A movable or fixed object on the table."""

    id: EntityId = Field(description="unique name, usable in programs (e.g. 'green_apple')")
    shape: Literal["box", "cylinder", "sphere", "mesh"]
    size: tuple[Length, ...] = Field((), description="m; box [x,y,z], cylinder [radius,height], sphere [radius]; mesh: derived")
    position: Vec3 = Field(description="centre of the shape (a mesh: its file's origin), m, base frame")
    rpy: Angles3 = (0.0, 0.0, 0.0)
    graspable: bool = Field(True, strict=True)
    attributes: Attributes = Field(default_factory=dict, description="free attributes: colour, ripeness, ...")
    # left out of dumps when unset, so the JSON (and the hashes) of scenes without meshes stay as they were
    file: Optional[str] = Field(
        None, max_length=4096, exclude_if=lambda v: v is None, description="mesh file (STL, DAE, OBJ); shape 'mesh' only"
    )
    scale: float = Field(
        1.0, exclude_if=lambda v: v == 1.0, description="mesh file unit in metres (0.001: millimetres); shape 'mesh' only"
    )

    @model_validator(mode="before")
    @classmethod
    def _mesh_fields(cls, data: Any) -> Any:
        """A mesh object's ``size`` comes from its file and it is never graspable; other shapes take no file."""
        if not isinstance(data, dict):
            return data
        if data.get("shape") != "mesh":
            for key in ("file", "scale"):
                if key in data:
                    raise ValueError(f"{key}: only a shape 'mesh' object has a {key}")
            return data
        data = dict(data)
        if "yaw" in data:  # the (and a container's) spelling of a turn about z
            if "rpy" in data:
                raise ValueError("yaw: give either yaw (rad about z) or rpy, not both")
            try:
                data["rpy"] = (0.0, 0.0, _number(data.pop("yaw"), kind="angle"))
            except ValueError as exc:
                raise ValueError(f"yaw: {exc}") from None
        if data.get("graspable", False) is not False:
            raise ValueError("graspable: a mesh object is a fixture; robocritics does not grasp meshes")
        data["graspable"] = False
        scale = _mesh_scale(data.get("scale", 1.0))
        data["scale"] = scale
        size = tuple(float(v) for v in _mesh_extents(_mesh_of(data.get("file"), scale)))
        if max(size) > MAX_LENGTH_M:
            raise ValueError(f"file: the mesh spans {max(size):.3g} m at scale {scale}; the limit is {MAX_LENGTH_M} m (is scale right?)")
        given = data.get("size")
        # a dumped scene carries the derived size: the same numbers are accepted, others are a mistake
        if given is not None and not (isinstance(given, (list, tuple)) and len(given) == 3 and all(
            isinstance(v, numbers.Real) and not isinstance(v, bool) and abs(float(v) - w) <= 1e-9 * max(1.0, w) for v, w in zip(given, size)
        )):  # fmt: skip
            raise ValueError(f"size: a mesh object's size comes from its file ({list(size)} m); leave size out")
        data["size"] = size
        return data

    @model_validator(mode="after")
    def _check_size(self) -> "SceneObject":
        if self.shape == "mesh":
            return self._check_mesh_placement()
        expected = {"box": 3, "cylinder": 2, "sphere": 1}[self.shape]
        if len(self.size) != expected:
            raise ValueError(
                f"size: a {self.shape} needs {expected} numbers "
                f"({ {'box': '[x, y, z]', 'cylinder': '[radius, height]', 'sphere': '[radius]'}[self.shape] }), got {len(self.size)}"
            )
        for i, s in enumerate(self.size):
            if not math.isfinite(s) or s <= 0:
                raise ValueError(f"size[{i}]: {s} is not a positive length in metres")
        return self

    def _check_mesh_placement(self) -> "SceneObject":
        vertices = self.placed_vertices()
        if np.abs(vertices).max() > MAX_COORD_M:
            raise ValueError(f"file: the placed mesh reaches {np.abs(vertices).max():.3g} m from the base; the limit is {MAX_COORD_M} m (is scale right?)")
        return self

    def _pose(self) -> np.ndarray:
        pose = np.eye(4)
        pose[:3, :3] = rpy_matrix(self.rpy)
        pose[:3, 3] = self.position
        return pose

    def placed_vertices(self) -> np.ndarray:
        """A mesh object's vertices in the base frame, m ``(V, 3)``."""
        vertices, _ = _mesh_of(self.file, self.scale)
        pose = self._pose()
        return vertices @ pose[:3, :3].T + pose[:3, 3]

    @property
    def half_height(self) -> float:
        """Half the object's vertical extent, m (exact for upright shapes)."""
        if self.shape == "mesh":
            return (self.top - self.bottom) / 2
        if self.shape == "box":
            return self.size[2] / 2
        if self.shape == "cylinder":
            return self.size[1] / 2
        return self.size[0]

    @property
    def top(self) -> float:
        """z of the object's top surface, m."""
        if self.shape == "mesh":
            return float(self.placed_vertices()[:, 2].max())
        return self.position[2] + self.half_height

    @property
    def bottom(self) -> float:
        """z of the object's lowest point, m."""
        if self.shape == "mesh":
            return float(self.placed_vertices()[:, 2].min())
        return self.position[2] - self.half_height

    @property
    def width(self) -> float:
        """Horizontal extent a gripper closes on, m (the smaller horizontal size; a mesh: of its placed bounding box)."""
        if self.shape == "mesh":
            extent = np.ptp(self.placed_vertices()[:, :2], axis=0)
            return float(extent.min())
        if self.shape == "box":
            return min(self.size[0], self.size[1])
        return 2 * self.size[0]

    @property
    def centre(self) -> tuple[float, float, float]:
        """The centre of the object, m (base frame): its ``position``, or for a mesh the middle of its placed
        axis-aligned bounding box (a mesh's ``position`` is its file's origin). Programs see this as x, y, z."""
        if self.shape != "mesh":
            return self.position
        vertices = self.placed_vertices()
        return tuple(float(v) for v in (vertices.max(axis=0) + vertices.min(axis=0)) / 2)

    def shapes(self) -> list[Shape]:
        mesh = _mesh_of(self.file, self.scale) if self.shape == "mesh" else None
        return [Shape(self.id, self.id, self.shape, tuple(self.size), self._pose(), mesh)]

    def moved_to(self, position: Vec3, rpy: Vec3 | None = None) -> "SceneObject":
        return self.model_copy(update={"position": tuple(float(v) for v in position), "rpy": rpy or self.rpy})


class Container(_Model):
    """An open-top box: a floor and four walls; the inside is free space."""

    id: EntityId
    size: tuple[Length, Length, Length] = Field(description="outer extents [x, y, z], m")
    position: Vec3 = Field(description="centre of the outer box, m, base frame")
    yaw: Angle = Field(0.0, description="rotation about z, rad")
    wall_m: Length = Field(0.005, description="wall and floor thickness, m")
    attributes: Attributes = Field(default_factory=dict)

    @model_validator(mode="after")
    def _check_walls(self) -> "Container":
        if 2 * self.wall_m >= min(self.size[0], self.size[1]) or self.wall_m >= self.size[2]:
            raise ValueError(f"wall_m {self.wall_m} leaves no inside in a container of size {list(self.size)}")
        return self

    @property
    def top(self) -> float:
        """z of the rim, m."""
        return self.position[2] + self.size[2] / 2

    @property
    def floor_top(self) -> float:
        """z of the inside floor surface, m."""
        return self.position[2] - self.size[2] / 2 + self.wall_m

    @property
    def bottom(self) -> float:
        return self.position[2] - self.size[2] / 2

    def contains_point(self, point: Vec3, margin_m: float = 0.0) -> bool:
        """Whether ``point`` lies in the inner volume (between the walls, above the floor, below the rim)."""
        # Rz(yaw)^T (point - position) on Python floats: the planner asks this per candidate support
        px, py, pz = (float(v) for v in point)
        dx, dy = px - float(self.position[0]), py - float(self.position[1])
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        hx, hy = self.size[0] / 2 - self.wall_m, self.size[1] / 2 - self.wall_m
        return (
            abs(c * dx + s * dy) <= hx + margin_m
            and abs(c * dy - s * dx) <= hy + margin_m
            and self.floor_top - margin_m <= pz <= self.top + margin_m
        )

    def shapes(self) -> list[Shape]:
        sx, sy, sz = self.size
        w = self.wall_m
        # (name, centre in container frame, extents)
        parts = [
            ("floor", (0, 0, -sz / 2 + w / 2), (sx, sy, w)),
            ("wall_x-", (-sx / 2 + w / 2, 0, 0), (w, sy, sz)),
            ("wall_x+", (sx / 2 - w / 2, 0, 0), (w, sy, sz)),
            ("wall_y-", (0, -sy / 2 + w / 2, 0), (sx - 2 * w, w, sz)),
            ("wall_y+", (0, sy / 2 - w / 2, 0), (sx - 2 * w, w, sz)),
        ]
        rot = rpy_matrix((0, 0, self.yaw))
        out = []
        for name, centre, ext in parts:
            pose = np.eye(4)
            pose[:3, :3] = rot
            pose[:3, 3] = np.asarray(self.position) + rot @ np.asarray(centre, float)
            out.append(Shape(f"{self.id}.{name}", self.id, "box", tuple(float(e) for e in ext), pose))
        return out


class Table(_Model):
    """The table the robot stands on; its top surface is the plane z = ``top_z``."""

    top_z: Coordinate = Field(0.0, description="m")
    size: tuple[Length, Length] = Field((1.6, 1.2), description="x, y extents, m")
    center_xy: tuple[Coordinate, Coordinate] = (0.0, 0.0)
    thickness_m: Length = 0.04

    def shapes(self) -> list[Shape]:
        pose = np.eye(4)
        pose[:3, 3] = (self.center_xy[0], self.center_xy[1], self.top_z - self.thickness_m / 2)
        return [Shape("table", "table", "box", (self.size[0], self.size[1], self.thickness_m), pose)]


class Workspace(_Model):
    """The allowed workspace W_allowed: a sphere (m) above the plane ``min_z``.

    A scene without one (``workspace`` None) follows its robot: ``robot.scene_for(scene)`` puts in
    ``robot.workspace``, the reach sphere around that robot's shoulder. A scene knows no arm, so it has no
    default sphere of its own (the default arm's is :func:`robocritics.robot.model.default_workspace`).
    """

    center: Vec3 = Field(description="sphere centre, m (e.g. the arm's shoulder)")
    radius_m: Length = Field(description="sphere radius, m (e.g. the arm's reach)")

    @property
    def volume_m3(self) -> float:
        """Volume of the allowed workspace, m^3 (the whole sphere, as the paper's 0.523 m^3)."""
        return 4.0 / 3.0 * math.pi * self.radius_m**3

    def outside_distance(self, points: np.ndarray) -> np.ndarray:
        """How far each point ``(..., 3)`` lies outside the sphere, m (<= 0 inside): ``|p - c| - r``.

        Evaluated component-wise (:meth:`squared_centre_distance`, :meth:`outside_of_squared`): a norm over a
        length-3 axis is several times slower in numpy, and critics call this on every link of every sample.
        """
        points = np.asarray(points, dtype=float)
        d = self.squared_centre_distance(points[..., 0], points[..., 1], points[..., 2])
        if isinstance(d, np.ndarray):
            np.sqrt(d, out=d)
        else:  # a single point
            d = np.sqrt(d)
        return d - self.radius_m

    def squared_centre_distance(self, x, y, z) -> np.ndarray:
        """``|p - c|^2``, m^2, of the points whose coordinates (m) are the equal-shaped arrays ``x``, ``y``, ``z``,
        as ``((x - cx)^2 + (y - cy)^2) + (z - cz)^2``."""
        c = self.center
        dx = np.subtract(x, c[0])
        dy = np.subtract(y, c[1])
        dz = np.subtract(z, c[2])
        dx *= dx
        dy *= dy
        dz *= dz
        dx += dy
        dx += dz
        return dx

    def outside_of_squared(self, squared: np.ndarray) -> np.ndarray:
        """``sqrt(squared) - r``, m: how far outside the sphere a point lies whose squared distance from the
        centre is ``squared`` (m^2). It does not decrease with ``squared``, so the farthest of several points is
        the one of largest squared distance, and ``outside_of_squared(max(squared))`` is the largest outside
        distance bit for bit."""
        return np.sqrt(squared) - self.radius_m


MIN_HEIGHT_M = 1.40
"""Smallest stature of a person in a scene [m]: below the 1st percentile of adult women (DIN 33402-2:2020)."""
MAX_HEIGHT_M = 2.10
"""Largest stature of a person in a scene [m]: above the 99th percentile of adult men (DIN 33402-2:2020)."""


def _stature(value: Any) -> float:
    v = _number(value, "length")
    if not MIN_HEIGHT_M <= v <= MAX_HEIGHT_M:
        raise ValueError(
            f"{v:g} m is not an adult's stature (the body model is scaled for {MIN_HEIGHT_M:g}-{MAX_HEIGHT_M:g} m)"
        )
    return v


class Human(_Model):
    """A person in the cell, for the collaborative-operation critics (``contact_speed``, ``separation``).

    ``position`` is where the feet stand (m, base frame, x and y); the person faces along ``yaw_rad`` (0: +x;
    an operator across the bench from the robot faces it with ``yaw_rad`` pi); ``floor_z_m`` is the floor's
    height relative to the table top (m, usually negative). The body regions of ISO/TS 15066 are built from
    these by :func:`robocritics.humans.body_model`.
    """

    id: EntityId = Field(description="unique name, e.g. 'operator'")
    position: tuple[Coordinate, Coordinate] = Field(description="where the feet stand [x, y], m, base frame")
    yaw_rad: Angle = Field(0.0, description="the direction the person faces, rad about z (0 = +x)")
    posture: Literal["standing", "seated"] = "standing"
    height_m: Annotated[float, BeforeValidator(_stature)] = Field(1.75, description="stature, m")
    floor_z_m: Coordinate = Field(-0.75, description="floor height relative to the robot base (table top), m")


class Scene(_Model):
    """A complete task scene; see the module docstring for conventions."""

    name: Name = "scene"
    description: Text = ""
    # `lambda: []`, not `list`: pydantic reads a default factory's signature, and a builtin's costs a
    # tokenizer regex compiled once per process (~3 ms of a cold `robocritics check`; tests/test_lazy_imports.py)
    objects: Annotated[list[SceneObject], BeforeValidator(_entities)] = Field(default_factory=lambda: [])
    containers: Annotated[list[Container], BeforeValidator(_entities)] = Field(default_factory=lambda: [])
    humans: Annotated[list[Human], BeforeValidator(_entities)] = Field(
        default_factory=lambda: [], description="people in the cell (robocritics.humans builds their body model)"
    )
    table: Table = Field(default_factory=Table)
    workspace: Optional[Workspace] = Field(None, description="the allowed workspace; None: the robot's reach")
    robot: Name = Field("", description="the robot this scene was made for (e.g. 'ur3e'); '' = any robot")

    @model_validator(mode="after")
    def _check_ids(self) -> "Scene":
        count = len(self.objects) + len(self.containers)
        if count > MAX_ENTITIES:
            raise ValueError(f"containers: {count} objects and containers; a scene holds at most {MAX_ENTITIES}")
        seen: dict[str, str] = {}
        for group in ("objects", "containers", "humans"):
            for i, item in enumerate(getattr(self, group)):
                if item.id in seen:
                    raise ValueError(f"{group}[{i}].id: duplicate id {item.id!r} (already used by {seen[item.id]})")
                seen[item.id] = f"{group}[{i}]"
        return self

    # --- construction -----------------------------------------------------------------

    @classmethod
    def load(cls, path: str | Path) -> "Scene":
        """Load a scene from a JSON file (see the module docstring for the bounds); :class:`SceneError` if bad."""
        text = _read_scene_file(path)
        shown = _path_label(path)
        data = parse_json(text, shown)
        if not isinstance(data, dict):
            raise SceneError(f"{shown}: a scene is a JSON object, got {type(data).__name__}")
        _resolve_mesh_files(data, Path(path).absolute().parent)
        try:
            return cls.model_validate(data)
        except SceneError as exc:
            located = SceneError(f"{shown}: {exc}")  # the file, then the field and the problem
            located.path = exc.path
            raise located from None

    @classmethod
    def builtin_names(cls) -> list[str]:
        return sorted(p.name[:-5] for p in resources.files("robocritics.scenes").iterdir() if p.name.endswith(".json"))

    @classmethod
    def builtin(cls, name: str) -> "Scene":
        """One of the paper's task scenes: ``recycling``, ``sorting`` or ``breakfast``."""
        names = cls.builtin_names()
        if name not in names:
            hint = did_you_mean(name, names) if isinstance(name, str) and len(name) <= _QUOTED_CHARS else ""
            raise SceneError(f"no built-in scene {_quoted(name)} (have {', '.join(names)}){hint}")
        return cls.model_validate(json.loads(resources.files("robocritics.scenes").joinpath(f"{name}.json").read_text()))

    @classmethod
    def resolve(cls, name_or_path: str | Path) -> "Scene":
        """A built-in scene by name, or a scene file by path."""
        text = str(name_or_path)
        if text in cls.builtin_names():
            return cls.builtin(text)
        return cls.load(text)

    def to_json(self) -> str:
        return self.model_dump_json(indent=2)

    # --- queries -------------------------------------------------------------------

    def entity(self, entity_id: str) -> SceneObject | Container:
        for item in (*self.objects, *self.containers):
            if item.id == entity_id:
                return item
        raise SceneError(f"no object or container {entity_id!r} in scene {self.name!r}", path="objects")

    @property
    def ids(self) -> list[str]:
        return [o.id for o in self.objects] + [c.id for c in self.containers]

    def shapes(self) -> list[Shape]:
        """Every collision shape of the scene: objects, container walls and floors, the table."""
        out: list[Shape] = []
        for item in (*self.objects, *self.containers, self.table):
            out.extend(item.shapes())
        return out

    def with_object(self, obj: SceneObject) -> "Scene":
        """A copy with ``obj`` replacing the object of the same id."""
        return self.model_copy(update={"objects": [obj if o.id == obj.id else o for o in self.objects]})

    def container_holding(self, obj_id: str) -> Container | None:
        """The container whose inside holds the centre of object ``obj_id``, if any."""
        obj = self.entity(obj_id)
        for c in self.containers:
            if c.contains_point(obj.position):
                return c
        return None


def _resolve_mesh_files(data: dict, folder: Path) -> None:
    """Make the relative ``file`` of every mesh object relative to ``folder`` (the scene file's), in place."""
    objects = data.get("objects")
    for obj in objects if isinstance(objects, list) else ():
        if isinstance(obj, dict) and obj.get("shape") == "mesh" and isinstance(obj.get("file"), str) and obj["file"]:
            if "\x00" not in obj["file"] and not Path(obj["file"]).is_absolute():
                obj["file"] = str(folder / obj["file"])


def _mesh_scale(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or isinstance(value, _LongInt):
        raise ValueError(f"scale: {_quoted(value)} is not a number")
    scale = float(value)
    if not (math.isfinite(scale) and 0.0 < scale <= MAX_MESH_SCALE):
        raise ValueError(f"scale: {scale} is not a positive finite unit in metres (at most {MAX_MESH_SCALE})")
    return scale


def _mesh_of(file: Any, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The scaled triangles of mesh ``file``; a ValueError naming ``file`` if it is missing, too big or not a mesh."""
    if not isinstance(file, str) or not file or "\x00" in file:
        raise ValueError("file: a mesh object needs the path of an STL, DAE or OBJ file")
    path = Path(file)
    try:
        info = path.stat()
    except OSError as exc:
        raise ValueError(f"file: cannot read mesh {_path_label(file)}: {exc.strerror}") from None
    if not path.is_file():
        raise ValueError(f"file: {_path_label(file)} is not a regular file")
    if info.st_size > MAX_MESH_FILE_BYTES:
        raise ValueError(f"file: {_path_label(file)} has {info.st_size:,} bytes; a scene mesh has at most {MAX_MESH_FILE_BYTES:,}")
    return _cached_mesh(str(path.resolve()), info.st_mtime_ns, info.st_size, float(scale))


@functools.lru_cache(maxsize=16)
def _cached_mesh(path: str, mtime_ns: int, size: int, scale: float) -> tuple[np.ndarray, np.ndarray]:
    from .errors import RobotModelError
    from .robot.fit import load_mesh

    try:
        mesh = load_mesh(Path(path), (scale, scale, scale), max_triangles=MAX_MESH_TRIANGLES)
    except RobotModelError as exc:
        raise ValueError(f"file: {exc}") from None
    vertices, triangles = mesh.vertices.copy(), mesh.triangles.copy()
    vertices.flags.writeable = triangles.flags.writeable = False  # shared by every Shape of this file
    return vertices, triangles


def mesh_triangles(obj: "SceneObject") -> tuple[np.ndarray, np.ndarray]:
    """A mesh object's triangles in its own frame: ``vertices (V, 3)`` m (scaled) and ``triangles (F, 3)``."""
    return _mesh_of(obj.file, obj.scale)


def _mesh_extents(mesh: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    vertices = mesh[0]
    return np.maximum(vertices.max(axis=0) - vertices.min(axis=0), 1e-9)  # a flat plate still has a (tiny) size


def _read_scene_file(path: str | Path) -> str:
    """The text of scene file ``path``: a regular file of at most MAX_FILE_BYTES bytes of UTF-8."""
    return read_bounded_text(path, "scene", repr(_path_label(path)), MAX_FILE_BYTES, SceneError)


_QUOTED_CHARS = 60
"""Input quoted in error messages is cut to this length."""


_PATH_CHARS = 200
"""File names longer than this are shown as their start and end (the end names the file)."""


def _path_label(path: Any) -> str:
    """A file name for an error message: whole if readable, else its start and its end."""
    text = str(path)
    return text if len(text) <= _PATH_CHARS else f"{text[:60]}...{text[-120:]} ({len(text):,} characters)"


def _quoted(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= _QUOTED_CHARS else text[:_QUOTED_CHARS] + f"... ({len(text):,} characters)"


def _scene_error(exc: ValidationError, model: str = "Scene") -> SceneError:
    err = exc.errors()[0]
    path = ""
    for part in err["loc"]:
        if isinstance(part, int):
            path += f"[{part}]"
        else:
            text = str(part)  # an unknown key may be anything: quote a readable part of it
            text = text if len(text) <= _QUOTED_CHARS else repr(text[:_QUOTED_CHARS]) + "..."
            path += ("." if path else "") + text
    message = err["msg"]
    if message.startswith("Value error, "):
        message = message[len("Value error, ") :]
    # validators name the sub-field they reject ("size[1]: ...", "objects[2].id: ...")
    sub = re.match(r"^((?:[A-Za-z_]\w*)?(?:\[\d+\])*(?:\.[A-Za-z_]\w*(?:\[\d+\])*)*): (.*)$", message, re.S)
    if sub and sub.group(1):
        field = sub.group(1)
        path = field if not path else path + (field if field.startswith("[") else "." + field)
        message = sub.group(2)
    if err["type"] == "literal_error" and path.endswith("shape"):
        message = f"unknown shape {_quoted(err.get('input'))}; use one of box, cylinder, sphere, mesh"
    if err["type"] == "literal_error" and path.endswith("posture"):
        message = f"unknown posture {_quoted(err.get('input'))}; use standing or seated"
    more = len(exc.errors()) - 1
    if more:
        message += f" (and {more} more problem{'s' if more > 1 else ''})"
    return SceneError(message, path=path or model.lower())
