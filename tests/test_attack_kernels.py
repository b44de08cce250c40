"""Adversarial inputs for the fast check kernels, each against a slow obvious reference.

* ``ProximityKernel.distances(far_m=..., exact_min_of=...)`` with carried boxes and cylinders in the poses the
  closed-form bounds find hardest (1 mm thin boxes, a 1 m cylinder lying down, tilted, edge-on and corner-down
  contacts, gaps of 0, 1e-13 and 1e-9 m, penetration, identical and nested poses, 100 m and 0.1 mm objects,
  coordinates 1e7 m out): values at or below the cutoff equal the all-exact kernel bit for bit, the others are
  lower bounds above the cutoff; the all-exact values equal the distance the geometry gives by hand (or coal's,
  where coal is accurate).
* Capsule groups with ``far_m`` at block (32 samples) and chunk edges, a still capsule and a zero-length one.
* ``Robot.forward`` / ``forward_with_capsules`` against Pinocchio at the 2,000-sample block edges, for huge
  angles, strided, Fortran-ordered and float32 ``q``, on every bundled arm.
* ``robocritics._arrays`` against numpy on NaN, -0.0, empty and one-element inputs, and ``trajectory._array``'s
  finiteness check against ``np.isfinite``.
"""

from __future__ import annotations

import coal
import numpy as np
import pytest

from fk_reference import capsule_reference, pinocchio_frames

from robocritics import Robot
from robocritics import _arrays as A
from robocritics.geometry import proximity as P
from robocritics.scene import Shape, rpy_matrix
from robocritics.trajectory import TrajectoryError, _array


def _pose(xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3] = rpy_matrix(tuple(float(v) for v in rpy))
    pose[:3, 3] = xyz
    return pose


def _coal_distance(a: Shape, pa: np.ndarray, b: Shape, pb: np.ndarray) -> float:
    """One ``coal.distance`` at a 1e-12 GJK tolerance (EPA when overlapping)."""

    def geometry(s, pose):
        g = coal.Box(*map(float, s.size)) if s.kind == "box" else coal.Cylinder(float(s.size[0]), float(s.size[1]))
        return g, coal.Transform3s(np.ascontiguousarray(pose[:3, :3]), np.ascontiguousarray(pose[:3, 3]))

    req = coal.DistanceRequest()
    req.gjk_tolerance = 1e-12
    req.gjk_max_iterations = 1000
    req.epa_max_iterations = 256
    return coal.distance(*geometry(a, pa), *geometry(b, pb), req, coal.DistanceResult())


# --- carried boxes and cylinders against a scene ------------------------------------------------------------

TABLE = Shape("table", "table", "box", (1.2, 1.2, 0.04), _pose((0, 0, -0.02)))  # top face at z = 0
WALL = Shape("wall", "wall", "box", (0.006, 0.4, 0.2), _pose((0.3, 0, 0.1)))  # face at x = 0.297
CAN = Shape("can", "can", "cylinder", (0.03, 0.14), _pose((-0.2, 0.1, 0.07)))  # top at z = 0.14
TILTED = Shape("tilted", "tilted", "box", (0.1, 0.05, 0.02), _pose((0.0, -0.3, 0.1), (0.3, 0.7, 0.2)))
LYING = Shape("lying", "lying", "cylinder", (0.02, 0.5), _pose((0.0, 0.3, 0.02), (np.pi / 2, 0, 0)))
SCENE = [TABLE, WALL, CAN, TILTED, LYING]

#: gaps (m) to the contact: touching, rounding-level, near, at and around the 0.03 m cutoff, penetrating
GAPS = np.array([0.0, 1e-13, 1e-9, 1e-7, 1e-6, 1e-3, 0.0299999, 0.03, 0.0300001, 0.1, -1e-9, -1e-4])
FARS = (0.0, 1e-3, 0.03, 0.1)


def _box(size):
    return Shape("obj", "obj", "box", tuple(size), np.eye(4))


def _cylinder(radius, height):
    return Shape("obj", "obj", "cylinder", (radius, height), np.eye(4))


def _kernel(obj: Shape) -> tuple[P.ProximityKernel, list[tuple[str, str]]]:
    # the table pair both ways round: the twin column reuses the first one's values
    pairs = [("obj", s.name) for s in SCENE] + [("table", "obj")]
    return P.ProximityKernel([("link", 0.01)], SCENE + [obj], pairs, moving={"obj"}), pairs


def _far_matches_exact(obj: Shape, poses: np.ndarray, tight: bool = False) -> np.ndarray:
    """Check the ``far_m`` contract against the all-exact kernel; return the exact ``(T, K)`` values."""
    poses = np.asarray(poses, dtype=float)
    T = len(poses)
    kern, pairs = _kernel(obj)
    far_capsules = np.full((T, 1, 3), 50.0)  # the capsule is far from everything: only the shape pairs matter
    exact = kern.distances(far_capsules, far_capsules, poses={"obj": poses})
    # the twin column: coal's GJK is symmetric to its tolerance, EPA (overlapping) only to ~1e-5 m on cylinders
    np.testing.assert_allclose(exact[:, -1], exact[:, 0], rtol=0, atol=1e-9 if obj.kind == "box" else 3e-5)
    for far in FARS:
        for columns in [None, list(range(len(pairs)))] if tight else [None]:
            D = kern.distances(far_capsules, far_capsules, poses={"obj": poses}, far_m=far, exact_min_of=columns)
            cut = np.full(T, far) if columns is None else np.maximum(far, exact.min(axis=1))
            inside = exact <= cut[:, None]
            np.testing.assert_array_equal(D[inside], exact[inside])
            assert (D[~inside] > np.broadcast_to(cut[:, None], D.shape)[~inside]).all()
            assert (D[~inside] <= exact[~inside] + 1e-9).all()
            if columns is not None:
                np.testing.assert_array_equal(D.min(axis=1), exact.min(axis=1))
    return exact


def _assert_gaps(values, gaps, apart_atol=1e-15):
    """``values`` are the signed distances ``gaps``: to ``apart_atol`` where the gap is >= 1 um (the closed forms
    and GJK); coal's accuracy nearer (GJK ~1e-9 m near contact) and overlapping (EPA, ~3e-5 m on cylinders)."""
    gaps = np.asarray(gaps)
    tol = np.where(gaps >= 1e-6, apart_atol, np.where(gaps >= 0.0, 1e-8, 3e-5))
    np.testing.assert_array_less(np.abs(values - gaps), tol + 1e-300)


def test_thin_box_flat_and_edge_down_over_the_table():
    """A 1 mm plate yawed flat over the table, and tilted 0.4 rad onto a long edge: distance = lowest point's z."""
    thin = _box((0.2, 0.1, 0.001))
    flat = _far_matches_exact(thin, [_pose((0, 0, 0.0005 + g), (0, 0, 0.3 * i)) for i, g in enumerate(GAPS)])
    _assert_gaps(flat[:, 0], GAPS)
    low = 0.05 * np.sin(0.4) + 0.0005 * np.cos(0.4)  # the centre's height over its lowest edge
    edge = _far_matches_exact(thin, [_pose((0, 0, low + g), (0.4, 0, 0)) for g in GAPS])
    _assert_gaps(edge[:, 0], GAPS)


def test_long_cylinder_lying_down_and_standing_on_the_table():
    long = _cylinder(0.005, 1.0)
    # lying down, a line contact that no closed form certifies: coal's GJK (and EPA) values
    lying = _far_matches_exact(long, [_pose((0, 0, 0.005 + g), (np.pi / 2, 0, 0.1 * i)) for i, g in enumerate(GAPS)])
    _assert_gaps(lying[:, 0], GAPS, apart_atol=1e-9)
    standing = _far_matches_exact(long, [_pose((0.05, 0.05, 0.5 + g)) for g in GAPS])
    _assert_gaps(standing[:, 0], GAPS)


def test_cup_beside_the_wall_on_the_can_and_rim_to_rim():
    cup = _cylinder(0.035, 0.09)
    side = _far_matches_exact(cup, [_pose((0.297 - 0.035 - g, 0, 0.1)) for g in GAPS])
    _assert_gaps(side[:, 1], GAPS)
    stacked = _far_matches_exact(cup, [_pose((-0.2, 0.1, 0.14 + 0.045 + g)) for g in GAPS])
    _assert_gaps(stacked[:, 2], GAPS)
    # standing on the can's top plane, its bottom rim beside (g > 0) or over (g < 0) the can's top rim: the gap
    # between the rims, or touching faces (distance 0: the overlap has no volume)
    rims = _far_matches_exact(cup, [_pose((-0.2 + 0.065 + g, 0.1, 0.14 + 0.045)) for g in GAPS])
    _assert_gaps(rims[:, 2], np.maximum(GAPS, 0.0), apart_atol=1e-9)


def test_tilted_cup_over_the_table_is_the_lowest_rim_point():
    """Tilted by 0.2 rad, the lowest point of the bottom rim is R sin 0.2 + H/2 cos 0.2 below the centre (coal's
    GJK is ~1e-9 m off here; the kernel's closed form is not)."""
    cup = _cylinder(0.035, 0.09)
    drop = 0.045 * np.cos(0.2) + 0.035 * np.sin(0.2)
    exact = _far_matches_exact(cup, [_pose((0.1, 0.1, drop + g), (0.2, 0, 0)) for g in GAPS])
    _assert_gaps(exact[:, 0], GAPS)


def test_box_face_edge_and_corner_contacts():
    cube = _box((0.05, 0.05, 0.05))
    face = _far_matches_exact(cube, [_pose((0.297 - 0.025 - g, 0.1, 0.1)) for g in GAPS])
    _assert_gaps(face[:, 1], GAPS)
    edge = _far_matches_exact(cube, [_pose((0.297 - 0.025 * np.sqrt(2) - g, 0.1, 0.1), (0, 0, np.pi / 4)) for g in GAPS])
    _assert_gaps(edge[:, 1], GAPS)
    corner_rpy = (0.6, 0.7, 0.2)  # a corner lowest: its height under the centre is sum_i h_i |R^T z|_i
    drop = 0.025 * np.abs(_pose(rpy=corner_rpy)[2, :3]).sum()
    corner = _far_matches_exact(cube, [_pose((0, 0, drop + g), corner_rpy) for g in GAPS])
    _assert_gaps(corner[:, 0], GAPS)


def test_identical_and_nested_poses():
    """An object exactly where a scene shape is (all faces coincide), and a small cube deep inside a tilted box:
    the contract holds and the depth is the half-width the object must move to get out."""
    same = _far_matches_exact(_box(TILTED.size), [TILTED.pose] * 5)
    np.testing.assert_allclose(same[:, 3], -0.02, rtol=0, atol=1e-9)  # the thinnest side's full thickness
    nested = _far_matches_exact(_box((0.01, 0.01, 0.01)), [TILTED.pose] * 3)
    np.testing.assert_allclose(nested[:, 3], -0.015, rtol=0, atol=1e-9)  # 0.01 to the nearest face + 0.005
    _far_matches_exact(_cylinder(*CAN.size), [CAN.pose] * 4)
    _far_matches_exact(_cylinder(*LYING.size), [LYING.pose] * 4)


def test_huge_and_tiny_objects_and_far_coordinates():
    huge = _far_matches_exact(_box((100, 100, 100)), [_pose((0, 0, 50 + g)) for g in GAPS])
    _assert_gaps(huge[:, 0], GAPS, apart_atol=1e-12)
    tiny_box = _far_matches_exact(_box((1e-4, 1e-4, 1e-4)), [_pose((0, 0, 5e-5 + g)) for g in GAPS])
    _assert_gaps(tiny_box[:, 0], GAPS)
    tiny_cyl = _far_matches_exact(_cylinder(1e-4, 1e-4), [_pose((0, 0, 5e-5 + g)) for g in GAPS])
    _assert_gaps(tiny_cyl[:, 0], GAPS)
    cube = _box((0.05, 0.05, 0.05))
    far = _far_matches_exact(cube, [_pose((1e7, 0, 0.5)), _pose((-1e7, 1e7, 1e7), (1, 2, 3)), _pose((1e4, 0, 0.5))])
    # beyond the table's corner edge at x = 0.6, z = 0 (the cube 0.475 m up): the distance to that edge
    np.testing.assert_allclose(far[0, 0], np.hypot(1e7 - 0.6 - 0.025, 0.475), rtol=1e-12)
    np.testing.assert_allclose(far[2, 0], np.hypot(1e4 - 0.6 - 0.025, 0.475), rtol=1e-12)


@pytest.mark.parametrize(
    "obj", [_box((0.05, 0.05, 0.05)), _cylinder(0.035, 0.09), _box((0.2, 0.1, 0.001)), _cylinder(0.005, 1.0)]
)
def test_a_new_random_pose_every_sample(obj):
    """Poses that change every sample, anywhere among the shapes and any orientation; the contract with and
    without ``exact_min_of``, and the exact values against coal where it is accurate (apart by > 1 um)."""
    rng = np.random.default_rng(7)
    poses = np.array(
        [_pose(rng.uniform([-0.35, -0.4, -0.05], [0.35, 0.4, 0.25]), rng.uniform(-3, 3, 3)) for _ in range(120)]
    )
    exact = _far_matches_exact(obj, poses, tight=True)
    for t in range(0, len(poses), 3):
        for k, s in enumerate(SCENE):
            ref = _coal_distance(obj, poses[t], s, s.pose)
            if ref > 1e-6:
                assert abs(exact[t, k] - ref) <= 1e-8, (t, s.name, exact[t, k], ref)
            else:  # touching or overlapping: the same side of contact, EPA's accuracy
                assert abs(exact[t, k] - ref) <= 3e-5, (t, s.name, exact[t, k], ref)


def test_still_and_slowly_descending_objects():
    cup, cube = _cylinder(0.035, 0.09), _box((0.05, 0.05, 0.05))
    still = _far_matches_exact(cup, [_pose((0.1, 0.1, 0.046))] * 200, tight=True)
    np.testing.assert_allclose(still[:, 0], 0.001, rtol=0, atol=1e-15)
    z = np.linspace(-0.01, 0.05, 400)  # through contact with the table, one sample 0.15 mm lower each time
    descent = _far_matches_exact(cube, [_pose((0.1, 0.1, 0.025 + h), (0, 0, 0.5)) for h in z], tight=True)
    _assert_gaps(descent[:, 0], z)
    drop = 0.045 * np.cos(0.2) + 0.035 * np.sin(0.2)
    tilted = _far_matches_exact(cup, [_pose((0.1, 0.1, drop + h), (0.2, 0, 0)) for h in z], tight=True)
    _assert_gaps(tilted[:, 0], z)


# --- capsule groups at block and chunk edges ------------------------------------------------------------------


def _smooth(rng, T, lo, hi, knots=6):
    k = rng.uniform(lo, hi, size=(knots, 3))
    s = np.linspace(0, knots - 1, T)
    return np.stack([np.interp(s, np.arange(knots), k[:, i]) for i in range(3)], axis=1)


@pytest.mark.parametrize("T", [1, 2, 31, 32, 33, 65, 257, 2049])
@pytest.mark.parametrize("chunk", [16384, 300])
def test_capsule_groups_with_a_cutoff_at_block_and_chunk_edges(T, chunk):
    """Five capsules (one still, one of zero length, radii 0 to 5 cm) past boxes, cylinders and a ball, a carried
    cylinder among them, chunks of 300 pair-samples (several per group) or one: every value within the cutoff
    is the all-exact value, the rest are lower bounds above it, and the minimum over ``exact_min_of`` is exact.
    (Capsule values match to 1e-15 m, not bit for bit: at T = 1 a capsule's value can differ in the last
    two bits with the cutoff, as the group's batches are shaped differently.)"""
    rng = np.random.default_rng(T * 7 + chunk)
    radii = [0.001, 0.01, 0.03, 0.05, 0.0]
    caps = [(f"c{i}", r) for i, r in enumerate(radii)]
    p0 = np.stack([_smooth(rng, T, [-0.35, -0.4, -0.05], [0.35, 0.4, 0.25]) for _ in radii], axis=1)
    p1 = p0 + np.stack([_smooth(rng, T, [-0.2] * 3, [0.2] * 3) for _ in radii], axis=1)
    p1[:, 4] = p0[:, 4]  # a point
    p0[:, 3], p1[:, 3] = p0[0, 3], p1[0, 3]  # a capsule that never moves
    if T > 3:
        p0[T // 3 : T // 2], p1[T // 3 : T // 2] = p0[T // 3], p1[T // 3]  # everything at rest for a while
    ball = Shape("ball", "ball", "sphere", (0.04,), _pose((0.1, -0.1, 0.05)))
    obj = _cylinder(0.035, 0.09)
    shapes = SCENE + [ball, obj]
    pairs = [(c, s.name) for c, _ in caps for s in shapes] + [("c0", "c2"), ("c1", "c3"), ("c4", "c0")]
    pairs += [("obj", s.name) for s in SCENE]
    kern = P.ProximityKernel(caps, shapes, pairs, moving={"obj"}, chunk=chunk)
    held = np.tile(np.eye(4), (T, 1, 1))
    held[:, :3, 3] = _smooth(rng, T, [-0.3, -0.35, 0.0], [0.3, 0.35, 0.2])
    yaw = np.cumsum(rng.normal(scale=0.05, size=T))
    held[:, :3, :3] = [rpy_matrix((0.3, 0.0, float(y))) for y in yaw]
    poses = {"obj": held}
    exact = kern.distances(p0, p1, poses=poses)
    columns = [k for k, (a, _) in enumerate(pairs) if a == "c2"]
    for far in (0.0, 0.005, 0.05):
        for tight in (None, columns):
            D = kern.distances(p0, p1, poses=poses, far_m=far, exact_min_of=tight)
            assert D.flags.f_contiguous
            cut = np.full(T, far) if tight is None else np.maximum(far, exact[:, columns].min(axis=1))
            inside = exact <= cut[:, None]
            np.testing.assert_allclose(D[inside], exact[inside], rtol=0, atol=1e-15)
            outside = ~inside
            assert (D[outside] > np.broadcast_to(cut[:, None], D.shape)[outside]).all()
            assert (D[outside] <= exact[outside] + 1e-9).all()
            if tight is not None:
                np.testing.assert_allclose(D[:, columns].min(axis=1), exact[:, columns].min(axis=1), rtol=0, atol=1e-15)


@pytest.mark.parametrize("far", [0.0, 0.01, 0.03])
@pytest.mark.parametrize("radius", [0.0, 0.01, 0.025])
def test_capsule_values_within_a_few_ulps_of_the_cutoff(far, radius):
    """Horizontal capsules over the table at heights within 4 ulps of the cutoff (some exactly on it): "at or
    below the cutoff" is inclusive, and the block bounds never drop a sample that rounds onto it."""
    table = Shape("table", "table", "box", (1.2, 1.2, 0.04), np.eye(4))  # top face at z = 0.02
    can = Shape("can", "can", "cylinder", (0.05, 0.2), np.eye(4))
    T = 64 * 40
    rng = np.random.default_rng(11)
    kern = P.ProximityKernel([("c", radius)], [table, can], [("c", "table"), ("c", "can")])
    level = 0.02 + radius + far
    z = level + rng.integers(-4, 5, T) * np.spacing(level)
    p0 = np.stack([rng.uniform(0.3, 0.5, T), rng.uniform(-0.5, 0.5, T), z], axis=1)[:, None]
    p1 = p0 + np.array([0.05, 0.0, 0.0])
    exact = kern.distances(p0, p1)
    assert (exact[:, 0] <= far).sum() > T // 4  # the inputs do straddle the cutoff
    for tight in (None, [0]):
        D = kern.distances(p0, p1, far_m=far, exact_min_of=tight)
        cut = np.full((T, 1), far) if tight is None else np.maximum(far, exact[:, :1])
        inside = exact <= cut
        np.testing.assert_array_equal(D[inside], exact[inside])
        assert (D[~inside] > np.broadcast_to(cut, D.shape)[~inside]).all()


# --- forward kinematics -----------------------------------------------------------------------------------------


@pytest.fixture(scope="module", params=["ur3e", "ur5e", "ur10e", "ur16e", "panda"])
def arm(request):
    return Robot.panda() if request.param == "panda" else Robot.ur(request.param)


@pytest.mark.parametrize("T", [1, 2, 1999, 2000, 2001, 4001])
@pytest.mark.parametrize("variant", ["plain", "huge angles", "strided", "fortran", "float32", "opening"])
def test_forward_matches_pinocchio_at_the_block_edges(arm, T, variant):
    """Samples either side of each 2,000-sample block edge (and the first and last) against Pinocchio; the
    capsule endpoints against the frames' ``R x + t``; ``forward`` and ``forward_with_capsules`` agree."""
    rng = np.random.default_rng(T)
    q = rng.uniform(-2 * np.pi, 2 * np.pi, (T, arm.n))
    opening = None
    if variant == "huge angles":
        q *= 1.6e5  # |q| up to 1e6 rad: cos and sin reduce the argument exactly, so do Pinocchio's
    elif variant == "strided":
        q = rng.uniform(-3, 3, (2 * T, 2 * arm.n))[::2, 1::2]
    elif variant == "fortran":
        q = np.asfortranarray(q)
    elif variant == "float32":
        q = q.astype(np.float32)
    elif variant == "opening" and arm.finger_links:
        opening = rng.uniform(0.0, arm.max_opening_m, T)
    q_before = q.copy()
    frames = arm.forward(q, opening)
    frames2, p0, p1 = arm.forward_with_capsules(q, opening)
    np.testing.assert_array_equal(q, q_before)
    np.testing.assert_array_equal(frames2, frames)
    rows = sorted({t for e in (0, 2000, 4000) for t in (e - 2, e - 1, e, e + 1) if 0 <= t < T} | {T - 1})
    ref = pinocchio_frames(arm, q[rows], None if opening is None else opening[rows])
    np.testing.assert_allclose(frames[rows], ref, rtol=0, atol=1e-12)
    c0, c1 = capsule_reference(arm, ref)
    np.testing.assert_allclose(p0[rows], c0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(p1[rows], c1, rtol=0, atol=1e-12)
    single = arm.forward(q[T - 1], None if opening is None else opening[T - 1])
    np.testing.assert_allclose(single, frames[T - 1], rtol=0, atol=1e-15)


# --- array helpers ------------------------------------------------------------------------------------------------

_VALUES = np.array([0.0, -0.0, 1.0, 2.5, np.nan, np.inf, -np.inf])


def test_unique_values_is_np_unique_on_awkward_inputs():
    """Same values, dtype and signs of zero as ``np.unique`` (NaNs collapsed into one)."""
    cases = [
        np.array([]), np.array([1.0]), np.array([np.nan]), np.array([np.nan, np.nan, 1.0]), np.array([0.0, -0.0]),
        np.array([-0.0, 0.0, -0.0]), np.array([np.inf, -np.inf, np.nan, np.inf]), np.array([3, 1, 3, 2]),
        np.array([[2, 1], [1, 2]]), np.array(["b", "a", "b"]), np.array([True, False, True]), np.array(5.0),
        np.array([], dtype=np.int64), np.array([1, 2, 1], dtype=np.uint8), np.array([1.0, np.nan], dtype=np.float16),
        np.array([3, 1, 3], dtype=object),
    ]
    rng = np.random.default_rng(3)
    cases += [rng.choice(_VALUES, size=rng.integers(0, 12)) for _ in range(500)]
    for x in cases:
        got, ref = A.unique_values(x), np.unique(x)
        assert got.dtype == ref.dtype and got.shape == ref.shape, x
        np.testing.assert_array_equal(got, ref)
        if ref.dtype.kind == "f":
            np.testing.assert_array_equal(np.signbit(got), np.signbit(ref))


def _first_of_equal_rows_reference(a, w):
    return np.array(
        [i for i, row in enumerate(a) if any((row == r).all() for r in w) and not any((row == a[j]).all() for j in range(i))],
        dtype=np.int64,
    )


def test_first_of_equal_rows_with_nan_signed_zeros_and_empty_sides():
    """NaN rows match nothing, -0.0 matches 0.0 (element-wise ``==``), either side may be empty."""
    rng = np.random.default_rng(5)
    values = np.array([0.0, -0.0, 1.0, np.nan, 2.0])
    for _ in range(1500):
        K = int(rng.integers(1, 4))
        a = rng.choice(values, size=(int(rng.integers(0, 8)), K))
        w = rng.choice(values, size=(int(rng.integers(0, 5)), K))
        if len(a) and len(w) and rng.random() < 0.4:
            w[0] = a[rng.integers(len(a))]
        got = A.first_of_equal_rows(a, w)
        assert got.dtype == np.int64
        np.testing.assert_array_equal(got, _first_of_equal_rows_reference(a, w))


def test_equal_row_groups_with_signed_zeros():
    rng = np.random.default_rng(6)
    for _ in range(500):
        a = rng.choice(np.array([0.0, -0.0, 1.0, 2.0]), size=(int(rng.integers(1, 9)), int(rng.integers(1, 4))))
        group, counts = A.equal_row_groups(a)
        _, inverse, ref_counts = np.unique(a, axis=0, return_inverse=True, return_counts=True)
        np.testing.assert_array_equal(group, inverse.ravel())
        np.testing.assert_array_equal(counts, ref_counts)


@pytest.mark.parametrize("shape", [(0, 3), (1, 1), (5, 1), (3, 4), (7000, 12)])
def test_row_reductions_are_numpys(shape):
    rng = np.random.default_rng(8)
    x = rng.normal(size=shape)
    if x.size:
        x.flat[0] = np.nan
        x.flat[-1] = -0.0
    np.testing.assert_array_equal(A.row_max(x), x.max(axis=1))
    np.testing.assert_array_equal(A.row_any(x), x.any(axis=1))
    np.testing.assert_array_equal(A.row_any(x == 0.0), (x == 0.0).any(axis=1))
    columns = np.arange(shape[1])[::-1]
    np.testing.assert_array_equal(A.min_over_columns(x, columns), x[:, columns].min(axis=1))
    np.testing.assert_array_equal(A.row_max(x[::2, ::-1]), x[::2, ::-1].max(axis=1))  # a strided view


def test_min_over_columns_repeated_negative_and_no_columns():
    rng = np.random.default_rng(9)
    x = rng.integers(-5, 5, (6, 4))
    for columns in ([0], [3, 3, 1], [-1], [2, 0], np.array([True, False, True, False])):
        got, ref = A.min_over_columns(x, np.asarray(columns)), x[:, np.asarray(columns)].min(axis=1)
        assert got.dtype == ref.dtype
        np.testing.assert_array_equal(got, ref)
    np.testing.assert_array_equal(A.min_over_columns(x.astype(float), np.array([], dtype=np.intp)), np.full(6, np.inf))
    z = np.array([[0.0, -0.0], [-0.0, 0.0]])
    np.testing.assert_array_equal(np.signbit(A.min_over_columns(z, np.array([0, 1]))), np.signbit(z.min(axis=1)))


# --- Trajectory's finiteness check ------------------------------------------------------------------------------


def _raises(x) -> bool:
    try:
        _array("x", x)
    except TrajectoryError:
        return True
    return False


def test_finiteness_check_is_np_isfinite():
    """Raises iff some element is NaN or +-inf, including sums that overflow (finite: no raise) and infinities of
    both signs (their sum is NaN), on views, Fortran order, float32 and ints."""
    big = np.finfo(float).max
    pool = np.array([0.0, -0.0, 1.0, big, -big, 1e308, 5e-324, np.nan, np.inf, -np.inf])
    rng = np.random.default_rng(10)
    for _ in range(3000):
        n = int(rng.integers(0, 9))
        x = rng.choice(pool, size=(n,) if rng.random() < 0.5 else (n, 2))
        assert _raises(x) == (not np.isfinite(x).all()), x
    for x, bad in [
        ([big, big, -big, -big], False), ([big, big, np.nan], True), ([np.inf, -np.inf], True), ([big] * 3 + [-np.inf], True),
        (np.array(np.nan), True), (np.array(1.0), False), ([], False), ([[np.nan]], True),
        (np.array([2**63 - 1] * 3), False), (np.float32([3e38, 3e38]), False), (np.float32([np.nan]), True),
    ]:
        assert _raises(x) == bad, x
    a = np.ones((50, 7))
    a[49, 6] = np.nan
    assert _raises(a[::7, ::3]) and _raises(a[::-1]) and _raises(np.asfortranarray(a)) and _raises(a.T)
    assert not _raises(a[:49])
    with pytest.raises(TrajectoryError, match=r"index \(1, 0\)"):
        _array("x", np.array([[1.0, 2.0], [np.inf, np.nan]]))
