"""What the gripper held, inferred for imported motion: a file holds joint angles and a finger gap, not grasps.

When the fingers close (the gap falls below the full opening) with a graspable object of the scene between them
— its centre within its own half size plus 1 cm of the TCP, and the fingers stopped on it (their final gap at
least its width less 5 mm) — the object is held from that closing until the fingers open again: it moves with
the TCP (``object_poses``), is the ``attached`` object (so the fingers touching it are the grasp, not a
collision) and stays where it was let go. While the held object leaves the surface it was picked from and
reaches the one it is set down on (within :data:`NEAR_M`), those surfaces are that moment's intended contacts,
as a program's pick and place steps name them: the samples get a copy of their step with the contacts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..scene import Scene, rpy_matrix
from ..trajectory import Step

__all__ = ["Grasp", "infer_grasps", "contact_steps", "imported_execution", "NEAR_M"]

#: A carried object this close to a surface at its pick or set-down is being picked from or set on it, m
#: (programs set objects down from just above the surface and let them drop the rest).
NEAR_M = 0.02
#: A pick or set-down's approach and retreat: the gripper within this of the surfaces it touches there, m
#: (the collision critic's default warning distance, which a program's pick and place steps cover the same way).
APPROACH_M = 0.05


@dataclass
class Grasp:
    object_id: str
    first: int  # first sample held
    stop: int  # first sample no longer held (len(q) if never let go)
    offset: np.ndarray = field(repr=False)  # object pose in the TCP frame


def infer_grasps(robot, scene: Scene, q: np.ndarray, opening: np.ndarray) -> tuple[list[Grasp], np.ndarray, dict[str, np.ndarray]]:
    """``(grasps, attached (T,), object_poses {id: (T, 4, 4)})`` of motion ``q (T, n)`` rad with finger gap
    ``opening (T,)`` m in ``scene``."""
    T = len(q)
    attached = np.full(T, "", dtype=object)
    closed = opening < robot.max_opening_m - 1e-3
    starts = np.flatnonzero(closed & ~np.concatenate([[False], closed[:-1]]))
    graspable = [o for o in scene.objects if o.graspable]
    if not len(starts) or not graspable:
        return [], attached.astype(str), {}
    tcp = robot.tcp_pose(q)
    rest = {o.id: _pose(o) for o in graspable}
    grasps: list[Grasp] = []
    drops: dict[tuple[str, int], np.ndarray] = {}
    for s in starts.tolist():
        run_end = s + int(np.argmax(~closed[s:])) if (~closed[s:]).any() else T
        gap = float(opening[s:run_end].min())
        held = s + int(np.argmax(opening[s:run_end] <= gap + 1e-4))  # the fingers stop: on the object, if any
        opens = np.flatnonzero(opening[held:run_end] > gap + 1e-3)
        stop = held + int(opens[0]) if len(opens) else run_end
        point = tcp[held, :3, 3]
        best = None
        for o in graspable:
            d = float(np.linalg.norm(rest[o.id][:3, 3] - point))
            if d <= max(o.size) / 2 + 0.01 and gap >= o.width - 0.005 and (best is None or d < best[0]):
                best = (d, o.id)
        if best is None:
            continue
        oid = best[1]
        offset = np.linalg.inv(tcp[held]) @ rest[oid]
        grasps.append(Grasp(oid, s, stop, offset))
        attached[s:stop] = oid
        rest[oid] = _dropped(scene, next(o for o in graspable if o.id == oid), tcp[stop - 1] @ offset, rest)
        drops[(oid, stop)] = rest[oid]
    poses: dict[str, np.ndarray] = {}
    for g in grasps:
        if g.object_id not in poses:
            obj = next(o for o in graspable if o.id == g.object_id)
            poses[g.object_id] = np.broadcast_to(_pose(obj), (T, 4, 4)).copy()
        track = poses[g.object_id]
        track[g.first : g.stop] = tcp[g.first : g.stop] @ g.offset
        track[g.stop :] = drops[(g.object_id, g.stop)]
    return grasps, attached.astype(str), poses


def _dropped(scene: Scene, obj, pose: np.ndarray, rest: dict[str, np.ndarray]) -> np.ndarray:
    """``pose`` of ``obj`` let go, lowered onto the highest surface below it (the table, a container's floor it is
    over, another object's top), as the planner lets a released object settle."""
    x, y, z = (float(v) for v in pose[:3, 3])
    bottom = z - obj.half_height
    surfaces = [scene.table.top_z]
    surfaces += [c.floor_top for c in scene.containers if c.contains_point((x, y, c.floor_top + 1e-3))]
    for other in scene.objects:
        if other.id != obj.id:
            ox, oy, oz = (float(v) for v in rest.get(other.id, _pose(other))[:3, 3])
            if math.hypot(x - ox, y - oy) < other.width / 2:
                surfaces.append(oz + other.half_height)
    below = [h for h in surfaces if h <= bottom + 1e-6]
    out = pose.copy()
    if below:
        out[2, 3] = max(below) + obj.half_height
    return out


def _pose(obj) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = rpy_matrix(obj.rpy), obj.position
    return pose


def contact_steps(trajectory, grasps: list[Grasp], scene: Scene, poses: dict[str, np.ndarray]) -> tuple[np.ndarray, list[Step]]:
    """``(step (T,), steps)``: ``trajectory``'s steps, with the samples of each pick and set-down moved to a
    copy of their step naming the surfaces the held object touches then (within :data:`NEAR_M`, or the container
    it is in), from the gripper's approach within :data:`APPROACH_M` of them
    (and the fingers closing or opening) to its retreat."""
    steps = list(trajectory.steps) or [Step(skill="recording")]
    step = np.array(trajectory.step, dtype=np.int64)
    opening = trajectory.gripper_opening_m
    copies: dict[tuple[int, tuple[str, ...]], int] = {}
    for g in grasps:
        columns = [k for k, p in enumerate(trajectory.pairs) if p.group_a == "attached" and p.a == g.object_id]
        if not columns:
            continue
        for edge, outward in ((g.first, -1), (g.stop - 1, 1)):  # the pick and the set-down
            touching = [trajectory.pairs[c].b_entity for c in columns if trajectory.proximity[edge, c] <= NEAR_M]
            where = tuple(float(v) for v in poses[g.object_id][edge, :3, 3])
            touching += [c.id for c in scene.containers if c.contains_point(where)]  # picked from or dropped in it
            if not touching:
                continue
            contacts = tuple(sorted(set(touching) | {g.object_id}))
            # the approach and the retreat: the gripper (and what it holds) within APPROACH_M of those surfaces
            close = [k for k, p in enumerate(trajectory.pairs) if p.group_a in ("gripper", "attached") and p.b_entity in contacts]
            approach = trajectory.proximity[:, close].min(axis=1) <= APPROACH_M
            window = np.union1d(_run_around(approach, edge), _fingers_moving(opening, edge, outward))
            for i in window.tolist():
                key = (int(step[i]), contacts)
                if key not in copies:
                    base = steps[key[0]]
                    copies[key] = len(steps)
                    steps.append(base.model_copy(update={"contacts": tuple(sorted(set(base.contacts) | set(contacts)))}))
                step[i] = copies[key]
    return step, steps


def _fingers_moving(opening: np.ndarray, edge: int, outward: int) -> np.ndarray:
    """The samples from ``edge`` outwards (-1 back in time, +1 forward) while the finger gap keeps changing."""
    i = edge
    while 0 <= i + outward < len(opening) and abs(opening[i + outward] - opening[i]) > 1e-7:
        i += outward
    return np.arange(min(i, edge), max(i, edge) + 1)


def _run_around(flags: np.ndarray, index: int) -> np.ndarray:
    """Indices of the run of True in ``flags`` that contains ``index``."""
    lo = index
    while lo > 0 and flags[lo - 1]:
        lo -= 1
    hi = index
    while hi + 1 < len(flags) and flags[hi + 1]:
        hi += 1
    return np.arange(lo, hi + 1)


def imported_execution(robot, scene: Scene, q, time, opening, source: str, step=None, steps=()):
    """The :class:`~robocritics.simulate.Execution` of imported motion: its trajectory with the grasps inferred
    (:func:`infer_grasps`, :func:`contact_steps`), ``plan=None``, the final scene with every held object where
    it was let go, and ``source``."""
    from ..execution import Execution
    from ..trajectory import Trajectory

    q = np.asarray(q, float)
    opening = np.full(len(q), robot.max_opening_m) if opening is None else np.asarray(opening, float)
    grasps, attached, poses = infer_grasps(robot, scene, q, opening)
    traj = robot.trajectory(
        q=q, time=time, scene=scene, gripper_opening_m=opening, attached=attached, step=step, steps=steps, object_poses=poses
    )
    if grasps:
        new_step, new_steps = contact_steps(traj, grasps, scene, poses)
        traj = Trajectory(
            q=traj.q, time=traj.time, frames=traj.frames, frame_names=traj.frame_names, proximity=traj.proximity,
            pairs=traj.pairs, gripper_opening_m=traj.gripper_opening_m, attached=traj.attached, step=new_step,
            steps=new_steps, limits=traj.limits, robot_name=traj.robot_name, tcp_frame=traj.tcp_frame,
        )  # fmt: skip
    final = scene
    if poses:
        moved = {oid: track[-1, :3, 3] for oid, track in poses.items()}
        final = scene.model_copy(
            update={"objects": [o.moved_to(moved[o.id]) if o.id in moved else o for o in scene.objects]}
        )
    return Execution(traj, None, [], final, scene, robot, object_poses=poses, source=source)
