"""Joint samples + robot + scene -> :class:`~robocritics.trajectory.Trajectory` in one call.

For every sample this computes every link frame (vectorised FK) and the signed
distance (m, <= 0 on penetration) of every proximity pair:

* **self** pairs: the robot's non-adjacent capsule pairs (``Robot.self_pairs``:
  arm links against arm links and against the gripper);
* **environment** pairs: every robot capsule against every scene entity (an
  object, a container - the minimum over its floor and walls -, the table), and
  every object the gripper carries at some point against every other entity.

Objects that the program moves have a pose per sample (``object_poses``):
at rest, carried with the TCP, at rest again where they were released, so
distances always use where the object really is.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from ..scene import Scene, Shape
from ..trajectory import Pair, Step, Trajectory
from . import proximity as prox

__all__ = ["build_trajectory"]


def _entity_groups(scene: Scene) -> list[tuple[str, str, list[Shape]]]:
    """(entity id, group, shapes) for every object, container and the table."""
    out: list[tuple[str, str, list[Shape]]] = []
    for o in scene.objects:
        out.append((o.id, "object", o.shapes()))
    for c in scene.containers:
        out.append((c.id, "container", c.shapes()))
    out.append(("table", "table", scene.table.shapes()))
    return out


def build_trajectory(
    robot,
    scene: Scene,
    q: np.ndarray,
    time: np.ndarray,
    *,
    gripper_opening_m: np.ndarray | float | None = None,
    attached: Sequence[str] | None = None,
    step: np.ndarray | None = None,
    steps: Sequence[Step] = (),
    object_poses: Mapping[str, np.ndarray] | None = None,
    frames: np.ndarray | None = None,
) -> Trajectory:
    """Build the trajectory of joint samples ``q (T, n)`` rad at ``time (T,)`` s in ``scene``.

    ``gripper_opening_m`` (m, default fully open), ``attached`` (object id per
    sample, '' for none), ``step``/``steps`` (provenance) and ``object_poses``
    (``{id: (T, 4, 4)}`` for objects that move) are optional.
    """
    q = np.asarray(q, dtype=float)
    if q.ndim != 2:
        q = np.atleast_2d(q)
    T = q.shape[0]
    opening = np.broadcast_to(
        np.asarray(robot.max_opening_m if gripper_opening_m is None else gripper_opening_m, float), (T,)
    ).copy()
    attached_arr = np.full(T, "", dtype=object) if attached is None else np.asarray(attached, dtype=object)
    step_arr = np.zeros(T, dtype=np.int64) if step is None else np.asarray(step, dtype=np.int64)
    if frames is None:
        frames = robot.forward(q, opening)
    object_poses = dict(object_poses or {})
    p0, p1 = robot.capsule_segments(frames)
    radii = robot.capsule_radii
    cidx = {name: i for i, name in enumerate(robot.capsule_names)}

    pairs: list[Pair] = []
    columns: list[np.ndarray] = []

    for a, b in robot.self_pairs:
        i, j = cidx[a], cidx[b]
        pairs.append(
            Pair(
                name=f"{a}|{b}",
                kind="self",
                a=a,
                b=b,
                group_a=robot.capsule_groups[i],
                group_b=robot.capsule_groups[j],
            )
        )
        columns.append(prox.capsule_capsule(p0[:, i], p1[:, i], radii[i], p0[:, j], p1[:, j], radii[j]))

    entities = _entity_groups(scene)
    for ci, cname in enumerate(robot.capsule_names):
        for eid, group, shapes in entities:
            if group == "table" and robot.capsules[ci].frame in robot.fixed_links:
                continue  # the base stands on the table
            d = None
            for shape in shapes:
                pose = object_poses.get(shape.owner, shape.pose)
                ds = prox.capsule_shape(p0[:, ci], p1[:, ci], radii[ci], shape, pose)
                d = ds if d is None else np.minimum(d, ds)
            pairs.append(
                Pair(
                    name=f"{cname}|{eid}",
                    kind="environment",
                    a=cname,
                    b=eid,
                    group_a=robot.capsule_groups[ci],
                    group_b=group,
                    b_entity=eid,
                )
            )
            columns.append(d)

    carried = [oid for oid in dict.fromkeys(a for a in attached_arr if a)]
    for oid in carried:
        obj = scene.entity(oid)
        (own,) = obj.shapes()
        own_pose = np.broadcast_to(np.asarray(object_poses.get(oid, own.pose), float), (T, 4, 4))
        # the pose is piecewise constant while the object rests: evaluate each run of equal poses once
        flat = own_pose.reshape(T, 16)
        changed = np.empty(T, dtype=bool)
        changed[0] = True
        np.any(flat[1:] != flat[:-1], axis=1, out=changed[1:])
        inverse = np.cumsum(changed) - 1
        unique_poses = flat[changed]
        for eid, group, shapes in entities:
            if eid == oid:
                continue
            d = None
            for shape in shapes:
                other = object_poses.get(shape.owner)
                if other is None:
                    ds = prox.shape_shape(own, shape, unique_poses.reshape(-1, 4, 4), shape.pose)[inverse]
                else:
                    ds = prox.shape_shape(own, shape, own_pose, other)
                d = ds if d is None else np.minimum(d, ds)
            pairs.append(
                Pair(
                    name=f"{oid}|{eid}",
                    kind="environment",
                    a=oid,
                    b=eid,
                    group_a="attached",
                    group_b=group,
                    b_entity=eid,
                )
            )
            columns.append(d)

    proximity = np.stack(columns, axis=1) if columns else np.zeros((T, 0))
    return Trajectory(
        q=q,
        time=time,
        frames=frames,
        frame_names=robot.frame_names,
        proximity=proximity,
        pairs=pairs,
        gripper_opening_m=opening,
        attached=np.asarray(attached_arr, dtype=str),
        step=step_arr,
        steps=steps,
        limits=robot.limits,
        robot_name=robot.name,
    )
