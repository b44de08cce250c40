"""The skill API a language model writes robot programs against.

Every skill's docstring is written for the model: it is pasted verbatim into
the system prompt by :func:`api_reference`. Calling a skill does not move the
robot: it validates and normalises the arguments and records a
:class:`~robocritics.program.plan.SkillCall` into the plan being built (see
:mod:`robocritics.program.plan` for the argument formats). Bad arguments raise
:class:`~robocritics.errors.ProgramError` at the calling line.

Skills are normally called from a program run by
:func:`robocritics.program.run_program`. Trusted Python code can also record a
plan directly::

    with recording(Scene.builtin("sorting")) as plan:
        move_above("green_apple")
        move_to("green_apple")
        close_gripper()

Units: metres, radians, seconds; percent only where the name says so.
"""

from __future__ import annotations

import contextvars
import copy
import inspect
import math
import numbers
import sys
import textwrap
from contextlib import contextmanager
from typing import Any, Callable, Iterator, Mapping

from .._suggest import did_you_mean
from ..errors import ProgramError
from ..scene import MAX_COORD_M, Container, Scene, SceneObject
from .budget import Budget, BudgetError
from .language import SAFE_BUILTINS
from .plan import MIN_SPEED_FRACTION, Plan, SkillCall
from .render import VALUE_CHARS, bounded_repr, clip

__all__ = [
    "SKILLS",
    "ObjectView",
    "Namespace",
    "Recorder",
    "recording",
    "api_reference",
    "move_to",
    "move_linear",
    "move_above",
    "move_up",
    "move_down",
    "open_gripper",
    "close_gripper",
    "rotate_gripper",
    "reduce_speed",
    "set_speed",
    "avoid_collision",
    "home",
    "wait",
    "expect",
    "print",
]

"""Largest |coordinate| accepted, m: ten times any tabletop arm's reach, so millimetres given as metres are caught."""
_MAX_MOVE_M = 1.0
"""Largest relative move or clearance (move_up/move_down dz, move_above height), m: more than a UR3e's reach."""
_MAX_WAIT_S = 10.0
"""Longest wait(), s: a pause in a pick-and-place task, not a way to stall the robot."""
_DESCRIBED_STR_CHARS = 40
"""Strings quoted in argument errors are cut to this length."""


def _suggest(name: str, candidates: Any, n: int = 3) -> str:
    """Up to ``n`` close names (:func:`robocritics._suggest.did_you_mean`)."""
    return did_you_mean(name, candidates, n)


_MAX_SUGGESTION_CANDIDATES = 300
"""A did-you-mean compares a name with at most this many candidates (those closest to it in length)."""


def _close_names(name: Any, candidates: Any, n: int = 3) -> str:
    """:func:`_suggest` bounded for untrusted names: names longer than ``VALUE_CHARS`` get no suggestion (nobody
    mistypes them and comparing them is slow), and at most ``_MAX_SUGGESTION_CANDIDATES`` candidates of a
    similar length are compared."""
    if type(name) is not str or len(name) > VALUE_CHARS:
        return ""
    near = [c for c in candidates if type(c) is str and len(name) // 2 <= len(c) <= 2 * len(name) + 2]
    if len(near) > _MAX_SUGGESTION_CANDIDATES:
        near = sorted(near, key=lambda c: abs(len(c) - len(name)))[:_MAX_SUGGESTION_CANDIDATES]
    return _suggest(name, near, n)


def _plain(value: Any) -> Any:
    """A deep copy of JSON-like scene data (dicts, lists, scalars) as plain Python values."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return copy.deepcopy(value)


# --------------------------------------------------------------------------------------
# read-only values a program sees


class ObjectView:
    """A read-only view of one scene object or container, as a program sees it.

    Fields (metres, robot base frame, z up; values are those of the INITIAL scene,
    they do not follow an object the robot has moved; skills that take an object
    use its current position at that point of the motion):

    * ``id`` (also ``name``): the object's name, e.g. ``'green_apple'``
    * ``kind``: ``'object'`` or ``'container'``
    * ``shape``: ``'box'``, ``'cylinder'``, ``'sphere'`` or ``'container'``
    * ``position``: centre ``(x, y, z)``; ``x``, ``y``, ``z`` the same one by one
    * ``size``: the shape's size tuple (box ``(x, y, z)``, cylinder ``(radius, height)``,
      sphere ``(radius,)``, container outer ``(x, y, z)``)
    * ``top``: z of the top surface (a container's rim); ``bottom``: z of its lowest point
    * ``height``: vertical extent; ``width``: the horizontal extent a gripper closes on
    * ``graspable``: whether the gripper can pick it up (containers: ``False``)
    * ``floor`` (containers only): z of the inside floor surface
    * ``attributes``: a copy of the free attributes dict, e.g. ``{'colour': 'green'}``;
      each attribute is also a field: ``green_apple.colour``, ``green_apple.ripeness``
    """

    __slots__ = ("_id", "_fields", "_attrs")

    def __init__(self, entity: SceneObject | Container):
        fields: dict[str, Any] = {"id": entity.id, "name": entity.id}
        # a mesh's position is its file's origin: programs get its centre, as for every other shape
        pos = tuple(float(v) for v in (entity.position if isinstance(entity, Container) else entity.centre))
        if isinstance(entity, Container):
            size = tuple(float(v) for v in entity.size)
            fields.update(
                kind="container",
                shape="container",
                position=pos,
                x=pos[0],
                y=pos[1],
                z=pos[2],
                size=size,
                top=float(entity.top),
                bottom=float(entity.bottom),
                height=size[2],
                width=min(size[0], size[1]),
                graspable=False,
                floor=float(entity.floor_top),
            )
        else:
            fields.update(
                kind="object",
                shape=entity.shape,
                position=pos,
                x=pos[0],
                y=pos[1],
                z=pos[2],
                size=tuple(float(v) for v in entity.size),
                top=float(entity.top),
                bottom=float(entity.bottom),
                height=2.0 * float(entity.half_height),
                width=float(entity.width),
                graspable=bool(entity.graspable),
            )
        object.__setattr__(self, "_id", entity.id)
        object.__setattr__(self, "_fields", fields)
        object.__setattr__(self, "_attrs", _plain(dict(entity.attributes)))

    def _names(self) -> list[str]:
        extra = [k for k in self._attrs if isinstance(k, str) and k.isidentifier() and not k.startswith("_")]
        return [*self._fields, "attributes", *[k for k in extra if k not in self._fields]]

    def _lookup(self, name: str) -> Any:
        """The value of field or attribute ``name``; AttributeError with suggestions otherwise."""
        if name in self._fields:
            return self._fields[name]
        if name == "attributes":
            return _plain(self._attrs)
        if name in self._attrs and not name.startswith("_"):
            return _plain(self._attrs[name])
        names = self._names()
        hint = _close_names(name, names, 1)
        raise AttributeError(
            f"{self._fields['kind']} {self._id!r} has no attribute {bounded_repr(name)}{hint or '.'} "
            f"It has: {', '.join(names)}"
        )

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        return self._lookup(name)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"scene objects are read-only; cannot set {self._id}.{name}")

    def __delattr__(self, name: str) -> None:
        raise AttributeError(f"scene objects are read-only; cannot delete {self._id}.{name}")

    def __eq__(self, other: object) -> bool:
        return isinstance(other, ObjectView) and other._id == self._id

    def __hash__(self) -> int:
        return hash(("ObjectView", self._id))

    def __repr__(self) -> str:
        return self._id

    __str__ = __repr__

    def __format__(self, spec: str) -> str:
        return format(self._id, spec)


class Namespace:
    """A read-only module-like namespace (``lib``, ``math``) visible to programs."""

    __slots__ = ("_name", "_members", "_what")

    def __init__(self, name: str, members: Mapping[str, Any], what: str = "member"):
        object.__setattr__(self, "_name", name)
        object.__setattr__(self, "_members", dict(members))
        object.__setattr__(self, "_what", what)

    def _lookup(self, name: str) -> Any:
        if name in self._members and not name.startswith("_"):
            return self._members[name]
        hint = _close_names(name, self._members, 3)
        raise AttributeError(
            f"{self._name} has no {self._what} {bounded_repr(name)}{hint or '.'} "
            f"{self._name} provides: {', '.join(sorted(self._members))}"
        )

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        return self._lookup(name)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"{self._name} is read-only")

    def __repr__(self) -> str:
        return f"<module {self._name!r}>"


def views_of(scene: Scene) -> dict[str, ObjectView]:
    """ObjectViews of every object and container of ``scene``, by id."""
    out: dict[str, ObjectView] = {}
    for item in (*scene.objects, *scene.containers):
        out[item.id] = ObjectView(item)
    return out


# --------------------------------------------------------------------------------------
# recording


class Recorder:
    """Collects the skill calls of one program run into a :class:`Plan`.

    ``where`` is ``(line, col, call_stack)`` of the skill call being made; the
    sandbox sets it before every call. In ``direct`` mode (plain Python, see
    :func:`recording`) it is taken from the caller's frame. ``budget`` gives the
    limits on skill calls and printed characters.
    """

    def __init__(self, scene: Scene, plan: Plan, budget: Budget, direct: bool = False):
        self.scene = scene
        self.plan = plan
        self.views = views_of(scene)
        self.max_skill_calls = budget.max_skill_calls
        self.max_output_chars = budget.max_output_chars
        self.output_chars = 0
        self.direct = direct
        self.where: tuple[int, int, tuple[int, ...]] = (0, 0, ())

    def error(self, message: str, limit: str = "") -> ProgramError:
        """The error at the skill call being made (a :class:`BudgetError` when ``limit`` names a Budget field)."""
        line, col, _ = self.where
        if limit:
            return BudgetError(clip(message), line, col, limit=limit)
        return ProgramError(clip(message), line, col)

    def record(self, skill: str, args: dict[str, Any]) -> None:
        if len(self.plan.calls) >= self.max_skill_calls:
            raise self.error(
                f"the program makes more than {self.max_skill_calls} skill calls; a robot task needs far fewer. "
                "Is a loop running more often than intended?",
                limit="max_skill_calls",
            )
        line, col, stack = self.where
        self.plan.calls.append(SkillCall(skill, args, line, col, stack))

    def add_output(self, text: str) -> None:
        self.output_chars += len(text)
        if self.output_chars > self.max_output_chars:
            raise self.error(f"the program printed more than {self.max_output_chars} characters", "max_output_chars")
        self.plan.output.append(text)

    def object_id(self, value: Any, skill: str, arg: str) -> str:
        """The id of the scene object/container ``value`` (an ObjectView or an id string)."""
        if isinstance(value, ObjectView):
            if value._id in self.views:
                return value._id
            raise self.error(f"{skill}: {value._id!r} is not an object of this scene")
        if isinstance(value, str):
            if value in self.views:
                return value
            hint = _close_names(value, self.views)
            raise self.error(
                f"{skill}: unknown object {bounded_repr(value)}{hint or '.'} "
                f"Objects and containers: {', '.join(self.views) or '(none)'}"
            )
        raise self.error(f"{skill}: {arg} must be a scene object (e.g. {self._example()}), got {_describe(value)}")

    def _example(self) -> str:
        return next(iter(self.views), "green_apple")


_CURRENT: contextvars.ContextVar[Recorder | None] = contextvars.ContextVar("robocritics_recorder", default=None)


@contextmanager
def recording(scene: Scene, plan: Plan | None = None, budget: Budget | None = None) -> Iterator[Plan]:
    """Record skill calls made by trusted Python code into a Plan (line numbers from the caller).

    ``budget`` limits skill calls and printed characters as in a sandboxed run.
    """
    plan = plan if plan is not None else Plan()
    token = _CURRENT.set(Recorder(scene, plan, budget or Budget(), direct=True))
    try:
        yield plan
    finally:
        _CURRENT.reset(token)


def _rec() -> Recorder:
    rec = _CURRENT.get()
    if rec is None:
        raise ProgramError(
            "skills only record into a plan: run the program with robocritics.program.run_program(source, scene) "
            "or call skills inside `with recording(scene):`"
        )
    if rec.direct:
        frame = sys._getframe(2)
        rec.where = (frame.f_lineno, 0, ())
    return rec


def _describe(value: Any) -> str:
    if isinstance(value, ObjectView):
        return f"scene object {value._id}"
    if isinstance(value, str):
        text = value if len(value) <= _DESCRIBED_STR_CHARS else value[: _DESCRIBED_STR_CHARS - 3] + "..."
        return f"str {text!r}"
    if isinstance(value, (bool, int, float)):
        return f"{type(value).__name__} {bounded_repr(value)}"
    name = type(value).__name__
    return _DESCRIBED_TYPES.get(name, f"a {name}")


_DESCRIBED_TYPES = {
    "function": "a function",
    "_SandboxFunction": "a function",
    "_Builtin": "a builtin function",
    "_Method": "a method",
    "Namespace": "a module",
}
"""What the interpreter's own types are called in skill messages (their class names are internals)."""


def _number(rec: Recorder, value: Any, skill: str, arg: str, unit: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        hint = ""
        if isinstance(value, str):
            try:
                float(value)
                hint = f"; write {value} without quotes"
            except ValueError:
                pass
        raise rec.error(f"{skill}: {arg} must be a number ({unit}), got {_describe(value)}{hint}")
    v = float(value)
    if not math.isfinite(v):
        raise rec.error(f"{skill}: {arg} is {v}; it must be a finite number ({unit})")
    return v


def _coord(rec: Recorder, value: Any, skill: str, arg: str) -> float:
    v = _number(rec, value, skill, arg, "metres")
    if abs(v) > MAX_COORD_M:
        raise rec.error(
            f"{skill}: {arg}={bounded_repr(value)} m is far outside any robot's reach; coordinates are in metres "
            f"(did you mean {v / 1000:g}?)"
        )
    return v


def _point(rec: Recorder, value: Any, skill: str, arg: str) -> tuple[float, float, float]:
    if isinstance(value, (list, tuple)):
        if len(value) != 3:
            raise rec.error(f"{skill}: a point needs 3 coordinates (x, y, z) in metres, got {len(value)}")
        return tuple(_coord(rec, v, skill, f"{arg}[{i}]") for i, v in enumerate(value))  # type: ignore[return-value]
    raise rec.error(f"{skill}: {arg} must be a point (x, y, z) in metres or a scene object, got {_describe(value)}")


def _place(rec: Recorder, skill: str, x: Any, y: Any, z: Any) -> dict[str, Any]:
    """Arguments of move_to / move_linear: three numbers, one point, or one object."""
    if y is None and z is None:
        if isinstance(x, (ObjectView, str)):
            return {"object": rec.object_id(x, skill, "the target")}
        if isinstance(x, (list, tuple)):
            return {"target": _point(rec, x, skill, "point")}
        raise rec.error(
            f"{skill} needs three coordinates {skill}(x, y, z) in metres, one point {skill}((x, y, z)) "
            f"or one scene object {skill}({rec._example()}); got only {_describe(x)}"
        )
    if y is None or z is None:
        raise rec.error(f"{skill} needs all three coordinates x, y, z in metres (or a single point or object)")
    if isinstance(x, (ObjectView, list, tuple)):
        raise rec.error(f"{skill}: give either one point/object or three numbers x, y, z, not both")
    return {"target": (_coord(rec, x, skill, "x"), _coord(rec, y, skill, "y"), _coord(rec, z, skill, "z"))}


def _dz(rec: Recorder, dz: Any, skill: str) -> float:
    v = _number(rec, dz, skill, "dz", "metres")
    if v <= 0:
        other = "move_down" if skill == "move_up" else "move_up"
        raise rec.error(f"{skill}: dz must be a positive distance in metres, got {v:g}; use {other} to go the other way")
    if v > _MAX_MOVE_M:
        raise rec.error(
            f"{skill}: dz={v:g} m is more than {_MAX_MOVE_M:g} m; distances are in metres (did you mean {v / 1000:g}?)"
        )
    return v


#: Arm postures a joint-space move may ask for (see move_to); "nearest" is the default and is not recorded.
POSTURES = ("nearest", "natural")


def _posture(rec: Recorder, posture: Any, skill: str) -> dict[str, Any]:
    """``{"posture": p}`` for a posture other than the default, ``{}`` for "nearest"; else a ProgramError."""
    if not isinstance(posture, str) or posture not in POSTURES:
        raise rec.error(
            f"{skill}: posture must be one of {', '.join(repr(p) for p in POSTURES)}, got {_describe(posture)}"
            f"{did_you_mean(posture, POSTURES) if isinstance(posture, str) else ''}"
        )
    return {} if posture == "nearest" else {"posture": posture}


# --------------------------------------------------------------------------------------
# the skills


def move_to(x, y=None, z=None, *, posture="nearest"):
    """Move the fingertip centre (TCP) to a point, fingers pointing down, along a joint-space path (fast, curved).

    Args:
        x, y, z: target in metres, robot base frame (x forward, y left, z up; table top z = 0).
            Instead of three numbers you may pass one point (x, y, z) or a scene object,
            which moves the fingertips to the object's centre (ready to close the gripper).
        posture: "nearest" (default: the arm posture closest to its current joints, which may
            reach back over the shoulder) or "natural" (shoulder facing the target, elbow up,
            wrist down, as at home: the base turns as far as needed; use it against pinch points).
    Example:
        move_to(0.3, 0.1, 0.2)
        move_to(green_apple)
        move_to(-0.1, -0.3, 0.1, posture="natural")
    """
    rec = _rec()
    rec.record("move_to", {**_place(rec, "move_to", x, y, z), **_posture(rec, posture, "move_to")})


def move_linear(x, y=None, z=None):
    """Move the fingertip centre (TCP) to a point along a straight line, fingers pointing down.

    Use it for the last few centimetres of an approach or to lift straight up.
    Args:
        x, y, z: target in metres, robot base frame; or one point (x, y, z); or a scene object (its centre).
    Example:
        move_linear(0.3, 0.1, 0.05)
        move_linear(green_apple)
    """
    rec = _rec()
    rec.record("move_linear", _place(rec, "move_linear", x, y, z))


def move_above(obj, height=0.1, *, posture="nearest"):
    """Move the fingertips to `height` metres above the top of an object or container (joint-space move).

    Args:
        obj: a scene object or container (e.g. green_apple, white_box), or a point (x, y, z),
            in which case the fingertips go to `height` m above that point.
        height: clearance above the object's top in metres (default 0.1, must be 0..1).
        posture: "nearest" (default) or "natural" (shoulder facing the target, elbow up, wrist down), as for move_to.
    Example:
        move_above(green_apple)            # 10 cm above the apple
        move_above(white_box, height=0.05)
    """
    rec = _rec()
    h = _number(rec, height, "move_above", "height", "metres")
    if h < 0:
        raise rec.error(f"move_above: height must be >= 0 m above the top, got {h:g}; use move_to to go lower")
    if h > _MAX_MOVE_M:
        raise rec.error(
            f"move_above: height={h:g} m is more than {_MAX_MOVE_M:g} m; heights are in metres "
            f"(did you mean {h / 1000:g}?)"
        )
    if isinstance(obj, (ObjectView, str)):
        args: dict[str, Any] = {"object": rec.object_id(obj, "move_above", "obj"), "height": h}
    elif isinstance(obj, (list, tuple)):
        args = {"target": _point(rec, obj, "move_above", "point"), "height": h}
    else:
        raise rec.error(
            f"move_above takes a scene object or a point (x, y, z) and an optional height, got {_describe(obj)}; "
            f"e.g. move_above({rec._example()}, height=0.1) or move_above((0.3, 0.1, 0.0))"
        )
    rec.record("move_above", {**args, **_posture(rec, posture, "move_above")})


def move_up(dz):
    """Move the fingertips straight up by dz metres (straight-line move).

    Args:
        dz: distance in metres, 0 < dz <= 1.
    Example:
        move_up(0.1)    # lift 10 cm
    """
    rec = _rec()
    rec.record("move_up", {"dz": _dz(rec, dz, "move_up")})


def move_down(dz):
    """Move the fingertips straight down by dz metres (straight-line move).

    Args:
        dz: distance in metres, 0 < dz <= 1.
    Example:
        move_down(0.05)   # lower 5 cm
    """
    rec = _rec()
    rec.record("move_down", {"dz": _dz(rec, dz, "move_down")})


def open_gripper():
    """Open the gripper fully, releasing whatever it holds.

    Example:
        open_gripper()
    """
    _rec().record("open_gripper", {})


def close_gripper():
    """Close the gripper; if an object is between the fingers it is grasped and moves with the gripper.

    Example:
        move_to(green_apple)
        close_gripper()
    """
    _rec().record("close_gripper", {})


def rotate_gripper(angle):
    """Rotate the fingers about the vertical axis to an absolute angle (yaw) in radians.

    Angle 0 means the fingers close along the robot base y axis.
    Args:
        angle: radians, -2*pi..2*pi. Convert degrees with math.radians(90).
    Example:
        rotate_gripper(math.radians(90))   # fingers now close along x
    """
    rec = _rec()
    a = _number(rec, angle, "rotate_gripper", "angle", "radians")
    if abs(a) > 2 * math.pi:
        raise rec.error(
            f"rotate_gripper: angle {a:g} is more than a full turn; angle is in radians; use math.radians({a:g})"
        )
    rec.record("rotate_gripper", {"angle": a})


def reduce_speed(percent):
    """Set the speed of the following moves to `percent` % of full speed (absolute, not cumulative).

    Args:
        percent: 1 <= percent <= 100. reduce_speed(100) restores full speed.
    Example:
        reduce_speed(30)    # careful moves near people or fragile objects
    """
    rec = _rec()
    p = _number(rec, percent, "reduce_speed", "percent", "percent of full speed")
    if not MIN_SPEED_FRACTION * 100 <= p <= 100:
        raise rec.error(f"reduce_speed: percent must be in {MIN_SPEED_FRACTION * 100:g} <= percent <= 100, got {p:g}")
    rec.record("reduce_speed", {"fraction": p / 100.0})


def set_speed(fraction):
    """Set the speed of the following moves as a fraction of full speed (absolute).

    Args:
        fraction: 0.01 <= fraction <= 1 (1 = full speed).
    Example:
        set_speed(0.5)    # half speed
    """
    rec = _rec()
    f = _number(rec, fraction, "set_speed", "fraction", "fraction of full speed")
    if not MIN_SPEED_FRACTION <= f <= 1:
        hint = f"; for percent use reduce_speed({f:g})" if 1 < f <= 100 else ""
        raise rec.error(f"set_speed: fraction must be in {MIN_SPEED_FRACTION:g} <= fraction <= 1, got {f:g}{hint}")
    rec.record("set_speed", {"fraction": f})


def avoid_collision(obj):
    """Treat a scene object or container as an obstacle: later moves route above it with clearance.

    Args:
        obj: a scene object or container.
    Example:
        avoid_collision(white_box)
    """
    rec = _rec()
    rec.record("avoid_collision", {"object": rec.object_id(obj, "avoid_collision", "obj")})


def expect(obj, inside=None, on=None):
    """State where an object should end up; the task_outcome critic checks it on the final scene. No motion.

    Give exactly one of ``inside`` (a container) or ``on`` (another object, or "table").

    Args:
        obj: a scene object.
        inside: the container it should end in.
        on: the object it should rest on, or "table".
    Example:
        expect(green_apple, inside=white_box)
    """
    rec = _rec()
    oid = rec.object_id(obj, "expect", "obj")
    if (inside is None) == (on is None):
        raise rec.error("expect: give exactly one of inside=<container> or on=<object or 'table'>")
    if inside is not None:
        relation, target = "in", rec.object_id(inside, "expect", "inside")
    elif isinstance(on, str) and on == "table":
        relation, target = "on", "table"
    else:
        relation, target = "on", rec.object_id(on, "expect", "on")
    from ..goals import Goal, GoalError

    try:  # inside= a container, on= an object: the task_outcome critic can only check those
        Goal(object=oid, relation=relation, target=target).check(rec.scene)
    except GoalError as exc:
        raise rec.error(f"expect: {exc}") from None
    rec.record("expect", {"object": oid, "relation": relation, "target": target})


def home():
    """Move back to the robot's home pose (joint-space move).

    Example:
        home()
    """
    _rec().record("home", {})


def wait(seconds):
    """Stay still for a number of seconds.

    Args:
        seconds: 0 <= seconds <= 10.
    Example:
        wait(0.5)
    """
    rec = _rec()
    s = _number(rec, seconds, "wait", "seconds", "seconds")
    if not 0 <= s <= _MAX_WAIT_S:
        raise rec.error(f"wait: seconds must be in 0..{_MAX_WAIT_S:g}, got {s:g}")
    rec.record("wait", {"seconds": s})


def print(*values, sep=" "):  # noqa: A001 - the program-facing print
    """Write a message to the program's output log (not to a terminal); the log is shown with the results.

    Example:
        print("picking", green_apple, "at", green_apple.position)
    """
    rec = _rec()
    rec.add_output(str(sep).join(str(v) for v in values))


SKILLS: dict[str, Callable[..., None]] = {
    f.__name__: f
    for f in (
        move_to,
        move_linear,
        move_above,
        move_up,
        move_down,
        open_gripper,
        close_gripper,
        rotate_gripper,
        reduce_speed,
        set_speed,
        avoid_collision,
        home,
        wait,
        expect,
    )
}
"""The motion skills by name. Every one of them records a SkillCall; ``print`` is separate."""

_USAGE = {
    "move_to": "move_to(x, y, z)  |  move_to(point)  |  move_to(obj)",
    "move_linear": "move_linear(x, y, z)  |  move_linear(point)  |  move_linear(obj)",
    # posture= (move_to, move_above) is in their docstrings; the short signature stays as before
    "move_above": "move_above(obj, height=0.1)",
}


def usage(name: str) -> str:
    """The call signature of a skill (or ``print``) as shown to the model."""
    if name in _USAGE:
        return _USAGE[name]
    fn = SKILLS.get(name) or (print if name == "print" else None)
    if fn is None:
        raise KeyError(name)
    return f"{name}{inspect.signature(fn)}"


_PREAMBLE = """\
# Robot program API

Write a Python program that calls the skills below, one motion at a time. The
program is checked and simulated before the robot moves.

Conventions: lengths in metres, angles in radians, times in seconds. Coordinates
are in the robot base frame: x forward, y left, z up; the table top is z = 0.
The fingertips point down in every move.

{language}

Scene objects and containers are variables named by their id (e.g.
`green_apple`, `white_box`); `objects` lists all objects and `containers` all
containers. They are read-only. Fields: `id`, `position` (x, y, z of the centre),
`x`, `y`, `z`, `size`, `top` (z of the top surface / container rim), `bottom`,
`height`, `width`, `graspable`, `kind`, `floor` (containers: inside floor z),
`attributes` (dict), and every attribute by name (`green_apple.colour`,
`green_apple.ripeness`). Positions are those of the INITIAL scene; they do not
follow an object after the robot moves it. Skills that take an object always use
its current position.

Example:

    for apple in objects:
        if apple.ripeness == "ripe":
            move_above(apple)
            open_gripper()
            move_to(apple)
            close_gripper()
            move_up(0.1)
            move_above(brown_box, height=0.05)
            open_gripper()
    home()
"""


def _language_rules() -> str:
    """What a program may use besides the skills; the builtins are the sandbox's own list."""
    return textwrap.fill(
        "Call skills directly (`move_to(...)`) or through `lib` (`lib.move_to(...)`). `math` is available "
        "(`import math` / `from math import pi` also work). You may define helper functions, use variables, "
        "lists, dicts, loops, `if`, f-strings and the builtins " + ", ".join(SAFE_BUILTINS) + ". Other imports, "
        "classes, try/except, files and names starting with `_` are not available.",
        width=80,
        break_on_hyphens=False,
    )


def api_reference() -> str:
    """All skill signatures and docstrings plus the language rules, for the model's system prompt."""
    parts = [_PREAMBLE.format(language=_language_rules()), "## Skills\n"]
    for name, fn in [*SKILLS.items(), ("print", print)]:
        doc = inspect.cleandoc(fn.__doc__ or "")
        body = "\n".join("    " + line if line else "" for line in doc.splitlines())
        parts.append(f"{usage(name)}\n{body}\n")
    return "\n".join(parts)
