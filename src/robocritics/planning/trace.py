"""Joint samples + robot + scene -> :class:`~robocritics.trajectory.Trajectory` in one call.

For every sample this computes every link frame (vectorised FK) and the signed
distance (m, <= 0 on penetration) of every proximity pair:

* **self** pairs: the robot's non-adjacent capsule pairs (``Robot.self_pairs``:
  arm links against arm links and against the gripper);
* **environment** pairs: every robot capsule against every scene entity (an
  object, a container - the minimum over its floor and walls -, the table), and
  every object the gripper carries at some point against every other entity.

A distance is exact when it is at most :data:`EXACT_WITHIN_M` or at most the arm's
closest distance to the scene at that sample (a self pair: the closest self
distance at that sample); beyond both, it may be a lower bound that is itself
larger (what lies that far needs no exact value). So every threshold test up to
``EXACT_WITHIN_M`` is exact, and so are, at every sample, the closest distance over
any set of environment pairs that includes the arm links' (the collision critic's
``D_t``) and the closest self distance (the pinch-point critic's).

Objects that the program moves have a pose per sample (``object_poses``):
at rest, carried with the TCP, at rest again where they were released, so
distances always use where the object really is.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from .._arrays import run_starts
from ..scene import Scene, Shape
from ..trajectory import Pair, Step, Trajectory
from ..geometry import proximity as prox

__all__ = ["build_trajectory", "EXACT_WITHIN_M"]

#: Distances (robot capsules against the scene and against each other, carried objects against the scene) are
#: exact up to this many metres (twice the collision critic's warning distance) and up to the closest distance of the
#: arm (a self pair: of the self pairs) at each sample;
#: larger ones may be a lower bound that is itself larger (:meth:`ProximityKernel.distances`).
EXACT_WITHIN_M = 0.10


def _entity_groups(scene: Scene) -> list[tuple[str, str, list[Shape]]]:
    """(entity id, group, shapes) for every object, container and the table."""
    out: list[tuple[str, str, list[Shape]]] = []
    for o in scene.objects:
        out.append((o.id, "object", o.shapes()))
    for c in scene.containers:
        out.append((c.id, "container", c.shapes()))
    out.append(("table", "table", scene.table.shapes()))
    return out


def _carried_ids(attached: np.ndarray) -> list[str]:
    """The object ids in ``attached`` (one per sample, '' for none), each once, in order of first appearance."""
    if not len(attached):
        return []
    # the id changes only where a grasp or a release starts: the runs' first samples hold every id
    return [oid for oid in dict.fromkeys(attached[run_starts(attached)].tolist()) if oid]


def _reported_pairs(robot, scene: Scene, carried: Sequence[str]) -> tuple[list[Pair], list[list[tuple[str, str]]]]:
    """One row per reported pair: its metadata, and the (a, shape) kernel pairs whose minimum it is: the robot's
    self pairs, every capsule against every entity (not the fixed base against the table), every carried object
    against every other entity."""
    capsule_group = dict(zip(robot.capsule_names, robot.capsule_groups))
    fixed_capsules = {c.name for c in robot.capsules if c.frame in robot.fixed_links} | set(getattr(robot, "table_fixed_capsules", ()))
    entities = _entity_groups(scene)
    pairs: list[Pair] = []
    members: list[list[tuple[str, str]]] = []
    for a, b in robot.self_pairs:
        pairs.append(Pair(name=f"{a}|{b}", kind="self", a=a, b=b, group_a=capsule_group[a], group_b=capsule_group[b]))
        members.append([(a, b)])
    for cname in robot.capsule_names:
        for eid, group, shapes in entities:
            if group == "table" and cname in fixed_capsules:
                continue  # the base stands on the table
            pairs.append(
                Pair(
                    name=f"{cname}|{eid}",
                    kind="environment",
                    a=cname,
                    b=eid,
                    group_a=capsule_group[cname],
                    group_b=group,
                    b_entity=eid,
                )
            )
            members.append([(cname, shape.name) for shape in shapes])
    for oid in carried:
        for eid, group, shapes in entities:
            if eid == oid:
                continue
            pairs.append(
                Pair(name=f"{oid}|{eid}", kind="environment", a=oid, b=eid, group_a="attached", group_b=group, b_entity=eid)
            )
            members.append([(oid, shape.name) for shape in shapes])
    return pairs, members


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
    segments: tuple[np.ndarray, np.ndarray] | None = None,
) -> Trajectory:
    """Build the trajectory of joint samples ``q (T, n)`` rad at ``time (T,)`` s in ``scene``.

    ``gripper_opening_m`` (m, default fully open), ``attached`` (object id per
    sample, '' for none), ``step``/``steps`` (provenance) and ``object_poses``
    (``{id: (T, 4, 4)}`` for objects that move) are optional. ``frames`` (``robot.forward(q, opening)``)
    and ``segments`` (its capsule endpoints ``(p0, p1)``, ``(T, C, 3)`` m each) may be given when the
    caller has them already (:meth:`Robot.forward_with_capsules` makes both in one pass).
    """
    q = np.asarray(q, dtype=float)
    if q.ndim != 2:
        q = np.atleast_2d(q)
    T = q.shape[0]
    opening = np.broadcast_to(
        np.asarray(robot.max_opening_m if gripper_opening_m is None else gripper_opening_m, float), (T,)
    ).copy()
    attached_arr = np.full(T, "", dtype=str) if attached is None else np.asarray(attached, dtype=str).reshape(-1)
    step_arr = np.zeros(T, dtype=np.int64) if step is None else np.asarray(step, dtype=np.int64)
    if frames is None:
        frames, p0, p1 = robot.forward_with_capsules(q, opening)
    elif segments is None:
        p0, p1 = robot.capsule_segments(frames)
    else:
        p0, p1 = segments
    object_poses = dict(object_poses or {})
    pairs, members = _reported_pairs(robot, scene, _carried_ids(attached_arr))

    # one kernel for robot and carried-object pairs: exact within EXACT_WITHIN_M and within the arm's closest
    # distance at each sample (its columns' minimum stays exact; the self pairs: within the closest self distance);
    # farther values are bounds, never evaluated
    flat = [pair for group in members for pair in group]
    bounds = np.cumsum([0] + [len(g) for g in members])
    arm = [
        j
        for k, p in enumerate(pairs)
        if p.kind == "environment" and p.group_a == "arm"
        for j in range(bounds[k], bounds[k + 1])
    ]
    own = [j for k, p in enumerate(pairs) if p.kind == "self" for j in range(bounds[k], bounds[k + 1])]
    capsules = [(name, float(r)) for name, r in zip(robot.capsule_names, robot.capsule_radii)]
    poses = {oid: np.asarray(pose, float) for oid, pose in object_poses.items()}
    proximity = np.zeros((T, 0))
    if flat:
        kernel = prox.ProximityKernel(capsules, scene.shapes(), flat, moving=list(object_poses))
        sets = [arm, own] if own else [arm]
        by_pair = kernel.distances(p0, p1, poses=poses, far_m=EXACT_WITHIN_M, exact_min_of=sets).T  # (K', T) C-order
        # each reported pair is the least of its consecutive kernel rows (an entity's shapes): every pair's
        # first row in one gather, then the pairs of several rows (containers) folded in row by row
        # (np.minimum.reduceat along axis 0 is 15x slower)
        rows = by_pair[bounds[:-1]]
        for k in np.flatnonzero(np.diff(bounds) > 1).tolist():
            np.minimum.reduce(by_pair[bounds[k] : bounds[k + 1]], axis=0, out=rows[k])
        proximity = rows.T  # (T, K) column-major: each pair's time series contiguous, as the critics read them
    return Trajectory(
        q=q,
        time=time,
        frames=frames,
        frame_names=robot.frame_names,
        proximity=proximity,
        pairs=pairs,
        gripper_opening_m=opening,
        attached=attached_arr,
        step=step_arr,
        steps=steps,
        limits=robot.limits,
        robot_name=robot.name,
        kinematic_hash=robot.kinematic_hash,
        tcp_frame=robot.tcp_frame,
    )
