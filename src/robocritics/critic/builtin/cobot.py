"""What the collaborative-operation critics share: the robot's parts over time, their speeds, the carried mass.

* :func:`robot_parts`: every robot capsule and the carried object (a sphere around it, while it is held), as
  segments ``(T, P, 3)`` m in the base frame with radii ``(P,)`` m and a mask ``(T, P)`` of when each exists;
* :func:`part_speeds`: the speed of each part, m/s: the faster of its two segment ends (a rigid body's speed
  is largest at an end of any segment in it, since velocity is affine along the segment);
* :func:`part_body_distances`: the distance ``(T, P, K)`` m between each part and each capsule of a body model
  (exact within a distance of interest), :func:`part_body_nearest` the distance ``(T, P)`` to the nearest one;
* :func:`robot_masses`: the robot's moving mass and its tool's, kg, from the model's inertias (URDF);
* :func:`carried_mass`: the mass held at each sample, kg, from the objects' ``mass_kg`` attribute;
* :func:`slow_flagged_moves`: the repair both people critics offer: the flagged moves, slower.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ...errors import SceneError
from ...geometry.kernels import capsule_capsule

if TYPE_CHECKING:  # pragma: no cover
    from ...execution import Execution
    from ...humans import BodyModel

__all__ = [
    "Parts",
    "carried_ids",
    "robot_parts",
    "part_speeds",
    "part_body_distances",
    "part_body_nearest",
    "robot_masses",
    "carried_mass",
    "object_mass",
    "slow_flagged_moves",
]

SPEED_MARGIN = 0.85
"""A slowdown aims this fraction of the way under the limit (as the built-in speed repairs do)."""
_MOVES = {"move_to", "move_linear", "move_above", "move_down", "move_up", "home"}


@dataclass(frozen=True)
class Parts:
    """Robot parts over time: segment ``p0``-``p1`` ``(T, P, 3)`` m, ``radius_m (P,)``, ``present (T, P)``."""

    names: tuple[str, ...]
    p0: np.ndarray
    p1: np.ndarray
    radius_m: np.ndarray
    present: np.ndarray


def _bounding_radius(kind: str, size: tuple[float, ...]) -> float:
    if kind == "box":
        return 0.5 * math.sqrt(sum(s * s for s in size))
    if kind == "cylinder":
        return math.hypot(size[0], size[1] / 2)
    return float(size[0])


def carried_ids(trajectory) -> list[str]:
    """The ids of the objects ``trajectory`` carries at some sample, sorted (the carried parts, in order)."""
    return sorted({a for a in trajectory.attached.tolist() if a})


def robot_parts(execution: "Execution", carried: list[str] | None = None) -> Parts:
    """The robot's capsules and each object it carries (while held), from ``execution`` (needs its robot).

    ``carried``: the carried objects' ids, in order (default :func:`carried_ids` of its trajectory); a chunk of a
    run (:meth:`~robocritics.execution.Execution.chunks`) passes the whole run's, so its parts are the run's.
    """
    trajectory, robot = execution.trajectory, execution.robot
    p0, p1 = robot.capsule_segments(trajectory.frames)
    names = [c.name for c in robot.capsules]
    radii = [c.radius_m for c in robot.capsules]
    T = len(trajectory)
    starts, ends, present = [p0], [p1], [np.ones((T, len(names)), dtype=bool)]
    poses = getattr(execution, "object_poses", {}) or {}
    for obj_id in carried_ids(trajectory) if carried is None else carried:
        held = trajectory.attached == obj_id
        if obj_id not in poses:
            continue
        obj = execution.scene.entity(obj_id)
        centre = np.asarray(poses[obj_id], dtype=float)[:, :3, 3]
        starts.append(centre[:, None, :])
        ends.append(centre[:, None, :])
        present.append(held[:, None])
        names.append(f"carried {obj_id}")
        radii.append(_bounding_radius(obj.shape, tuple(obj.size)))
    return Parts(
        names=tuple(names),
        p0=np.concatenate(starts, axis=1),
        p1=np.concatenate(ends, axis=1),
        radius_m=np.asarray(radii, dtype=float),
        present=np.concatenate(present, axis=1),
    )


def part_speeds(parts: Parts, time_s: np.ndarray) -> np.ndarray:
    """``(T, P)`` speed of each part, m/s, reached at each sample (sample 0: 0); the faster segment end."""
    dt = np.diff(np.asarray(time_s, dtype=float))[:, None]
    speed = np.zeros(parts.present.shape)
    v0 = np.linalg.norm(np.diff(parts.p0, axis=0), axis=-1) / dt
    v1 = np.linalg.norm(np.diff(parts.p1, axis=0), axis=-1) / dt
    speed[1:] = np.maximum(v0, v1)
    speed[1:] *= parts.present[1:] & parts.present[:-1]  # a part picked up or let go has no speed across it
    return speed


def _exact(parts: Parts, body: "BodyModel", rows: np.ndarray, p: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Capsule distances (m) of the (sample, part, body capsule) triples ``rows, p, k`` (index arrays)."""
    return capsule_capsule(parts.p0[rows, p], parts.p1[rows, p], parts.radius_m[p], body.p0[k], body.p1[k],
                           body.radius_m[k])


def _centre_distances(parts: Parts, body: "BodyModel") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(between, half_a, half_b)``: the distance ``(T, P, K)`` m between the segments' midpoints and the half
    lengths ``(T, P, 1)`` and ``(K,)`` m of the segments: bounds on the capsule distance (see the callers)."""
    mid_a = 0.5 * (parts.p0 + parts.p1)  # (T, P, 3)
    mid_b = 0.5 * (body.p0 + body.p1)  # (K, 3)
    half_a = 0.5 * np.linalg.norm(parts.p1 - parts.p0, axis=-1)[:, :, None]
    half_b = 0.5 * np.linalg.norm(body.p1 - body.p0, axis=-1)
    diff = mid_a[:, :, None, :] - mid_b[None, None]
    return np.sqrt(np.einsum("tpki,tpki->tpk", diff, diff)), half_a, half_b


def part_body_distances(parts: Parts, body: "BodyModel", within_m: float | None = None) -> np.ndarray:
    """``(T, P, K)`` distance, m, between each part and each capsule of ``body`` (negative: overlapping); +inf
    where the part is absent.

    With ``within_m``, the distance is exact wherever it may be ``<= within_m`` at that sample or the next one,
    and elsewhere a lower bound above ``within_m`` (the distance between bounding spheres), which is all a
    caller comparing against ``within_m`` needs: far pairs skip the segment-distance computation.
    """
    if within_m is None:
        rows, p, k = np.indices(parts.present.shape + (len(body),)).reshape(3, -1)
        d = _exact(parts, body, rows, p, k).reshape(parts.present.shape + (len(body),))
    else:
        between, half_a, half_b = _centre_distances(parts, body)
        d = between - half_a - half_b - parts.radius_m[None, :, None] - body.radius_m
        need = d <= within_m
        need[:-1] |= need[1:]  # the sample before a near one: its exact distance says whether the part closes in
        rows, p, k = np.nonzero(need)
        d[rows, p, k] = _exact(parts, body, rows, p, k)
    return np.where(parts.present[:, :, None], d, np.inf)


def part_body_nearest(parts: Parts, body: "BodyModel") -> np.ndarray:
    """``(T, P)`` exact distance, m, between each part and the nearest capsule of ``body``; +inf where absent.

    Branch and bound: a capsule whose bounding-sphere distance exceeds the least midpoint-to-midpoint distance
    (an upper bound: both midpoints lie on the segments) cannot be the nearest, so only the others are computed.
    """
    between, half_a, half_b = _centre_distances(parts, body)
    radii = parts.radius_m[None, :, None] + body.radius_m
    upper = (between - radii).min(axis=2, keepdims=True)
    candidate = between - half_a - half_b - radii <= upper
    rows, p, k = np.nonzero(candidate)
    d = np.full(candidate.shape, np.inf)
    d[rows, p, k] = _exact(parts, body, rows, p, k)
    return np.where(parts.present, d.min(axis=2), np.inf)


def robot_masses(robot) -> tuple[float, float]:
    """``(moving_kg, tool_kg)``: the mass of the arm's moving links and of its tool (gripper), kg.

    From the robot model's inertias (the URDF's ``<inertial>``; the bundled UR3e's link masses are UR's
    published ones, :data:`robocritics.robot.arms.UR3E`): the tool is what the model fixes to the last joint
    (its frames of fixed joints that carry mass), the moving links are the rest of what the joints move.
    """
    model = robot.model
    total = sum(model.inertias[j].mass for j in range(1, model.njoints))
    tool = sum(
        f.inertia.mass for f in model.frames if f.parentJoint == model.njoints - 1 and str(f.type) == "FIXED_JOINT"
    )
    return float(total - tool), float(tool)


def object_mass(execution: "Execution", obj_id: str) -> float | None:
    """The ``mass_kg`` attribute of object ``obj_id``, kg (None when it has none); SceneError if not a mass."""
    scene = execution.scene
    for i, obj in enumerate(scene.objects):
        if obj.id != obj_id:
            continue
        value = obj.attributes.get("mass_kg")
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not 0 <= float(value) <= 1000:
            raise SceneError(f"{value!r} is not a mass in kg (0 to 1000)", path=f"objects[{i}].attributes.mass_kg")
        return float(value)
    return None


def carried_mass(execution: "Execution") -> tuple[np.ndarray, list[str]]:
    """``(T,)`` mass held at each sample, kg, and the ids of held objects whose mass is unknown (counted 0)."""
    attached = execution.trajectory.attached
    mass = np.zeros(len(attached))
    unknown: list[str] = []
    for obj_id in sorted({a for a in attached.tolist() if a}):
        m = object_mass(execution, obj_id)
        if m is None:
            unknown.append(obj_id)
            continue
        mass[attached == obj_id] = m
    return mass, unknown


def slow_flagged_moves(verdict, execution, ratio: float) -> list:
    """Repair candidates: ``set_speed(f)`` before each flagged move line (the speed in force restored after it),
    ``f`` = the speed there times ``ratio`` (the limit over the measured speed) times :data:`SPEED_MARGIN`, and a
    second, stronger candidate. Empty without a plan (imported motion) or a ratio to aim at."""
    from ...repair.edit import Edit, Insert

    plan = getattr(execution, "plan", None)
    if plan is None or not 0 < ratio < 1:
        return []
    skills = {c.line: c.skill for c in plan.calls}
    lines = [ln for ln in verdict.evidence.lines if skills.get(ln) in _MOVES]
    edits = []
    for margin in (SPEED_MARGIN, SPEED_MARGIN**3):
        ops, said = [], []
        for ln in lines:
            before = plan.speed_at(ln)
            f = max(0.01, round(before * ratio * margin, 2))
            ops.append(Insert(ln, before=(f"set_speed({f:g})",), after=(f"set_speed({before:g})",)))
            said.append(f"line {ln}: speed {before:g} -> {f:g}")
        if ops:
            edits.append(Edit(verdict.critic, lines[0], "; ".join(said) + " (restored after the move)",
                              f"{verdict.message.split(':')[0]}", ops))
    return edits


def nothing_to_judge(name: str, execution: "Execution", needs: str):
    """The OK verdict of a collaborative-operation critic that has nothing to judge (no people in the scene, or
    no robot model, whose ``needs`` — e.g. "shapes and masses" — the critic reads), else None."""
    from .. import Flag, Verdict

    if not getattr(execution.scene, "humans", ()):
        return Verdict(critic=name, flag=Flag.OK, message="no people in the scene: nothing to check",
                       hint="add people to the scene's 'humans' to judge collaborative operation")
    if execution.robot is None:
        return Verdict(critic=name, flag=Flag.OK, message=f"no robot model: nothing to check (its parts' {needs} "
                       "are needed)", hint="judge the motion with its robot")
    return None

