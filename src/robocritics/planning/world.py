"""The world while a program runs: where each object is, what the gripper holds, what rests on what.

The planner (:mod:`robocritics.planning.planner`) moves the arm; this is its bookkeeping of the objects: the
graspable object between the fingers, the surface an object settles on when released (a container floor, another
object, the table), what falls when the object under it is lifted, the intended contacts at a TCP pose (which
the collision critic does not count), and at the end every moved object's pose per sample. Metres, base frame.
"""

from __future__ import annotations

import math

import numpy as np

from ..robot.model import Robot
from ..scene import Scene, SceneObject, rpy_matrix

__all__ = ["World", "ON_SURFACE_M"]

#: A point this close to a container floor [m] (above or below) is on it.
ON_SURFACE_M = 1e-6


class World:
    """The scene's objects as a program moves them; one instance per program run.

    ``settings`` is the planner's :class:`~robocritics.planning.planner.PlannerSettings` (grasp region, stacking
    tolerances); ``robot`` gives the gripper's opening.
    """

    def __init__(self, scene: Scene, robot: Robot, settings) -> None:
        self.scene = scene
        self.robot = robot
        self.settings = settings
        self.objects: dict[str, SceneObject] = {o.id: o for o in scene.objects}
        self.attached: str = ""
        self.grasp_offset = np.eye(4)  # object pose in the tcp frame while attached
        self.resting_on: dict[str, str] = {}
        # the object just grasped: what rests on it falls at the first sample of the next motion (the lift)
        self.pending_lift: str = ""
        # per attachment interval: (object id, first sample, last sample exclusive, offset)
        self.carry: list[tuple[str, int, int, np.ndarray]] = []
        # poses of objects at rest, changing when released: (object id, first sample, pose)
        self.rest_changes: list[tuple[str, int, np.ndarray]] = []

    def grasp_candidate(self, tcp: np.ndarray) -> str | None:
        """The graspable object whose centre lies between the fingers at TCP pose ``tcp`` (the nearest to the TCP)."""
        best, best_d = None, math.inf
        (r00, r01, r02, tx), (r10, r11, r12, ty), (r20, r21, r22, tz) = tcp[:3].tolist()
        for oid, o in self.objects.items():
            if oid == self.attached or not o.graspable:
                continue
            # R^T (p - t): the rigid inverse, no general 4x4 inverse; on Python floats (three objects' worth of
            # numpy calls cost more than the arithmetic)
            dx, dy, dz = o.position[0] - tx, o.position[1] - ty, o.position[2] - tz
            local = (dx * r00 + dy * r10 + dz * r20, dx * r01 + dy * r11 + dz * r21, dx * r02 + dy * r12 + dz * r22)
            # local z: along the fingers (+ beyond the tips); y: closing axis; x: finger width
            if abs(local[0]) > self.settings.grasp_region_m or abs(local[1]) > self.robot.max_opening_m / 2:
                continue
            if not (-self.settings.grasp_depth_m <= local[2] <= o.half_height + self.settings.grasp_tip_gap_m):
                continue
            # the centre nearest the TCP: in a stack every centre is on the finger axis (lateral distances tie,
            # up to rounding), and the one the fingers close on is the one at the TCP's height
            d = math.hypot(local[0], local[1], local[2])
            if d < best_d:
                best, best_d = oid, d
        return best

    def support_below(
        self, oid: str, position: np.ndarray, half_height: float, radius: float, ignore: str = ""
    ) -> tuple[str, float]:
        """The entity an object at ``position`` would settle on (not object ``ignore``), and the z of that surface [m]."""
        best_id, best_z = "table", self.scene.table.top_z
        for c in self.scene.containers:
            floor = c.floor_top
            # the cheap comparisons first: they rule most containers out without the point test
            if position[2] >= floor - ON_SURFACE_M and floor > best_z:
                if c.contains_point((position[0], position[1], floor + ON_SURFACE_M)):
                    best_id, best_z = c.id, floor
        footprint, gap = self.settings.stack_footprint_fraction, self.settings.stack_gap_m
        for other_id, other in self.objects.items():
            if other_id == oid or other_id == ignore:
                continue
            horizontal = math.hypot(other.position[0] - position[0], other.position[1] - position[1])
            if horizontal < max(radius, other.width / 2) * footprint and other.top <= position[2] - half_height + gap:
                if other.top > best_z:
                    best_id, best_z = other_id, other.top
        return best_id, best_z

    def contacts_at(self, tcp: np.ndarray) -> set[str]:
        """Entities the gripper or its load may touch at TCP pose ``tcp``.

        The object between the fingers, and the surface under the object in (or
        about to be in) the hand; a container floor lies on the table, so an
        object on it is a few millimetres above the table too.
        """
        out: set[str] = set()
        supports: list[str] = []
        cand = self.grasp_candidate(tcp)
        if cand:
            out.add(cand)
            o = self.objects[cand]
            supports.append(self.support_below(cand, np.asarray(o.position), o.half_height, o.width / 2)[0])
        if self.attached:
            o = self.objects[self.attached]
            pose = tcp @ self.grasp_offset
            supports.append(self.support_below(self.attached, pose[:3, 3], o.half_height, o.width / 2)[0])
        out.update(supports)
        # what a support itself stands on is millimetres under the load too (a plate on the table)
        for s in supports:
            if s in self.objects:
                o = self.objects[s]
                out.add(self.support_below(s, np.asarray(o.position), o.half_height, o.width / 2)[0])
            elif s != "table":
                out.add("table")
        return out

    def drop_unsupported(self, lifted: str, sample: int) -> list[tuple[str, str, float]]:
        """Everything resting on ``lifted`` (transitively) falls to the highest support below its footprint, at
        ``sample``; returns ``(object, what it fell onto, drop [m])`` per fallen object.

        Runs as the lift starts (the first sample of the motion after the grasp), so the fall is instantaneous
        at that sample; lower objects settle first so that a stack keeps its order.
        """
        self.pending_lift = ""
        # a mesh fixture is bolted down: it never falls
        others = [oid for oid in self.objects if oid not in (lifted, self.attached) and self.objects[oid].shape != "mesh"]
        support = {}
        for oid in others:
            o = self.objects[oid]
            support[oid] = self.resting_on.get(oid) or self.support_below(oid, np.asarray(o.position), o.half_height, o.width / 2)[0]
        falling: set[str] = set()
        frontier = [lifted]
        while frontier:
            below = frontier.pop()
            for oid in others:
                if support[oid] == below and oid not in falling:
                    falling.add(oid)
                    frontier.append(oid)
        fallen = []
        for oid in sorted(falling, key=lambda i: self.objects[i].bottom):
            o = self.objects[oid]
            below, z = self.support_below(oid, np.asarray(o.position), o.half_height, o.width / 2, ignore=lifted)
            settled = (o.position[0], o.position[1], z + o.half_height)
            drop = o.position[2] - settled[2]
            self.objects[oid] = o.moved_to(settled)
            self.resting_on[oid] = below
            pose = np.eye(4)
            pose[:3, :3], pose[:3, 3] = rpy_matrix(o.rpy), settled
            self.rest_changes.append((oid, sample, pose))
            fallen.append((oid, below, drop))
        return fallen

    def object_poses(self, tcp: np.ndarray) -> dict[str, np.ndarray]:
        """Per-sample pose ``(T, 4, 4)`` of every object that moves during the program."""
        T = tcp.shape[0]
        moved = {c[0] for c in self.carry} | {r[0] for r in self.rest_changes}  # carried or fallen
        out: dict[str, np.ndarray] = {}
        for oid in moved:
            o = next(o for o in self.scene.objects if o.id == oid)
            rest = np.eye(4)
            rest[:3, :3], rest[:3, 3] = rpy_matrix(o.rpy), o.position
            poses = np.broadcast_to(rest, (T, 4, 4)).copy()
            events = sorted(
                [(first, "carry", (last if last >= 0 else T), off) for (cid, first, last, off) in self.carry if cid == oid]
                + [(first, "rest", None, pose) for (cid, first, pose) in self.rest_changes if cid == oid],
                key=lambda e: e[0],
            )
            for first, kind, last, data in events:
                if kind == "rest":
                    poses[first:] = data
                else:
                    poses[first:last] = tcp[first:last] @ data
                    if last < T:
                        poses[last:] = tcp[last - 1] @ data
            out[oid] = poses
        return out
