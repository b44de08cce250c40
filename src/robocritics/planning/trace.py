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

A vendor arm's capsules fitted around its link meshes (``Robot.from_urdf``) are measured as their link's own
mesh wherever the capsule distance is at most :data:`MESH_EXACT_WITHIN_M`
(:func:`robocritics.geometry.link_meshes.refine_near_contact`): every value up to ``MESH_EXACT_WITHIN_M`` is
then the mesh's, and a larger one a lower bound of it (the capsule's, at most its ``slack_m`` below).

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
from ..geometry.link_meshes import refine_near_contact

__all__ = [
    "build_trajectory", "build_compact_trajectory", "ChunkGeometry", "PoseSchedule", "EXACT_WITHIN_M",
    "MESH_EXACT_WITHIN_M",
]  # fmt: skip

#: Distances (robot capsules against the scene and against each other, carried objects against the scene) are
#: exact up to this many metres (twice the collision critic's warning distance) and up to the closest distance of the
#: arm (a self pair: of the self pairs) at each sample;
#: larger ones may be a lower bound that is itself larger (:meth:`ProximityKernel.distances`).
EXACT_WITHIN_M = 0.10

#: A vendor arm's link is measured as its own mesh where its fitted capsule is at most this far [m] from the
#: other side: the largest threshold of the built-in critics (pinch_point's ``d_max_m``, 6 cm; collision's
#: ``d_warn_m`` is 5 cm), so every built-in threshold test reads the mesh (tests/test_link_meshes.py checks).
MESH_EXACT_WITHIN_M = 0.06


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
    geometry = _Distances(robot, scene, _carried_ids(attached_arr), list(object_poses))
    poses = {oid: np.asarray(pose, float) for oid, pose in object_poses.items()}
    proximity = geometry.proximity(p0, p1, poses, frames)
    pairs = geometry.pairs
    return Trajectory(
        q=q,
        time=time,
        frames=frames,
        proximity=proximity,
        pairs=pairs,
        gripper_opening_m=opening,
        attached=attached_arr,
        step=step_arr,
        steps=steps,
        **_robot_facts(robot),
    )


def _robot_facts(robot) -> dict:
    """The arm's facts a :class:`Trajectory` carries, whole or compact: frame names, limits, name, kinematic
    hash and TCP frame."""
    return {
        "frame_names": robot.frame_names, "limits": robot.limits, "robot_name": robot.name,
        "kinematic_hash": robot.kinematic_hash, "tcp_frame": robot.tcp_frame,
    }  # fmt: skip


class _Distances:
    """The reported pairs of a robot in a scene and the proximity kernel that measures them (see the module
    docstring); :meth:`proximity` of any run of samples."""

    def __init__(self, robot, scene: Scene, carried: Sequence[str], moving: Sequence[str]):
        self.pairs, members = _reported_pairs(robot, scene, carried)
        # one kernel for robot and carried-object pairs: exact within EXACT_WITHIN_M and within the arm's closest
        # distance at each sample (its columns' minimum stays exact; the self pairs: within the closest self
        # distance); farther values are bounds, never evaluated
        flat = [pair for group in members for pair in group]
        self.bounds = np.cumsum([0] + [len(g) for g in members])
        arm = [
            j
            for k, p in enumerate(self.pairs)
            if p.kind == "environment" and p.group_a == "arm"
            for j in range(self.bounds[k], self.bounds[k + 1])
        ]
        own = [j for k, p in enumerate(self.pairs) if p.kind == "self" for j in range(self.bounds[k], self.bounds[k + 1])]
        self.exact_sets = [arm, own] if own else [arm]
        capsules = [(name, float(r)) for name, r in zip(robot.capsule_names, robot.capsule_radii)]
        self.kernel = prox.ProximityKernel(capsules, scene.shapes(), flat, moving=list(moving)) if flat else None
        self.flat, self.robot, self.shapes = flat, robot, scene.shapes()
        # a vendor arm's links near contact are measured as their own meshes (geometry.link_meshes)
        self.has_meshes = any(piece is not None for piece in getattr(robot, "capsule_meshes", ()))

    def proximity(
        self, p0: np.ndarray, p1: np.ndarray, poses: Mapping[str, np.ndarray], frames: np.ndarray
    ) -> np.ndarray:
        """``(T, K)`` m, column-major, of capsule endpoints ``p0``, ``p1`` ``(T, C, 3)``, moving objects' poses and
        the link poses ``frames (T, L, 4, 4)`` (which place a vendor arm's link meshes)."""
        if self.kernel is None:
            return np.zeros((p0.shape[0], 0))
        bounds = self.bounds
        by_pair = self.kernel.distances(p0, p1, poses=poses, far_m=EXACT_WITHIN_M, exact_min_of=self.exact_sets).T
        if self.has_meshes:
            refine_near_contact(by_pair, self.flat, self.robot, frames, p0, p1, self.shapes, poses, MESH_EXACT_WITHIN_M)
        # each reported pair is the least of its consecutive kernel rows (an entity's shapes): every pair's
        # first row in one gather, then the pairs of several rows (containers) folded in row by row
        # (np.minimum.reduceat along axis 0 is 15x slower)
        rows = by_pair[bounds[:-1]]
        for k in np.flatnonzero(np.diff(bounds) > 1).tolist():
            np.minimum.reduce(by_pair[bounds[k] : bounds[k + 1]], axis=0, out=rows[k])
        return rows.T  # (T, K) column-major: each pair's time series contiguous, as the critics read them


class PoseSchedule:
    """Where one object the program moves is at every sample, without a ``(T, 4, 4)`` array.

    ``rest`` is its pose ``(4, 4)`` at the start; ``paints`` are applied in order, each over samples
    ``[first, last)``: ``("fixed", pose)`` (at rest there) or ``("carry", offset)`` (carried: ``tcp @ offset``).
    :meth:`poses` of samples ``[lo, hi)`` equals those rows of
    :meth:`robocritics.planning.world.World.object_poses`.
    """

    def __init__(self, rest: np.ndarray, paints: list[tuple[int, int, str, np.ndarray]]):
        self.rest = np.asarray(rest, float)
        self.paints = paints

    def at(self, samples: np.ndarray, tcp: np.ndarray) -> np.ndarray:
        """``(n, 4, 4)`` poses, m, at sample indices ``samples``; ``tcp`` the TCP poses there."""
        out = np.broadcast_to(self.rest, (len(samples), 4, 4)).copy()
        for first, last, kind, data in self.paints:
            m = (samples >= first) & (samples < last)
            if m.any():
                out[m] = data if kind == "fixed" else tcp[m] @ data
        return out

    def poses(self, lo: int, hi: int, tcp: np.ndarray) -> np.ndarray:
        """``(hi - lo, 4, 4)`` poses, m, of samples ``lo..hi-1``; ``tcp`` the TCP poses of those samples."""
        out = np.broadcast_to(self.rest, (hi - lo, 4, 4)).copy()
        for first, last, kind, data in self.paints:
            a, b = max(first, lo), min(last, hi)
            if a >= b:
                continue
            if kind == "fixed":
                out[a - lo : b - lo] = data
            else:
                out[a - lo : b - lo] = tcp[a - lo : b - lo] @ data
        return out


def pose_schedules(world, q: np.ndarray, opening: np.ndarray, robot) -> dict[str, PoseSchedule]:
    """The :class:`PoseSchedule` of every object ``world`` (the planner's bookkeeping) moved, for samples ``q``:
    the same events, in the same order, as :meth:`~robocritics.planning.world.World.object_poses`."""
    from ..scene import rpy_matrix

    T = q.shape[0]
    moved = {c[0] for c in world.carry} | {r[0] for r in world.rest_changes}
    out: dict[str, PoseSchedule] = {}
    for oid in moved:
        o = next(o for o in world.scene.objects if o.id == oid)
        rest = np.eye(4)
        rest[:3, :3], rest[:3, 3] = rpy_matrix(o.rpy), o.position
        events = sorted(
            [(first, "carry", (last if last >= 0 else T), off) for (cid, first, last, off) in world.carry if cid == oid]
            + [(first, "rest", None, pose) for (cid, first, pose) in world.rest_changes if cid == oid],
            key=lambda e: e[0],
        )
        paints: list[tuple[int, int, str, np.ndarray]] = []
        for first, kind, last, data in events:
            if kind == "rest":
                paints.append((first, T, "fixed", data))
                continue
            paints.append((first, last, "carry", data))
            if last < T:  # let go: it stays where the TCP left it (its pose at the last carried sample)
                frames = robot.forward_with_capsules(q[last - 1 : last], opening[last - 1 : last])[0]
                paints.append((last, T, "fixed", frames[0, robot.tcp_index] @ data))
        out[oid] = PoseSchedule(rest, paints)
    return out


class ChunkGeometry:
    """Link frames, proximity and moving objects' poses of any run of samples of one motion, computed on demand.

    What a compact :class:`~robocritics.trajectory.Trajectory` (:func:`build_compact_trajectory`) keeps instead
    of its ``(T, L, 4, 4)`` frames and ``(T, K)`` proximity: the robot, the scene's distance kernel and the
    objects' :class:`PoseSchedule`. :meth:`compute` of samples ``[lo, hi)`` gives the frames and object poses
    :func:`build_trajectory` computes for the whole motion bit for bit, and the same proximity wherever it is
    exact (up to :data:`EXACT_WITHIN_M` and the arm's closest distance at each sample, a self pair's up to the
    closest self distance: every value a critic reads); beyond, a far pair's value is a lower bound above both either way, but which one depends on the
    kernel's blocks of 32 samples and on how many samples it is given (the chunks of 16,384 samples that start
    on multiples of :data:`~robocritics.trajectory.CHUNK_ALIGN` give the whole motion's bounds too).
    """

    def __init__(self, robot, scene: Scene, q: np.ndarray, opening: np.ndarray, attached: np.ndarray,
                 schedules: Mapping[str, PoseSchedule]):  # fmt: skip
        self.robot = robot
        self.q, self.opening = q, opening
        self.schedules = dict(schedules)
        self.distances = _Distances(robot, scene, _carried_ids(attached), list(self.schedules))

    @property
    def pairs(self) -> list[Pair]:
        return self.distances.pairs

    def frames_at(self, samples: np.ndarray) -> np.ndarray:
        """``(n, L, 4, 4)`` link poses at sample indices ``samples`` (forward kinematics of those samples only)."""
        return self.robot.forward_with_capsules(self.q[samples], self.opening[samples])[0]

    def poses_at(self, obj_id: str, samples: np.ndarray) -> np.ndarray:
        """``(n, 4, 4)`` poses of moving object ``obj_id`` at sample indices ``samples``."""
        tcp = self.frames_at(samples)[:, self.robot.tcp_index]
        return self.schedules[obj_id].at(samples, tcp)

    def compute(self, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """``(frames (n, L, 4, 4), proximity (n, K) m, {object id: poses (n, 4, 4)})`` of samples ``lo..hi-1``."""
        frames, p0, p1 = self.robot.forward_with_capsules(self.q[lo:hi], self.opening[lo:hi])
        tcp = frames[:, self.robot.tcp_index]
        poses = {oid: s.poses(lo, hi, tcp) for oid, s in self.schedules.items()}
        return frames, self.distances.proximity(p0, p1, poses, frames), poses


def build_compact_trajectory(robot, scene: Scene, q, time, *, gripper_opening_m, attached, step, steps,
                             schedules: Mapping[str, PoseSchedule]) -> Trajectory:  # fmt: skip
    """The :class:`Trajectory` of :func:`build_trajectory` that stores only its per-sample joints, time, gripper,
    attachment and step (some 100 bytes a sample) and computes frames, proximity and object poses chunk by chunk
    (:class:`ChunkGeometry`): the form of a long motion, whose whole arrays would take gigabytes."""
    q = np.asarray(q, dtype=float)
    opening = np.asarray(gripper_opening_m, dtype=float)
    attached = np.asarray(attached, dtype=str).reshape(-1)
    geometry = ChunkGeometry(robot, scene, q, opening, attached, schedules)
    return Trajectory(
        q=q,
        time=time,
        frames=None,
        proximity=None,
        pairs=geometry.pairs,
        gripper_opening_m=opening,
        attached=attached,
        step=step,
        steps=steps,
        **_robot_facts(robot),
        geometry=geometry,
    )
