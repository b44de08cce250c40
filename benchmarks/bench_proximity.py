"""Timing of the exact capsule distance kernels (robocritics.geometry.proximity) on trajectory-sized arrays.

Run: ``python benchmarks/bench_proximity.py`` (single thread is what counts; set
OMP_NUM_THREADS=1 to be sure numpy's linear algebra does not spread).
Cases: the UR3e (10 capsules) on a pick-and-place-like joint trajectory of
T = 10,000 samples through each built-in scene (every capsule against every
scene shape, plus the robot's self pairs), with the FK time for scale; a
synthetic chain of 10 capsules wandering through the scenes (many more
contacts, so more depth computations); an object carried low over each scene
against its boxes and cylinders (the closed-form bounds and the coal calls they
leave); and the pure kernels on flat arrays.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from robocritics.geometry.kernels import _point_seg_sq, _seg_box_sq, _seg_cyl_sq, _seg_seg_sq
from robocritics.geometry.proximity import ProximityKernel
from robocritics.scene import Scene


def capsule_trajectory(T: int, C: int = 10, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Capsule endpoints (T, C, 3) m: a chain of C links wandering smoothly above the table."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0.0, 1.0, T)[:, None]
    # smooth random joint-like angles
    freqs = rng.uniform(0.5, 3.0, (1, C))
    phase = rng.uniform(0, 2 * np.pi, (1, C))
    yaw = np.sin(2 * np.pi * freqs * s + phase) * 2.0
    pitch = np.cos(2 * np.pi * freqs * 0.7 * s + phase) * 1.2
    lengths = rng.uniform(0.05, 0.25, C)
    dirs = np.stack([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)], axis=-1)
    seg = dirs * lengths[None, :, None]
    p1 = np.cumsum(seg, axis=1) + np.array([0.0, 0.0, 0.15])
    p0 = p1 - seg
    return p0, p1


def timeit(fn, repeat: int = 5) -> float:
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("-T", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    T = args.T
    bench_ur3e(T, args.repeat)
    bench_carried(T, args.repeat)
    p0, p1 = capsule_trajectory(T)
    C = p0.shape[1]
    caps = [(f"c{i}", 0.04) for i in range(C)]
    self_pairs = [(f"c{i}", f"c{j}") for i in range(C) for j in range(i + 2, C)][:20]
    for name in Scene.builtin_names():
        shapes = Scene.builtin(name).shapes()
        pairs = [(c, s.name) for c, _ in caps for s in shapes]
        kinds = {k: sum(s.kind == k for s in shapes) for k in ("box", "cylinder", "sphere")}
        kern = ProximityKernel(caps, shapes, pairs + self_pairs)
        dt = timeit(lambda: kern.distances(p0, p1), args.repeat)
        n = T * len(kern.pairs)
        print(f"{name:10s} shapes {kinds}: {len(kern.pairs)} pairs x {T} samples = {n/1e6:.2f}M distances: {dt*1e3:7.1f} ms ({dt/n*1e9:.0f} ns each)")
    # the brief's mix: 10 capsules x 7 shapes (3 box, 2 cylinder, 2 sphere)
    from robocritics.scene import Shape, rpy_matrix

    rng = np.random.default_rng(1)
    shapes = []
    for i, kind in enumerate(["box", "box", "box", "cylinder", "cylinder", "sphere", "sphere"]):
        pose = np.eye(4)
        pose[:3, :3] = rpy_matrix(tuple(rng.uniform(-0.3, 0.3, 3)))
        pose[:3, 3] = rng.uniform([-0.4, -0.4, 0.0], [0.4, 0.4, 0.2])
        size = {"box": (0.1, 0.08, 0.12), "cylinder": (0.04, 0.12), "sphere": (0.04,)}[kind]
        shapes.append(Shape(f"s{i}", f"s{i}", kind, size, pose))
    pairs = [(c, s.name) for c, _ in caps for s in shapes]
    kern = ProximityKernel(caps, shapes, pairs)
    dt = timeit(lambda: kern.distances(p0, p1), args.repeat)
    n = T * len(pairs)
    print(f"mix 10x7 (3 box, 2 cyl, 2 sphere): {n/1e6:.2f}M distances: {dt*1e3:7.1f} ms ({dt/n*1e9:.0f} ns each)")
    kern = ProximityKernel(caps, [], self_pairs)
    dt = timeit(lambda: kern.distances(p0, p1), args.repeat)
    print(f"self pairs: {len(self_pairs)} x {T}: {dt*1e3:7.1f} ms")
    # flat kernels
    N = 700_000
    a = rng.uniform(-0.4, 0.4, (3, N))
    d = rng.normal(size=(3, N)) * 0.15
    for label, fn in [
        ("_seg_box_sq", lambda: _seg_box_sq(*a, *d, 0.0, 0.0, 0.0, 0.05, 0.04, 0.06)),
        ("_seg_cyl_sq", lambda: _seg_cyl_sq(*a, *d, 0.0, 0.0, 0.0, 0.04, 0.06)),
        ("_point_seg_sq", lambda: _point_seg_sq(0.1, 0.0, 0.1, *a, *d)),
        ("_seg_seg_sq", lambda: _seg_seg_sq(*a, *d, *(a[::-1] * 0.9), *(d[::-1]))),
    ]:
        dt = timeit(fn, args.repeat)
        print(f"flat {label:14s} N={N} in one array (memory-bound; the kernel works in cache-sized chunks): {dt*1e3:7.1f} ms ({dt/N*1e9:.0f} ns each)")



def ur3e_case(T: int = 10_000, scene_name: str = "breakfast"):
    """A pick-and-place-like UR3e joint trajectory (T samples) through a built-in scene.

    Joint-space straight lines between IK solutions above and at every object, the
    way a program visits them; returns (robot, scene, q).
    """
    from robocritics.robot.model import Robot

    robot = Robot.ur3e()
    scene = Scene.builtin(scene_name)
    targets = [robot.home_q]
    seed = robot.home_q
    for o in scene.objects:
        for z in (o.top + 0.12, o.top - 0.01, o.top + 0.12):
            try:
                q = robot.ik((o.position[0], o.position[1], z), seed=seed)
            except Exception:
                continue
            targets.append(q)
            seed = q
    targets.append(robot.home_q)
    targets = np.array(targets)
    s = np.linspace(0, len(targets) - 1, T)
    i = np.minimum(s.astype(int), len(targets) - 2)
    f = (s - i)[:, None]
    f = f * f * (3 - 2 * f)  # smoothstep between waypoints
    q = targets[i] * (1 - f) + targets[i + 1] * f
    return robot, scene, q


def bench_ur3e(T: int, repeat: int) -> None:
    for scene_name in Scene.builtin_names():
        robot, scene, q = ur3e_case(T, scene_name)
        shapes = scene.shapes()
        caps = list(zip(robot.capsule_names, robot.capsule_radii))
        env = [(c, s.name) for c in robot.capsule_names for s in shapes]
        pairs = list(robot.self_pairs) + env
        kern = ProximityKernel(caps, shapes, pairs)

        def fk():
            return robot.capsule_segments(robot.forward(q))

        p0, p1 = fk()
        t_fk = timeit(fk, repeat)
        t_exact = timeit(lambda: kern.distances(p0, p1), repeat)
        t_far = timeit(lambda: kern.distances(p0, p1, far_m=0.1), repeat)
        D = kern.distances(p0, p1)
        print(
            f"UR3e {scene_name:9s} T={T}: {len(robot.capsule_names)} capsules, {len(shapes)} shapes, "
            f"{len(robot.self_pairs)} self + {len(env)} env pairs; FK+segments {t_fk*1e3:5.1f} ms, "
            f"proximity exact {t_exact*1e3:5.1f} ms, far_m=0.1 {t_far*1e3:5.1f} ms; "
            f"min distance {D.min():+.3f} m"
        )


def bench_carried(T: int, repeat: int) -> None:
    """A box and a cylinder carried low over each built-in scene (a new pose every sample, upright, turning
    slowly), against every box and cylinder of the scene: the time, and how many samples still went to coal."""
    from robocritics.geometry import pairs as shape_pairs
    from robocritics.scene import Shape, rpy_matrix

    s = np.linspace(0.0, 1.0, T)
    poses = np.tile(np.eye(4), (T, 1, 1))
    poses[:, :3, 3] = np.stack([0.3 * np.cos(2 * np.pi * s), 0.3 * np.sin(2 * np.pi * s), 0.06 + 0.1 * s * (1 - s)], axis=1)
    for t in range(T):
        poses[t, :3, :3] = rpy_matrix((0.0, 0.0, 3.0 * s[t]))
    asked = [0]
    coal_values = shape_pairs._coal_values

    def counting(a, b, Pa, Pb, at):
        asked[0] += len(at)
        return coal_values(a, b, Pa, Pb, at)

    for kind, size in (("box", (0.06, 0.05, 0.1)), ("cylinder", (0.035, 0.09))):
        for name in Scene.builtin_names():
            shapes = [sh for sh in Scene.builtin(name).shapes() if sh.kind != "sphere"]
            held = Shape("held", "held", kind, size, np.eye(4))
            kern = ProximityKernel([("link", 0.01)], shapes + [held], [("held", sh.name) for sh in shapes], moving={"held"})
            z = np.zeros((T, 1, 3))
            t_exact = timeit(lambda: kern.distances(z, z, poses={"held": poses}), repeat)
            t_far = timeit(lambda: kern.distances(z, z, poses={"held": poses}, far_m=0.1), repeat)
            shape_pairs._coal_values = counting
            try:
                asked[0] = 0
                kern.distances(z, z, poses={"held": poses})
                n_exact = asked[0]
                asked[0] = 0
                kern.distances(z, z, poses={"held": poses}, far_m=0.1)
                n_far = asked[0]
            finally:
                shape_pairs._coal_values = coal_values
            n = T * len(shapes)
            print(
                f"carried {kind:8s} over {name:9s} T={T}: {len(shapes)} pairs; exact {t_exact*1e3:6.1f} ms "
                f"(coal for {n_exact}/{n} samples), far_m=0.1 {t_far*1e3:6.1f} ms (coal for {n_far})"
            )


if __name__ == "__main__":
    main()
