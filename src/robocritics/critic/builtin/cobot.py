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
    "part_body_near",
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
    P = parts.p0.shape[1]
    flat = rows * P + p
    a0, a1 = parts.p0.reshape(-1, 3), parts.p1.reshape(-1, 3)
    return capsule_capsule(a0[flat], a1[flat], parts.radius_m[p], body.p0[k], body.p1[k], body.radius_m[k])


BLOCK = 32
"""Samples per block of :class:`_Blocks` (one exact distance per part and body capsule at each block's centre)."""
_ROUNDING_M = 1e-9
"""Slack, m, added to the bounds' comparisons so that rounding can only add candidates, never drop one."""


class _Blocks:
    """Lower bounds on the part-to-body distances from their exact values at one sample of every block.

    The body is static and a part's segment moves by at most ``disp(t, p)`` = the farther of its two ends'
    displacements from the block's centre sample ``c`` (every point of a segment is a convex combination of its
    ends), so its distance to any fixed set moves by at most as much: ``|d(t, p, k) - d(c, p, k)| <=
    disp(t, p)`` (m). Blocks of :data:`BLOCK` samples: ``d_c (B, P, K)`` exact at the centres, ``disp (T, P)``.
    """

    def __init__(self, parts: Parts, body: "BodyModel"):
        T, P = parts.present.shape
        self.T, self.P, self.K = T, P, len(body)
        self.nb = -(-T // BLOCK)
        centres = np.minimum(np.arange(self.nb) * BLOCK + BLOCK // 2, T - 1)
        self.d_c = capsule_capsule(parts.p0[centres][:, :, None], parts.p1[centres][:, :, None],
                                   parts.radius_m[:, None], body.p0, body.p1, body.radius_m)  # (B, P, K)
        of = np.repeat(centres, BLOCK)[:T]  # (T,) the centre sample each sample is bounded from
        self.disp = np.maximum(np.linalg.norm(parts.p0 - parts.p0[of], axis=-1),
                               np.linalg.norm(parts.p1 - parts.p1[of], axis=-1))  # (T, P) m

    def padded(self, a: np.ndarray) -> np.ndarray:
        """``(T, P)`` array ``a`` as ``(B, BLOCK, P)`` (the last block padded with NaN, which no bound passes)."""
        out = np.full((self.nb * BLOCK, self.P), np.nan)
        out[: self.T] = a
        return out.reshape(self.nb, BLOCK, self.P)

    def lower(self) -> np.ndarray:
        """``(T, P, K)`` lower bounds, m: ``d_c - disp``."""
        low = self.d_c[:, None] - self.padded(self.disp)[..., None]
        return low.reshape(self.nb * BLOCK, self.P, self.K)[: self.T]

    def near(self, within_m: float) -> np.ndarray:
        """``(T, P, K)`` mask of the triples whose distance may be ``<= within_m`` at that sample or the next."""
        reach = self.padded(self.disp + (within_m + _ROUNDING_M))[..., None]  # d_c - disp <= within_m
        need = (self.d_c[:, None] <= reach).reshape(self.nb * BLOCK, self.P, self.K)[: self.T]
        need[:-1] |= need[1:]  # the sample before a near one: its exact distance says whether the part closes in
        return need


def part_body_distances(parts: Parts, body: "BodyModel", within_m: float | None = None) -> np.ndarray:
    """``(T, P, K)`` distance, m, between each part and each capsule of ``body`` (negative: overlapping); +inf
    where the part is absent.

    With ``within_m``, the distance is exact wherever it may be ``<= within_m`` at that sample or the next one
    (:func:`part_body_near`), and elsewhere a lower bound above ``within_m`` (:class:`_Blocks`' bound from the
    block's centre sample), which is all a caller comparing against ``within_m`` needs: far pairs skip the
    segment-distance computation.
    """
    if within_m is None:
        rows, p, k = np.indices(parts.present.shape + (len(body),)).reshape(3, -1)
        d = _exact(parts, body, rows, p, k).reshape(parts.present.shape + (len(body),))
    else:
        blocks = _Blocks(parts, body)
        d = blocks.lower()
        rows, p, k = np.nonzero(blocks.near(within_m))
        d[rows, p, k] = _exact(parts, body, rows, p, k)
    return np.where(parts.present[:, :, None], d, np.inf)


def part_body_near(parts: Parts, body: "BodyModel", within_m: float) -> tuple[np.ndarray, ...]:
    """``(rows, p, k, d)``: the (sample, part, body capsule) triples, in C order of ``(T, P, K)``, whose distance
    may be ``<= within_m`` at that sample or the next one (every one that is, and more), with their exact
    distances ``d`` (m; whether or not the part is present): the sparse form of :func:`part_body_distances`."""
    rows, p, k = np.nonzero(_Blocks(parts, body).near(within_m))
    return rows, p, k, _exact(parts, body, rows, p, k)


def part_body_nearest(parts: Parts, body: "BodyModel") -> np.ndarray:
    """``(T, P)`` exact distance, m, between each part and the nearest capsule of ``body``; +inf where absent.

    Branch and bound (:class:`_Blocks`): the capsule nearest at the block's centre gives an upper bound ``u``
    (its exact distance at the sample), and only the capsules whose lower bound ``d_c - disp`` is at most ``u``
    can be nearer: their exact distances are computed (for a part that moves little in a block, none).
    """
    blocks = _Blocks(parts, body)
    T, P = parts.present.shape
    order = np.argsort(blocks.d_c, axis=2, kind="stable")  # (B, P, K) capsules by distance at the centre
    first = np.repeat(order[:, :, 0], BLOCK, axis=0)[:T]  # (T, P) nearest at the centre
    d = capsule_capsule(parts.p0, parts.p1, parts.radius_m, body.p0[first], body.p1[first], body.radius_m[first])
    sorted_c = np.take_along_axis(blocks.d_c, order, axis=2)[:, None, :, 1:]  # (B, 1, P, K - 1)
    reach = blocks.padded(d + blocks.disp + _ROUNDING_M)[..., None]  # (B, BLOCK, P, 1)
    b, i, p, j = np.nonzero(sorted_c <= reach)  # the others' lower bound d_c - disp <= u
    if len(b):
        rows, k = b * BLOCK + i, order[b, p, j + 1]
        np.minimum.at(d, (rows, p), _exact(parts, body, rows, p, k))
    return np.where(parts.present, d, np.inf)


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

