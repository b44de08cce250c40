"""FK + all proximities over a 10,000-sample UR3e trajectory, and ruckig timing of a 6-waypoint motion.

Compares the vectorised trajectory builder (FK for every frame, every self and
environment pair) with the obvious implementation: Pinocchio FK per sample and
``coal.distance`` called pair by pair in a Python loop; the batched FK alone
(``Robot.forward``) with Pinocchio's ``framesForwardKinematics`` per sample; and FK with
the capsule endpoints in one pass (``Robot.forward_with_capsules``, what ``simulate()``
runs) with ``forward`` followed by ``capsule_segments`` of its frames.

Run: .venv/bin/python benchmarks/bench_kinematics.py
"""

from __future__ import annotations

import statistics
import sys
import time

import coal
import numpy as np
import pinocchio as pin

from robocritics import Robot, Scene
from robocritics.planning.timing import Limits, time_joint_move

SAMPLES = 10_000


def six_object_scene() -> Scene:
    return Scene.model_validate(
        {
            "name": "bench",
            "objects": [
                {"id": "box_a", "shape": "box", "size": [0.06, 0.05, 0.08], "position": [0.30, 0.12, 0.04]},
                {"id": "box_b", "shape": "box", "size": [0.10, 0.04, 0.03], "position": [0.22, -0.20, 0.015], "rpy": [0, 0, 0.4]},
                {"id": "cyl_a", "shape": "cylinder", "size": [0.035, 0.10], "position": [0.35, -0.05, 0.05]},
                {"id": "cyl_b", "shape": "cylinder", "size": [0.05, 0.02], "position": [0.15, 0.25, 0.01]},
                {"id": "ball_a", "shape": "sphere", "size": [0.035], "position": [0.40, 0.05, 0.035]},
                {"id": "ball_b", "shape": "sphere", "size": [0.04], "position": [0.25, 0.0, 0.04]},
            ],
        }
    )


def sweep(robot: Robot, samples: int) -> np.ndarray:
    rng = np.random.default_rng(3)
    knots = robot.home_q + rng.uniform(-0.8, 0.8, (12, robot.n))
    s = np.linspace(0, len(knots) - 1, samples)
    return np.stack([np.interp(s, np.arange(len(knots)), knots[:, j]) for j in range(robot.n)], axis=1)


def coal_geometry(kind, size):
    if kind == "box":
        return coal.Box(*size)
    if kind == "cylinder":
        return coal.Cylinder(size[0], size[1])
    return coal.Sphere(size[0])


def transform(R, p):
    t = coal.Transform3s()
    t.setRotation(np.ascontiguousarray(R))
    t.setTranslation(np.ascontiguousarray(p))
    return t


def reference(robot: Robot, scene: Scene, q: np.ndarray, pairs) -> np.ndarray:
    """Per sample: Pinocchio FK, then coal.distance for every pair, in Python loops."""
    data = robot.model.createData()
    caps = []
    for c in robot.capsules:
        p0, p1 = np.array(c.p0), np.array(c.p1)
        axis = p1 - p0
        length = float(np.linalg.norm(axis))
        z = axis / length
        x = np.cross(z, [1.0, 0, 0]) if abs(z[0]) < 0.9 else np.cross(z, [0, 1.0, 0])
        x /= np.linalg.norm(x)
        local = np.eye(4)
        local[:3, :3] = np.column_stack([x, np.cross(z, x), z])
        local[:3, 3] = (p0 + p1) / 2
        caps.append((robot.model.getFrameId(c.frame, pin.FrameType.BODY), coal.Capsule(c.radius_m, length), local))
    shapes = {s.name: (coal_geometry(s.kind, s.size), transform(s.pose[:3, :3], s.pose[:3, 3])) for s in scene.shapes()}
    index = {name: i for i, name in enumerate(robot.capsule_names)}
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    req.gjk_tolerance = 1e-10  # coal's default (1e-6) would blur the comparison
    out = np.empty((len(q), len(pairs)))
    for t in range(len(q)):
        pin.framesForwardKinematics(robot.model, data, q[t])
        poses = []
        for fid, geom, local in caps:
            world = data.oMf[fid].homogeneous @ local
            poses.append((geom, transform(world[:3, :3], world[:3, 3])))
        for k, (a, b) in enumerate(pairs):
            ga, ta = poses[index[a]]
            if b in index:
                gb, tb = poses[index[b]]
            else:
                gb, tb = shapes[b]
            res.clear()
            out[t, k] = coal.distance(ga, ta, gb, tb, req, res)
    return out


def pinocchio_frames(robot: Robot, q: np.ndarray) -> np.ndarray:
    """Every body frame of every sample, one ``framesForwardKinematics`` per sample."""
    data = robot.model.createData()
    ids = [robot.model.getFrameId(name, pin.FrameType.BODY) for name in robot.frame_names]
    out = np.empty((len(q), len(ids), 4, 4))
    for t, qt in enumerate(q):
        pin.framesForwardKinematics(robot.model, data, qt)
        for k, fid in enumerate(ids):
            out[t, k] = data.oMf[fid].homogeneous
    return out


def timed(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), times


def main() -> None:
    robot = Robot.ur3e()
    scene = six_object_scene()
    q = sweep(robot, SAMPLES)
    t = np.arange(SAMPLES) / 125.0
    traj = robot.trajectory(q, t, scene)
    n_pairs = len(traj.pairs)
    fast, _ = timed(lambda: robot.trajectory(q, t, scene), 7)

    # the reference computes the same capsule/shape pairs (entities with one shape each here)
    pairs = [(p.a, p.b if p.kind == "self" else p.b) for p in traj.pairs]
    pairs = [(a, "table" if b == "table" else b) for a, b in pairs]
    ref_samples = 300  # the loop is slow; time a slice and scale
    t0 = time.perf_counter()
    ref = reference(robot, scene, q[:ref_samples], pairs)
    ref_time = (time.perf_counter() - t0) * SAMPLES / ref_samples
    err = np.max(np.abs(ref - traj.proximity[:ref_samples]))

    fk_fast, _ = timed(lambda: robot.forward(q), 7)
    t0 = time.perf_counter()
    fk_ref = pinocchio_frames(robot, q)
    fk_loop = time.perf_counter() - t0
    fk_err = float(np.max(np.abs(fk_ref - robot.forward(q))))
    fused, _ = timed(lambda: robot.forward_with_capsules(q), 7)
    separate, _ = timed(lambda: robot.capsule_segments(robot.forward(q)), 7)

    limits = Limits(robot.velocity_limits, robot.acceleration_limits, robot.jerk_limits)
    rng = np.random.default_rng(5)
    waypoints = robot.home_q + rng.uniform(-1.0, 1.0, (6, robot.n))

    def ruckig_six():
        for a, b in zip(waypoints[:-1], waypoints[1:]):
            time_joint_move(a, b, limits, 1.0, 125.0)

    ruckig_median, _ = timed(ruckig_six, 20)

    rows = [
        ("FK + all proximities, vectorised", f"{fast * 1e3:.1f} ms", f"{SAMPLES} samples x {n_pairs} pairs"),
        ("Pinocchio FK + coal.distance loop", f"{ref_time * 1e3:.0f} ms", f"timed on {ref_samples} samples, scaled"),
        ("speed-up", f"{ref_time / fast:.0f}x", f"max |difference| {err:.2e} m"),
        ("FK only, batched (Robot.forward)", f"{fk_fast * 1e3:.1f} ms", f"{SAMPLES} samples x {len(robot.frame_names)} frames"),
        ("FK only, Pinocchio per sample", f"{fk_loop * 1e3:.0f} ms", f"max |difference| {fk_err:.1e}; speed-up {fk_loop / fk_fast:.1f}x"),
        ("FK + capsule endpoints, one pass", f"{fused * 1e3:.1f} ms", f"forward_with_capsules; forward then capsule_segments {separate * 1e3:.1f} ms"),
        ("ruckig, 6-waypoint joint motion", f"{ruckig_median * 1e3:.2f} ms", "5 rest-to-rest segments, sampled at 125 Hz"),
    ]
    width = max(len(r[0]) for r in rows)
    print(f"{'measure':<{width}}  {'median':>10}  notes")
    for name, value, note in rows:
        print(f"{name:<{width}}  {value:>10}  {note}")
    print(f"\nreproduce: {sys.executable} benchmarks/bench_kinematics.py")


if __name__ == "__main__":
    main()
