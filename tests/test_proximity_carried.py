"""Carried objects against the scene (box/cylinder pairs): the closed-form bounds that spare coal calls.

``_convex_bounds`` and ``_refine_bounds`` must bracket the signed distance (coal at a 1e-12 GJK tolerance;
EPA when overlapping, good to ~1e-5 m on cylinders); where they meet (within ``_CERTIFIED_M``) their value is
the distance. The kernel with ``far_m`` is checked against the kernel and a per-sample coal reference with
every value exact: equal within the cutoff, a lower bound above it beyond.
"""

from __future__ import annotations

import coal
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robocritics.geometry import pairs as PS, proximity as P
from robocritics.scene import Shape, rpy_matrix

SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)


def _coal(kind, size, pose):
    g = coal.Box(*map(float, size)) if kind == "box" else coal.Cylinder(float(size[0]), float(size[1]))
    return g, coal.Transform3s(np.ascontiguousarray(pose[:3, :3]), np.ascontiguousarray(pose[:3, 3]))


def _reference(a: Shape, b: Shape, Pa: np.ndarray, Pb: np.ndarray) -> np.ndarray:
    """One ``coal.distance`` per sample, GJK at 1e-12 (the slow obvious reference)."""
    out = np.empty(len(Pa))
    for t in range(len(Pa)):
        req = coal.DistanceRequest()
        req.gjk_tolerance = 1e-12
        req.gjk_max_iterations = 1000
        req.epa_max_iterations = 256
        out[t] = coal.distance(*_coal(a.kind, a.size, Pa[t]), *_coal(b.kind, b.size, Pb[t]), req, coal.DistanceResult())
    return out


def _tolerance(ref: np.ndarray, kinds) -> np.ndarray:
    """coal's accuracy: GJK ~1e-10 m apart (up to ~1.3e-9 for a tilted cylinder over a box; near contact ~1e-8),
    EPA on cylinders ~1e-5 m."""
    return np.where(ref > 1e-6, 3e-9, np.where(ref > 0.0, 1e-7, 3e-5 if "cylinder" in kinds else 1e-9))


def _shape(kind, rng, name):
    size = tuple(rng.uniform(0.01, 0.2, 3)) if kind == "box" else (float(rng.uniform(0.01, 0.08)), float(rng.uniform(0.02, 0.2)))
    return Shape(name, name, kind, size, np.eye(4))


def _poses(rng, N, spread, tilt):
    poses = np.tile(np.eye(4), (N, 1, 1))
    poses[:, :3, 3] = rng.normal(scale=spread, size=(N, 3))
    for t in range(N):
        # a few exactly upright poses: faces parallel, the degenerate supports that certify
        poses[t, :3, :3] = np.eye(3) if t % 3 == 0 else rpy_matrix(tuple(rng.uniform(-tilt, tilt, 3)))
    return poses


@settings(max_examples=40, **SETTINGS)
@given(
    seed=st.integers(0, 2**31 - 1),
    kinds=st.sampled_from([("box", "box"), ("box", "cylinder"), ("cylinder", "box"), ("cylinder", "cylinder")]),
    spread=st.sampled_from([0.05, 0.15, 0.4]),
    tilt=st.sampled_from([0.0, 0.3, 3.0]),
)
def test_bounds_bracket_the_signed_distance(seed, kinds, spread, tilt):
    """lb <= sd <= ub for random boxes and cylinders (apart, touching, overlapping); the alternating projections
    only tighten them; where the bounds meet, their value is coal's distance."""
    rng = np.random.default_rng(seed)
    N = 30
    a, b = _shape(kinds[0], rng, "a"), _shape(kinds[1], rng, "b")
    Pa, Pb = _poses(rng, N, spread, tilt), _poses(rng, N, spread, tilt)
    A = PS._Convex.of(a.kind, np.tile(PS._half_sizes(a), (N, 1)), Pa)
    B = PS._Convex.of(b.kind, np.tile(PS._half_sizes(b), (N, 1)), Pb)
    ref = _reference(a, b, Pa, Pb)
    tol = _tolerance(ref, kinds)
    lb, ub = PS._convex_bounds(A, B)
    assert (lb <= ref + tol).all(), np.max(lb - ref)
    assert (ub >= ref - tol).all(), np.max(ref - ub)
    lb2, ub2 = PS._refine_bounds(A, B, lb, ub, 4)
    assert (lb2 >= lb).all() and (ub2 <= ub).all()
    assert (lb2 <= ref + tol).all() and (ub2 >= ref - tol).all()
    certified = ub2 - lb2 <= PS._CERTIFIED_M
    np.testing.assert_allclose(ub2[certified], ref[certified], rtol=0, atol=1e-7 if "cylinder" not in kinds else 3e-5)
    apart = certified & (ref > 1e-6)
    np.testing.assert_allclose(ub2[apart], ref[apart], rtol=0, atol=1e-9)


def test_face_contacts_are_certified_in_closed_form():
    """A box hovering over a table, an upright cylinder over a box and beside a wall, boxes sunk into the
    table: the bounds meet at the distance (or depth) that the geometry gives by hand."""
    table = Shape("table", "table", "box", (1.2, 1.2, 0.04), np.eye(4))
    fork = Shape("fork", "fork", "box", (0.02, 0.16, 0.012), np.eye(4))
    cup = Shape("cup", "cup", "cylinder", (0.035, 0.09), np.eye(4))
    wall = Shape("wall", "wall", "box", (0.006, 0.22, 0.08), np.eye(4))
    heights = np.array([0.05, 0.02, 0.0061, 0.026, 0.005])  # centre heights above the table's top face
    N = len(heights)

    def at(z, x=0.0, yaw=0.0):
        pose = np.eye(4)
        pose[:3, :3] = rpy_matrix((0.0, 0.0, yaw))
        pose[:3, 3] = [x, 0.1, z]
        return pose

    def bounds(a, Pa, b, Pb):
        A = PS._Convex.of(a.kind, np.tile(PS._half_sizes(a), (len(Pa), 1)), Pa)
        B = PS._Convex.of(b.kind, np.tile(PS._half_sizes(b), (len(Pb), 1)), Pb)
        return PS._convex_bounds(A, B)

    table_pose = np.tile(at(-0.02), (N, 1, 1))
    fork_poses = np.array([at(z, yaw=0.3 * i) for i, z in enumerate(heights)])
    lb, ub = bounds(fork, fork_poses, table, table_pose)
    np.testing.assert_allclose(ub, heights - 0.006, rtol=0, atol=1e-15)  # at z = 0.005 sunk 1 mm: the exact depth
    assert (ub - lb <= PS._CERTIFIED_M).all()
    cup_poses = np.array([at(z + 0.045) for z in np.abs(heights - 0.005)])
    lb, ub = bounds(cup, cup_poses, table, table_pose)
    np.testing.assert_allclose(ub, np.abs(heights - 0.005), rtol=0, atol=1e-15)
    assert (ub - lb <= PS._CERTIFIED_M).all()
    # beside a wall, within its height: the side against the wall's face
    gaps = np.array([0.001, 0.01, 0.05, 0.0, 0.2])
    wall_pose = np.tile(at(0.04), (N, 1, 1))
    cup_poses = np.array([at(0.05, x=0.003 + 0.035 + g) for g in gaps])
    lb, ub = bounds(cup, cup_poses, wall, wall_pose)
    np.testing.assert_allclose(ub, gaps, rtol=0, atol=1e-15)
    assert (ub - lb <= PS._CERTIFIED_M).all()
    ref = _reference(cup, wall, cup_poses, wall_pose)
    np.testing.assert_allclose(ub, ref, rtol=0, atol=1e-9)


def _carried_path(rng, T):
    """A held object's poses (T, 4, 4): a smooth random path low over the scene, turning slowly, at rest for a while."""
    knots = rng.uniform([-0.15, -0.15, 0.0], [0.15, 0.15, 0.12], size=(5, 3))
    s = np.linspace(0.0, 4.0, T)
    path = np.stack([np.interp(s, np.arange(5), knots[:, i]) for i in range(3)], axis=1)
    path[T // 3 : T // 2] = path[T // 3]  # set down: one run of equal poses
    poses = np.tile(np.eye(4), (T, 1, 1))
    poses[:, :3, 3] = path
    yaw = np.cumsum(rng.normal(scale=0.02, size=T))
    yaw[T // 3 : T // 2] = yaw[T // 3]
    tilt = rng.uniform(-0.2, 0.2) * (rng.uniform() < 0.5)  # upright half the time: face contacts
    for t in range(T):
        poses[t, :3, :3] = rpy_matrix((tilt, 0.0, yaw[t]))
    return poses


def _scene(rng):
    shapes = [
        Shape("table", "table", "box", (1.2, 1.2, 0.04), np.eye(4)),
        Shape("bin.floor", "bin", "box", (0.2, 0.2, 0.006), np.eye(4)),
        Shape("bin.wall", "bin", "box", (0.006, 0.2, 0.08), np.eye(4)),
        Shape("can", "can", "cylinder", (0.03, 0.14), np.eye(4)),
    ]
    out = []
    for s, (x, y, z) in zip(shapes, [(0.0, 0.0, -0.02), (0.05, 0.05, 0.003), (0.15, 0.05, 0.04), (-0.1, 0.05, 0.07)]):
        pose = np.eye(4)
        pose[:3, :3] = rpy_matrix((0.0, 0.0, float(rng.uniform(-0.5, 0.5)) if s.name != "table" else 0.0))
        pose[:3, 3] = [x, y, z]
        out.append(Shape(s.name, s.owner, s.kind, s.size, pose))
    return out


@settings(max_examples=20, **SETTINGS)
@given(seed=st.integers(0, 2**31 - 1), held=st.sampled_from(["box", "cylinder"]), far=st.sampled_from([0.0, 0.03, 0.1]))
def test_carried_pairs_exact_within_the_cutoff_and_bounded_beyond(seed, held, far):
    """Random carried paths past a table, a bin and a can: with ``far_m`` every value within the cutoff equals the
    all-exact kernel (itself coal's distance per sample), every other one is a lower bound above the cutoff; the
    pair asked both ways round has both columns right; and coal is asked for fewer samples than there are runs."""
    rng = np.random.default_rng(seed)
    T = 150
    obj = Shape("obj", "obj", held, (0.06, 0.05, 0.1) if held == "box" else (0.035, 0.09), np.eye(4))
    scene = _scene(rng)
    shapes = scene + [obj]
    pairs = [("obj", s.name) for s in scene] + [("can", "obj")]
    kern = P.ProximityKernel([("link", 0.01)], shapes, pairs, moving={"obj"})
    pose = _carried_path(rng, T)
    args = (np.zeros((T, 1, 3)), np.zeros((T, 1, 3)))
    calls = []
    original = PS._coal_values

    def counting(a, b, Pa, Pb, at):
        calls.append(len(at))
        return original(a, b, Pa, Pb, at)

    PS._coal_values = counting
    try:
        exact = kern.distances(*args, poses={"obj": pose})
        exact_calls = sum(calls)
        D = kern.distances(*args, poses={"obj": pose}, far_m=far)
    finally:
        PS._coal_values = original
    runs = int(PS._pose_changes(pose, T).sum())
    assert exact_calls < len(pairs) * runs  # the closed forms settle some samples
    by = {s.name: s for s in shapes}
    for k, (a, b) in enumerate(pairs):
        Pa = pose if a == "obj" else np.broadcast_to(by[a].pose, (T, 4, 4))
        Pb = pose if b == "obj" else np.broadcast_to(by[b].pose, (T, 4, 4))
        ref = _reference(by[a], by[b], Pa, Pb)
        np.testing.assert_array_less(np.abs(exact[:, k] - ref), _tolerance(ref, (held, by[b if a == "obj" else a].kind)) + 1e-15)
    inside = exact <= far
    np.testing.assert_array_equal(D[inside], exact[inside])
    assert (D[~inside] > far).all() and (D[~inside] <= exact[~inside] + 1e-9).all()
    np.testing.assert_allclose(exact[:, -1], exact[:, pairs.index(("obj", "can"))], rtol=0, atol=3e-5)


def test_shape_shape_cutoff_per_sample():
    """A per-sample cutoff: each run's value is exact up to the largest cutoff of its samples."""
    T = 60
    a = Shape("a", "a", "box", (0.1, 0.1, 0.1), np.eye(4))
    b = Shape("b", "b", "cylinder", (0.05, 0.2), np.eye(4))
    poses = np.tile(np.eye(4), (T, 1, 1))
    poses[:, 0, 3] = np.linspace(-0.6, 0.6, T)
    poses[20:30] = poses[20]
    cut = np.where(np.arange(T) % 2 == 0, 0.02, 0.3)
    exact = PS.shape_shape(a, b, poses, None)
    D = PS.shape_shape(a, b, poses, None, far_m=cut)
    inside = exact <= cut
    inside[20:30] = exact[20:30] <= cut[20:30].max()  # one run: exact up to its largest cutoff
    np.testing.assert_array_equal(D[inside], exact[inside])
    assert (D[~inside] > cut[~inside]).all() and (D[~inside] <= exact[~inside] + 1e-12).all()
