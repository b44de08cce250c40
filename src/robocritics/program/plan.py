"""The Plan: what a robot program asked the robot to do, one skill call at a time.

Running a program in the sandbox (:func:`robocritics.program.run_program`) does
not move anything: every skill call is validated, normalised and recorded as a
:class:`SkillCall`. The motion planner turns the recorded calls into a
trajectory; each call keeps the source line that made it so critics can point
back at the program.

Argument formats (``SkillCall.args``; lengths in metres, angles in radians,
times in seconds, speeds as a fraction of full speed):

=====================  ===========================================================
skill                  args
=====================  ===========================================================
``move_to``            ``{"target": (x, y, z)}`` or ``{"object": id}`` (object centre); ``"posture": "natural"``
                       when asked for (absent: the default, ``"nearest"``)
``move_linear``        ``{"target": (x, y, z)}`` or ``{"object": id}`` (no posture: the line fixes it)
``move_above``         ``{"object": id, "height": h}`` or ``{"target": (x, y, z), "height": h}``, and
                       ``"posture"`` as for ``move_to``
``move_up``            ``{"dz": dz}`` (``0 < dz <= 1``)
``move_down``          ``{"dz": dz}`` (``0 < dz <= 1``)
``open_gripper``       ``{}``
``close_gripper``      ``{}``
``rotate_gripper``     ``{"angle": a}`` (absolute yaw, ``|a| <= 2*pi``)
``reduce_speed``       ``{"fraction": percent / 100}``
``set_speed``          ``{"fraction": f}`` (``0 < f <= 1``)
``avoid_collision``    ``{"object": id}``
``home``               ``{}``
``wait``               ``{"seconds": s}`` (``0 <= s <= 10``)
``expect``             ``{"object": id, "relation": "in" | "on", "target": id | "table"}`` (no motion)
=====================  ===========================================================

Numbers are Python ``float``; points are tuples of three floats; object ids
are ``str`` (ids of scene objects or containers).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

MIN_SPEED_FRACTION = 0.01
"""Slowest speed fraction (1 % of full speed): slower moves stretch a 1 s move past a minute, and far below it
ruckig's profiles leave their numerical range (at 1e-5 a short UR3e move can no longer be timed)."""

__all__ = ["SkillCall", "Plan", "FrozenArgs"]


class FrozenArgs(dict):
    """A read-only, hashable ``dict`` of normalised skill arguments."""

    __slots__ = ()

    def _readonly(self, *args: Any, **kwargs: Any) -> None:
        raise TypeError("skill call arguments are read-only")

    __setitem__ = __delitem__ = _readonly  # type: ignore[assignment]
    clear = pop = popitem = setdefault = update = _readonly  # type: ignore[assignment]

    def __ior__(self, other: Any) -> "FrozenArgs":  # type: ignore[override]
        raise TypeError("skill call arguments are read-only")

    def __hash__(self) -> int:  # type: ignore[override]
        return hash(tuple(sorted(self.items())))

    def __reduce__(self) -> tuple:
        return (FrozenArgs, (dict(self),))

    def __copy__(self) -> "FrozenArgs":
        return self

    def __deepcopy__(self, memo: dict) -> "FrozenArgs":
        return self

    def __repr__(self) -> str:
        return f"FrozenArgs({dict.__repr__(self)})"


def _num(v: float) -> str:
    return f"{v:.4g}"


def _point(p: tuple[float, float, float]) -> str:
    return f"x={_num(p[0])}, y={_num(p[1])}, z={_num(p[2])}"


@dataclass(frozen=True)
class SkillCall:
    """One recorded skill call.

    ``line``/``col`` (1-based) locate the call expression itself, even when it
    sits inside a helper function; ``call_stack`` holds the lines of the
    enclosing user-function calls, outermost first (``()`` at top level).
    """

    skill: str
    args: Mapping[str, Any]
    line: int
    col: int = 0
    call_stack: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.args, FrozenArgs):
            object.__setattr__(self, "args", FrozenArgs(self.args))
        if not isinstance(self.call_stack, tuple):
            object.__setattr__(self, "call_stack", tuple(self.call_stack))

    def describe(self) -> str:
        """The call in program syntax with normalised arguments, e.g. ``move_to(x=0.3, y=0.1, z=0.2)``."""
        a = self.args
        s = self.skill
        if s in ("move_to", "move_linear"):
            inner = a["object"] if "object" in a else _point(a["target"])
        elif s == "move_above":
            where = a["object"] if "object" in a else _point(a["target"])
            inner = f"{where}, height={_num(a['height'])}"
        elif s == "avoid_collision":
            inner = str(a["object"])
        elif s == "reduce_speed":
            inner = f"percent={_num(a['fraction'] * 100)}"
        else:
            parts = []
            for k, v in a.items():
                if isinstance(v, float):
                    parts.append(f"{k}={_num(v)}")
                elif isinstance(v, tuple):
                    parts.append(f"{k}=({', '.join(_num(x) for x in v)})")
                else:
                    parts.append(f"{k}={v}")
            inner = ", ".join(parts)
        if s in ("move_to", "move_above") and "posture" in a:
            inner += f", posture={a['posture']!r}"
        return f"{s}({inner})"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (tuples become lists)."""
        return {
            "skill": self.skill,
            "args": {k: list(v) if isinstance(v, tuple) else v for k, v in self.args.items()},
            "line": self.line,
            "col": self.col,
            "call_stack": list(self.call_stack),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "SkillCall":
        args = {k: tuple(float(x) for x in v) if isinstance(v, list) else v for k, v in data["args"].items()}
        return cls(
            skill=data["skill"],
            args=args,
            line=int(data["line"]),
            col=int(data.get("col", 0)),
            call_stack=tuple(int(x) for x in data.get("call_stack", ())),
        )


@dataclass
class Plan:
    """The result of running a program: its source, the skill calls in order, and captured ``print`` output."""

    source: str = ""
    calls: list[SkillCall] = field(default_factory=list)
    output: list[str] = field(default_factory=list)

    def speed_at(self, line: int) -> float:
        """The speed fraction in effect at the first skill call on ``line`` (1 = full speed), as set by the
        ``set_speed`` / ``reduce_speed`` calls before it."""
        speed = 1.0
        for call in self.calls:
            if call.line == line:
                return speed
            if call.skill in ("set_speed", "reduce_speed"):
                speed = float(call.args["fraction"])
        return speed

    def describe(self) -> str:
        """One line per call: ``line 4: move_above(green_apple, height=0.1)``."""
        return "\n".join(f"line {c.line}: {c.describe()}" for c in self.calls)

    def to_dict(self) -> dict[str, Any]:
        return {"source": self.source, "calls": [c.to_dict() for c in self.calls], "output": list(self.output)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Plan":
        return cls(
            source=data.get("source", ""),
            calls=[SkillCall.from_dict(c) for c in data.get("calls", [])],
            output=list(data.get("output", [])),
        )
