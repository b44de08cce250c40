"""The scene a robot program runs in: objects, open-top containers, the table, the workspace.

All coordinates are metres in the robot base frame, z up. An object's
``position`` is the centre of its shape; ``rpy`` (rad, roll-pitch-yaw about the
fixed x, y, z axes) orients it. Sizes are full extents in metres:

* ``box``: ``[x, y, z]`` edge lengths;
* ``cylinder``: ``[radius, height]`` (axis along the object's z);
* ``sphere``: ``[radius]``.

A container is an open-top box of outer extents ``size`` whose floor and four
walls are ``wall_m`` thick: its inside is free space, so placing something
*into* it is not a collision. The table top is the plane ``z = table.top_z``
(the robot base stands on it). The allowed workspace is a sphere (default the
UR3e reach, radius 0.5 m around the shoulder) cut by the table top.

Invalid input raises :class:`~robocritics.errors.SceneError` naming the field
path (``objects[2].size[0]``) and the problem.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from ._suggest import did_you_mean
from .errors import SceneError
from .robot.arms import UR3E

__all__ = ["SceneObject", "Container", "Table", "Workspace", "Scene", "Shape", "rpy_matrix"]

Vec3 = tuple[float, float, float]


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


def _finite(values: Any, what: str) -> Any:
    for i, v in enumerate(values):
        if not math.isfinite(v):
            raise ValueError(f"[{i}]: {v} is not a finite number")
    return values


@dataclass(frozen=True)
class Shape:
    """One primitive collision shape of the scene, posed in the base frame.

    ``kind`` is ``box`` (``size`` = full extents), ``cylinder`` (radius, height)
    or ``sphere`` (radius); ``pose`` is a 4x4 homogeneous transform of the
    shape's centre; ``owner`` is the id of the scene entity it belongs to.
    """

    name: str
    owner: str
    kind: str
    size: tuple[float, ...]
    pose: np.ndarray


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class SceneObject(_Model):
    """A movable or fixed object on the table."""

    id: str = Field(min_length=1, description="unique name, usable in programs (e.g. 'green_apple')")
    shape: Literal["box", "cylinder", "sphere"]
    size: tuple[float, ...] = Field(description="m; box [x,y,z], cylinder [radius,height], sphere [radius]")
    position: Vec3 = Field(description="centre of the shape, m, base frame")
    rpy: Vec3 = (0.0, 0.0, 0.0)
    graspable: bool = True
    attributes: dict[str, Any] = Field(default_factory=dict, description="free attributes: colour, ripeness, ...")

    @field_validator("position", "rpy")
    @classmethod
    def _check_finite(cls, v: Vec3) -> Vec3:
        return _finite(v, "value")

    @model_validator(mode="after")
    def _check_size(self) -> "SceneObject":
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

    @property
    def half_height(self) -> float:
        """Half the object's vertical extent, m (exact for upright shapes)."""
        if self.shape == "box":
            return self.size[2] / 2
        if self.shape == "cylinder":
            return self.size[1] / 2
        return self.size[0]

    @property
    def top(self) -> float:
        """z of the object's top surface, m."""
        return self.position[2] + self.half_height

    @property
    def bottom(self) -> float:
        """z of the object's lowest point, m."""
        return self.position[2] - self.half_height

    @property
    def width(self) -> float:
        """Horizontal extent a gripper closes on, m (the smaller horizontal size)."""
        if self.shape == "box":
            return min(self.size[0], self.size[1])
        return 2 * self.size[0]

    def shapes(self) -> list[Shape]:
        pose = np.eye(4)
        pose[:3, :3] = rpy_matrix(self.rpy)
        pose[:3, 3] = self.position
        return [Shape(self.id, self.id, self.shape, tuple(self.size), pose)]

    def moved_to(self, position: Vec3, rpy: Vec3 | None = None) -> "SceneObject":
        return self.model_copy(update={"position": tuple(float(v) for v in position), "rpy": rpy or self.rpy})


class Container(_Model):
    """An open-top box: a floor and four walls; the inside is free space."""

    id: str = Field(min_length=1)
    size: Vec3 = Field(description="outer extents [x, y, z], m")
    position: Vec3 = Field(description="centre of the outer box, m, base frame")
    yaw: float = Field(0.0, description="rotation about z, rad")
    wall_m: float = Field(0.005, gt=0, description="wall and floor thickness, m")
    attributes: dict[str, Any] = Field(default_factory=dict)

    @field_validator("position")
    @classmethod
    def _check_finite(cls, v: Vec3) -> Vec3:
        return _finite(v, "position")

    @field_validator("size")
    @classmethod
    def _check_size(cls, v: Vec3) -> Vec3:
        for i, s in enumerate(v):
            if not math.isfinite(s) or s <= 0:
                raise ValueError(f"[{i}]: {s} is not a positive length in metres")
        return v

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
        local = rpy_matrix((0, 0, self.yaw)).T @ (np.asarray(point, float) - np.asarray(self.position))
        hx, hy = self.size[0] / 2 - self.wall_m, self.size[1] / 2 - self.wall_m
        return bool(
            abs(local[0]) <= hx + margin_m
            and abs(local[1]) <= hy + margin_m
            and self.floor_top - margin_m <= point[2] <= self.top + margin_m
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

    top_z: float = Field(0.0, description="m")
    size: tuple[float, float] = Field((1.6, 1.2), description="x, y extents, m")
    center_xy: tuple[float, float] = (0.0, 0.0)
    thickness_m: float = Field(0.04, gt=0)

    def shapes(self) -> list[Shape]:
        pose = np.eye(4)
        pose[:3, 3] = (self.center_xy[0], self.center_xy[1], self.top_z - self.thickness_m / 2)
        return [Shape("table", "table", "box", (self.size[0], self.size[1], self.thickness_m), pose)]


class Workspace(_Model):
    """The allowed workspace W_allowed: a sphere (m) above the plane ``min_z``."""

    center: Vec3 = Field((0.0, 0.0, UR3E.dh.d1), description="sphere centre, m (default: UR3e shoulder)")
    radius_m: float = Field(0.5, gt=0, description="sphere radius, m (default: UR3e reach)")

    @property
    def volume_m3(self) -> float:
        """Volume of the allowed workspace, m^3 (the whole sphere, as the paper's 0.523 m^3)."""
        return 4.0 / 3.0 * math.pi * self.radius_m**3

    def outside_distance(self, points: np.ndarray) -> np.ndarray:
        """How far each point ``(..., 3)`` lies outside the sphere, m (<= 0 inside): ``|p - c| - r``.

        Evaluated component-wise: a norm over a length-3 axis is several times slower in
        numpy, and critics call this on every link of every sample.
        """
        points = np.asarray(points, dtype=float)
        c = self.center
        dx = points[..., 0] - c[0]
        dy = points[..., 1] - c[1]
        dz = points[..., 2] - c[2]
        dx *= dx
        dy *= dy
        dz *= dz
        dx += dy
        dx += dz
        if isinstance(dx, np.ndarray):
            np.sqrt(dx, out=dx)
        else:  # a single point
            dx = np.sqrt(dx)
        return dx - self.radius_m


class Scene(_Model):
    """A complete task scene; see the module docstring for conventions."""

    name: str = "scene"
    description: str = ""
    objects: list[SceneObject] = Field(default_factory=list)
    containers: list[Container] = Field(default_factory=list)
    table: Table = Field(default_factory=Table)
    workspace: Workspace = Field(default_factory=Workspace)

    @model_validator(mode="after")
    def _check_ids(self) -> "Scene":
        seen: dict[str, str] = {"table": "table"}
        for group in ("objects", "containers"):
            for i, item in enumerate(getattr(self, group)):
                if item.id in seen:
                    raise ValueError(f"{group}[{i}].id: duplicate id {item.id!r} (already used by {seen[item.id]})")
                if not item.id.isidentifier() or item.id.startswith("_"):
                    raise ValueError(
                        f"{group}[{i}].id: {item.id!r} must be a Python identifier not starting with '_' "
                        "(programs refer to objects by name)"
                    )
                seen[item.id] = f"{group}[{i}]"
        return self

    # --- construction -----------------------------------------------------------------

    @classmethod
    def model_validate(cls, obj: Any, *args: Any, **kwargs: Any) -> "Scene":  # type: ignore[override]
        """Validate a dict; raise :class:`SceneError` naming the first bad field."""
        try:
            return super().model_validate(obj, *args, **kwargs)
        except ValidationError as exc:
            raise _scene_error(exc) from None

    @classmethod
    def load(cls, path: str | Path) -> "Scene":
        """Load a scene from a JSON file."""
        path = Path(path)
        try:
            data = json.loads(path.read_text())
        except FileNotFoundError:
            raise SceneError(f"no such scene file {str(path)!r}") from None
        except json.JSONDecodeError as exc:
            raise SceneError(f"{path}: not valid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}") from None
        if not isinstance(data, dict):
            raise SceneError(f"{path}: a scene is a JSON object, got {type(data).__name__}")
        return cls.model_validate(data)

    @classmethod
    def builtin_names(cls) -> list[str]:
        return sorted(p.name[:-5] for p in resources.files("robocritics.scenes").iterdir() if p.name.endswith(".json"))

    @classmethod
    def builtin(cls, name: str) -> "Scene":
        """One of the paper's task scenes: ``recycling``, ``sorting`` or ``breakfast``."""
        names = cls.builtin_names()
        if name not in names:
            raise SceneError(f"no built-in scene {name!r} (have {', '.join(names)}){did_you_mean(name, names)}")
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


def _scene_error(exc: ValidationError) -> SceneError:
    err = exc.errors()[0]
    path = ""
    for part in err["loc"]:
        if isinstance(part, int):
            path += f"[{part}]"
        else:
            path += ("." if path else "") + str(part)
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
        message = f"unknown shape {err.get('input')!r}; use one of box, cylinder, sphere"
    more = len(exc.errors()) - 1
    if more:
        message += f" (and {more} more problem{'s' if more > 1 else ''})"
    return SceneError(message, path=path or "scene")
