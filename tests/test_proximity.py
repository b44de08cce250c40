"""Exact capsule distances (robocritics.geometry.proximity) against coal and brute-force references.

coal's GJK (separated shapes, run with a 1e-12 tolerance) and its EPA for boxes
and capsules agree with the closed forms to ~1e-15 m. coal's EPA for cylinders
is only good to about 1e-6 m, so penetrating cylinders are checked against coal
at 3e-6 m and, where they differ by more, against a brute-force minimisation of
the support function of the Minkowski difference (``depth = min_n h_Z(n)``)
at 1e-8 m.
"""

from __future__ import annotations

import math

import coal
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize

from robocritics.geometry import kernels as PK, pairs as PS, proximity as P
from robocritics.scene import Scene, Shape, rpy_matrix

SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)

# ------------------------------------------------------------------------------------------
# coal references
# ------------------------------------------------------------------------------------------


def _tf(R, p) -> coal.Transform3s:
    return coal.Transform3s(np.asarray(R, dtype=float), np.asarray(p, dtype=float))


def _coal_capsule(p0, p1, r):
    """coal.Capsule(radius, length) is centred with its axis along z: pose it on the segment."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = p1 - p0
    L = float(np.linalg.norm(d))
    z = d / L if L > 0 else np.array([0.0, 0.0, 1.0])
    x = np.cross(z, [1.0, 0.0, 0.0])
    if np.linalg.norm(x) < 1e-6:
        x = np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    return coal.Capsule(float(r), L), _tf(np.column_stack([x, np.cross(z, x), z]), (p0 + p1) / 2)


def _coal_shape(kind, size, pose):
    pose = np.asarray(pose, float)
    if kind == "box":
        g = coal.Box(*map(float, size))  # full extents
    elif kind == "cylinder":
        g = coal.Cylinder(float(size[0]), float(size[1]))  # radius, full height, axis z
    else:
        g = coal.Sphere(float(size[0]))
    return g, _tf(pose[:3, :3], pose[:3, 3])


def coal_distance(g1, t1, g2, t2, tight=True):
    req = coal.DistanceRequest()
    if tight:
        req.gjk_tolerance = 1e-12
        req.gjk_max_iterations = 1000
    req.epa_max_iterations = 256
    return coal.distance(g1, t1, g2, t2, req, coal.DistanceResult())


def test_coal_conventions():
    assert np.allclose(coal.Box(2.0, 4.0, 6.0).halfSide, [1, 2, 3])  # full extents
    assert coal.Cylinder(0.1, 0.4).halfLength == pytest.approx(0.2)  # full height
    assert coal.Capsule(0.1, 0.4).halfLength == pytest.approx(0.2)
    # negative = penetration depth
    g, t = _coal_capsule((-1, 0, 0.12), (1, 0, 0.12), 0.05)
    b, tb = _coal_shape("box", (0.2, 0.2, 0.2), np.eye(4))
    assert coal_distance(g, t, b, tb) == pytest.approx(-0.03)


# ------------------------------------------------------------------------------------------
# brute-force depth (min over directions of the support function of the Minkowski difference)
# ------------------------------------------------------------------------------------------


def _h_cyl(n, R, H):
    return R * np.hypot(n[..., 0], n[..., 1]) + H * np.abs(n[..., 2])


def _h_box(n, h):
    return np.abs(n) @ np.asarray(h)


def brute_depth(support, a, b):
    """``min_n support(n) - min(n.a, n.b)`` over unit n: the depth of segment a-b in a convex shape."""
    a, b = np.asarray(a, float), np.asarray(b, float)

    def hz(n):
        n = n / np.linalg.norm(n, axis=-1, keepdims=True)
        return support(n) - np.minimum(n @ a, n @ b)

    th, ph = np.meshgrid(np.linspace(0, np.pi, 91), np.linspace(-np.pi, np.pi, 181), indexing="ij")
    grid = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=-1).reshape(-1, 3)
    v = hz(grid)
    best = v.min()
    starts: list[np.ndarray] = []
    for k in np.argsort(v):  # the best grid directions that are not neighbours of each other
        if all(grid[k] @ s < 0.998 for s in starts):
            starts.append(grid[k])
        if len(starts) == 5:
            break
    for s0 in starts:
        res = minimize(lambda x: hz(x[None])[0], s0, method="Nelder-Mead", options=dict(xatol=1e-12, fatol=1e-14, maxiter=4000))
        best = min(best, res.fun)
    return best


def _pt_box(p, h):
    return float(np.linalg.norm(np.maximum(np.abs(p) - h, 0.0)))


def _pt_cyl(p, R, H):
    return float(np.hypot(max(np.hypot(p[0], p[1]) - R, 0.0), max(abs(p[2]) - H, 0.0)))


def brute_signed(kind, size, pose, p0, p1, r):
    """Independent signed distance: a bounded scalar minimisation of the (convex) point distance
    along the segment, and :func:`brute_depth` when the segment meets the shape."""
    from scipy.optimize import minimize_scalar

    pose = np.asarray(pose, float)
    a = pose[:3, :3].T @ (np.asarray(p0, float) - pose[:3, 3])
    b = pose[:3, :3].T @ (np.asarray(p1, float) - pose[:3, 3])
    if kind == "box":
        h = np.asarray(size, float) / 2
        dist, support = (lambda p: _pt_box(p, h)), (lambda n: _h_box(n, h))
    else:
        R, H = size[0], size[1] / 2
        dist, support = (lambda p: _pt_cyl(p, R, H)), (lambda n: _h_cyl(n, R, H))
    f = lambda t: dist(a + t * (b - a))  # noqa: E731
    ts = np.linspace(0, 1, 201)
    k = int(np.argmin([f(t) for t in ts]))
    res = minimize_scalar(f, bounds=(ts[max(k - 1, 0)], ts[min(k + 1, 200)]), method="bounded", options=dict(xatol=1e-13))
    sep = min(res.fun, f(0.0), f(1.0), f(ts[k]))
    if sep > 1e-12:
        return sep - r
    return -brute_depth(support, a, b) - r


FALLBACKS: list[str] = []


def assert_signed_close(kind, size, pose, p0, p1, r, mine, coal_ref, tol=1e-9):
    """``mine`` within ``tol`` of coal or, where coal is off (EPA on cylinders, failures), of brute force."""
    if np.isfinite(coal_ref) and abs(coal_ref) < 1e3:
        if coal_ref > 1e-7 and abs(mine - coal_ref) <= tol:  # GJK: exact
            return
        if coal_ref <= 1e-7 and abs(mine - coal_ref) <= (3e-6 if kind == "cylinder" else tol):
            return
    FALLBACKS.append(f"{kind} mine={float(mine):.9f} coal={coal_ref:.9f}")
    assert mine == pytest.approx(brute_signed(kind, size, pose, p0, p1, r), abs=1e-8)


# ------------------------------------------------------------------------------------------
# strategies
# ------------------------------------------------------------------------------------------

coord = st.floats(-0.3, 0.3)
vec = st.tuples(coord, coord, coord).map(np.array)
angles = st.tuples(*[st.floats(-math.pi, math.pi)] * 3)
radius = st.floats(0.0, 0.05)


def pose_of(rpy, t):
    pose = np.eye(4)
    pose[:3, :3] = rpy_matrix(rpy)
    pose[:3, 3] = t
    return pose


@st.composite
def local_segment(draw, half):
    """A segment in a shape's frame (half extents ``half``), often in a degenerate position."""
    hx, hy, hz = half
    mode = draw(st.sampled_from(["free", "free", "zero", "inside_end", "axis", "through", "face", "face_touch", "edge"]))
    p0 = draw(vec)
    p1 = draw(vec)
    if mode == "zero":
        p1 = p0.copy()
    elif mode == "inside_end":
        p0 = np.array([draw(st.floats(-1, 1)) * hx, draw(st.floats(-1, 1)) * hy, draw(st.floats(-1, 1)) * hz])
    elif mode == "axis":  # parallel to the local z axis (a cylinder's axis)
        p1 = p0.copy()
        p1[2] = draw(coord)
    elif mode == "through":  # through the centre
        p1 = -p0 * draw(st.floats(0.1, 2.0))
    elif mode in ("face", "face_touch"):  # in the plane of the +z face
        z = hz if mode == "face" else hz + draw(st.floats(0, 0.05))
        p0[2] = z
        p1[2] = z
    elif mode == "edge":  # along an edge line (x, y at the corner)
        p0[:2] = (hx, hy)
        p1[:2] = (hx, hy)
    return p0, p1


# ------------------------------------------------------------------------------------------
# segment-segment
# ------------------------------------------------------------------------------------------


def _ref_seg_seg(a0, a1, b0, b1):
    """Independent reference: the minimum of four point-segment distances and the interior critical point."""

    def pt_seg(p, s0, s1):
        d = s1 - s0
        dd = d @ d
        t = 0.0 if dd == 0 else np.clip((p - s0) @ d / dd, 0, 1)
        return np.linalg.norm(p - s0 - t * d)

    best = min(pt_seg(a0, b0, b1), pt_seg(a1, b0, b1), pt_seg(b0, a0, a1), pt_seg(b1, a0, a1))
    u, v, w = a1 - a0, b1 - b0, a0 - b0
    a, b, c, d, e = u @ u, u @ v, v @ v, u @ w, v @ w
    den = a * c - b * b
    if den > 1e-12 * a * c:
        s, t = (b * e - c * d) / den, (a * e - b * d) / den
        if 0 <= s <= 1 and 0 <= t <= 1:
            best = min(best, np.linalg.norm(w + s * u - t * v))
    return best


@st.composite
def segment_pairs(draw):
    a0, a1, b0 = draw(vec), draw(vec), draw(vec)
    mode = draw(st.sampled_from(["free", "parallel", "antiparallel", "zero_a", "zero_both", "collinear", "crossing", "nearly"]))
    b1 = draw(vec)
    if mode == "parallel":
        b1 = b0 + (a1 - a0) * draw(st.floats(0.1, 2.0))
    elif mode == "antiparallel":
        b1 = b0 - (a1 - a0) * draw(st.floats(0.1, 2.0))
    elif mode == "zero_a":
        a1 = a0.copy()
    elif mode == "zero_both":
        a1, b1 = a0.copy(), b0.copy()
    elif mode == "collinear":
        b0 = a0 + (a1 - a0) * draw(st.floats(-1, 2))
        b1 = a0 + (a1 - a0) * draw(st.floats(-1, 2))
    elif mode == "crossing":
        m = a0 + (a1 - a0) * draw(st.floats(0, 1))
        b1 = 2 * m - b0
    elif mode == "nearly":
        b1 = b0 + (a1 - a0) + draw(st.floats(-1e-9, 1e-9))
    return a0, a1, b0, b1


@settings(max_examples=600, **SETTINGS)
@given(segment_pairs(), radius, radius)
def test_capsule_capsule_matches_coal_and_reference(seg, ra, rb):
    a0, a1, b0, b1 = seg
    mine = PK.capsule_capsule(a0, a1, ra, b0, b1, rb)
    assert mine.shape == ()
    ref = _ref_seg_seg(a0, a1, b0, b1) - ra - rb
    assert mine == pytest.approx(ref, abs=1e-9)
    ga, ta = _coal_capsule(a0, a1, ra)
    gb, tb = _coal_capsule(b0, b1, rb)
    assert mine == pytest.approx(coal_distance(ga, ta, gb, tb), abs=1e-6)


def test_capsule_capsule_vectorised_and_degenerate():
    T = 50
    rng = np.random.default_rng(0)
    a0, a1, b0, b1 = (rng.uniform(-0.3, 0.3, (T, 3)) for _ in range(4))
    d = PK.capsule_capsule(a0, a1, 0.01, b0, b1, 0.02)
    assert d.shape == (T,)
    assert np.allclose(d, [_ref_seg_seg(*x) - 0.03 for x in zip(a0, a1, b0, b1)], atol=1e-12)
    # crossing segments: depth ra + rb exactly; identical points
    assert PK.capsule_capsule((-1, 0, 0), (1, 0, 0), 0.1, (0, -1, 0), (0, 1, 0), 0.2) == pytest.approx(-0.3)
    assert PK.capsule_capsule((0, 0, 0), (0, 0, 0), 0.1, (0, 0, 0), (0, 0, 0), 0.1) == pytest.approx(-0.2)
    # parallel, overlapping in projection, 0.5 apart
    assert PK.capsule_capsule((0, 0, 0), (1, 0, 0), 0, (0.5, 0.5, 0), (2, 0.5, 0), 0) == pytest.approx(0.5)
    # broadcast one static segment against a trajectory
    assert PK.capsule_capsule(a0, a1, 0.0, (0, 0, 0), (0, 0, 1), 0.0).shape == (T,)


# ------------------------------------------------------------------------------------------
# capsule-sphere, point-shape
# ------------------------------------------------------------------------------------------


@settings(max_examples=300, **SETTINGS)
@given(vec, vec, radius, vec, st.floats(0.005, 0.1), st.booleans())
def test_capsule_sphere_matches_coal(p0, p1, r, c, R, zero):
    if zero:
        p1 = p0.copy()
    mine = PK.capsule_sphere(p0, p1, r, c, R)
    g, t = _coal_capsule(p0, p1, r)
    s, ts = _coal_shape("sphere", (R,), pose_of((0, 0, 0), c))
    assert mine == pytest.approx(coal_distance(g, t, s, ts), abs=1e-9)


@settings(max_examples=300, **SETTINGS)
@given(st.sampled_from(["box", "cylinder", "sphere"]), vec, angles, vec, st.tuples(*[st.floats(0.01, 0.3)] * 3), st.floats(0.001, 0.05))
def test_sphere_shape_matches_coal(kind, centre, rpy, t, size, R):
    size = {"box": size, "cylinder": size[:2], "sphere": size[:1]}[kind]
    shape = Shape("s", "s", kind, tuple(size), pose_of(rpy, t))
    mine = PK.sphere_shape(centre, R, shape)
    g, tg = _coal_shape(kind, size, shape.pose)
    s, ts = _coal_shape("sphere", (R,), pose_of((0, 0, 0), centre))
    ref = coal_distance(s, ts, g, tg)
    if kind == "cylinder" and ref < 1e-7 and abs(mine - ref) > 3e-6:
        # coal's EPA on a cylinder is the less accurate side (a sphere at the very centre
        # comes out through the side even when the caps are nearer): settle it by brute force
        local = shape.pose[:3, :3].T @ (centre - shape.pose[:3, 3])
        ref = -brute_depth(lambda n: _h_cyl(n, size[0], size[1] / 2), local, local) - R
    assert mine == pytest.approx(ref, abs=1e-8)


def test_point_shape_inside_is_depth():
    box = Shape("b", "b", "box", (0.2, 0.4, 0.6), np.eye(4))
    assert PK.point_shape([0.05, 0, 0], box) == pytest.approx(-0.05)
    assert PK.point_shape([0.3, 0.4, 0.5], box) == pytest.approx(math.sqrt(0.2**2 + 0.2**2 + 0.2**2))
    cyl = Shape("c", "c", "cylinder", (0.1, 0.4), np.eye(4))
    assert PK.point_shape([0.0, 0.0, 0.15], cyl) == pytest.approx(-0.05)
    assert PK.point_shape([[0.2, 0.0, 0.3]], cyl) == pytest.approx([math.hypot(0.1, 0.1)])


# ------------------------------------------------------------------------------------------
# capsule-box
# ------------------------------------------------------------------------------------------


@st.composite
def box_case(draw):
    size = np.array(draw(st.tuples(*[st.floats(0.004, 0.4)] * 3)))
    p0, p1 = draw(local_segment(size / 2))
    pose = pose_of(draw(angles), draw(vec)) if draw(st.booleans()) else pose_of((0, 0, 0), draw(vec))
    R, c = pose[:3, :3], pose[:3, 3]
    return size, pose, R @ p0 + c, R @ p1 + c, draw(radius)


@settings(max_examples=1000, **SETTINGS)
@given(box_case())
def test_capsule_box_matches_coal(case):
    size, pose, p0, p1, r = case
    mine = PK.capsule_box(p0, p1, r, size, pose)
    g, t = _coal_capsule(p0, p1, r)
    b, tb = _coal_shape("box", size, pose)
    assert_signed_close("box", size, pose, p0, p1, r, mine, coal_distance(g, t, b, tb))


def test_capsule_box_cases():
    size, pose = (0.2, 0.4, 0.6), np.eye(4)
    # touching the +z face from above, lying in it, endpoint inside, through the middle
    assert PK.capsule_box((-1, 0, 0.35), (1, 0, 0.35), 0.05, size, pose) == pytest.approx(0.0, abs=1e-15)
    assert PK.capsule_box((-1, 0, 0.3), (1, 0, 0.3), 0.05, size, pose) == pytest.approx(-0.05)
    assert PK.capsule_box((0.05, 0, 0), (1, 0, 0), 0.01, size, pose) == pytest.approx(-0.05 - 0.01)  # pushed along +x
    assert PK.capsule_box((-1, 0, 0), (1, 0, 0), 0.0, size, pose) == pytest.approx(-0.2)  # out along y: 0.2
    # far corner: vertex distance
    assert PK.capsule_box((0.2, 0.3, 0.4), (0.2, 0.3, 0.4), 0.0, size, pose) == pytest.approx(math.sqrt(3 * 0.1**2))
    # a segment parallel to an edge, offset diagonally
    assert PK.capsule_box((0.2, 0.3, -1), (0.2, 0.3, 1), 0.0, size, pose) == pytest.approx(math.hypot(0.1, 0.1))
    # per-sample pose: a box moving along x under a static capsule
    T = 5
    poses = np.tile(np.eye(4), (T, 1, 1))
    poses[:, 0, 3] = np.linspace(0, 1, T)
    d = PK.capsule_box(np.array([0.0, 0, 1]), np.array([0.0, 0, 2]), 0.0, (0.1, 0.1, 0.1), poses)
    assert d.shape == (T,)
    expect = [np.hypot(max(abs(x) - 0.05, 0), 0.95) for x in np.linspace(0, 1, T)]
    assert np.allclose(d, expect)


def test_box_depth_matches_brute_force():
    rng = np.random.default_rng(11)
    for _ in range(15):
        h = rng.uniform(0.004, 0.3, 3)
        a = rng.uniform(-1, 1, 3) * h
        b = a + rng.normal(size=3) * rng.uniform(0, 0.3)
        mine = -PK.capsule_box(a, b, 0.0, 2 * h, np.eye(4))
        assert mine >= 0
        assert mine == pytest.approx(brute_depth(lambda n: _h_box(n, h), a, b), abs=1e-9)


# ------------------------------------------------------------------------------------------
# capsule-cylinder
# ------------------------------------------------------------------------------------------


@st.composite
def cylinder_case(draw):
    R, height = draw(st.floats(0.005, 0.2)), draw(st.floats(0.005, 0.4))
    p0, p1 = draw(local_segment((R / math.sqrt(2), R / math.sqrt(2), height / 2)))
    mode = draw(st.sampled_from(["free", "axis", "rim"]))
    if mode == "axis":  # on the axis line
        p0[:2] = p1[:2] = 0.0
    elif mode == "rim":  # through a point of the top rim
        ang = draw(st.floats(-math.pi, math.pi))
        q = np.array([R * math.cos(ang), R * math.sin(ang), height / 2])
        p1 = 2 * q - p0
    pose = pose_of(draw(angles), draw(vec))
    Rm, c = pose[:3, :3], pose[:3, 3]
    return R, height, pose, Rm @ p0 + c, Rm @ p1 + c, p0, p1, draw(radius)


@settings(max_examples=1000, **SETTINGS)
@given(cylinder_case())
def test_capsule_cylinder_matches_coal(case):
    R, height, pose, p0, p1, l0, l1, r = case
    mine = PK.capsule_cylinder(p0, p1, r, R, height, pose)
    g, t = _coal_capsule(p0, p1, r)
    c, tc = _coal_shape("cylinder", (R, height), pose)
    assert_signed_close("cylinder", (R, height), pose, p0, p1, r, mine, coal_distance(g, t, c, tc))


def test_capsule_cylinder_depth_matches_brute_force():
    rng = np.random.default_rng(7)
    n = 0
    while n < 25:
        R, H = rng.uniform(0.01, 0.2), rng.uniform(0.01, 0.2)
        a = rng.uniform(-1, 1, 3) * (R / 1.5, R / 1.5, H)
        b = a + rng.normal(size=3) * rng.uniform(0, 0.3)
        mine = -PK.capsule_cylinder(a, b, 0.0, R, 2 * H, np.eye(4))
        assert mine >= 0
        assert mine == pytest.approx(brute_depth(lambda n: _h_cyl(n, R, H), a, b), abs=1e-9)
        n += 1


def test_capsule_cylinder_cases():
    pose = np.eye(4)
    # parallel to the axis, outside: radial gap; inside: depth to the side
    assert PK.capsule_cylinder((0.3, 0, -1), (0.3, 0, 1), 0.01, 0.1, 0.4, pose) == pytest.approx(0.19)
    assert PK.capsule_cylinder((0.07, 0, -0.1), (0.07, 0, 0.1), 0.0, 0.1, 0.4, pose) == pytest.approx(-0.03)
    # through the whole cylinder along the axis: pushed out sideways by R
    assert PK.capsule_cylinder((0, 0, -1), (0, 0, 1), 0.0, 0.1, 0.4, pose) == pytest.approx(-0.1)
    # across, through the centre: pushed out through a cap by H, or sideways by R
    assert PK.capsule_cylinder((-1, 0, 0), (1, 0, 0), 0.0, 0.1, 0.4, pose) == pytest.approx(-0.1)
    assert PK.capsule_cylinder((-1, 0, 0), (1, 0, 0), 0.0, 0.3, 0.1, pose) == pytest.approx(-0.05)
    # above the rim, diagonal: distance to the rim circle
    assert PK.capsule_cylinder((0.2, 0, 0.3), (0.2, 0, 0.3), 0.0, 0.1, 0.4, pose) == pytest.approx(math.hypot(0.1, 0.1))
    # a horizontal segment over the top face
    assert PK.capsule_cylinder((-1, 0, 0.5), (1, 0, 0.5), 0.02, 0.1, 0.4, pose) == pytest.approx(0.28)


# ------------------------------------------------------------------------------------------
# the batch kernel
# ------------------------------------------------------------------------------------------


def _trajectory(T, C, seed=0):
    rng = np.random.default_rng(seed)
    s = np.linspace(0, 1, T)[:, None, None]
    base = rng.uniform([-0.4, -0.4, 0.0], [0.4, 0.4, 0.3], (1, C, 3))
    amp = rng.uniform(-0.3, 0.3, (1, C, 3))
    p0 = base + amp * np.sin(2 * np.pi * s * rng.uniform(0.5, 2, (1, C, 1)))
    p1 = p0 + rng.normal(size=(1, C, 3)) * 0.1 * np.cos(3 * s + rng.uniform(0, 3, (1, C, 1)))
    return p0, p1


def _scene_shapes(seed=0):
    rng = np.random.default_rng(seed)
    shapes = Scene.builtin("breakfast").shapes()
    out = []
    for i, s in enumerate(shapes):
        pose = s.pose.copy()
        if i % 4 == 1:  # some tilted objects
            pose[:3, :3] = rpy_matrix(tuple(rng.uniform(-1, 1, 3)))
        out.append(Shape(s.name, s.owner, s.kind, s.size, pose))
    # a yawed container (five boxes sharing one rotation)
    from robocritics.scene import Container

    out += Container(id="bin", size=(0.2, 0.15, 0.1), position=(0.1, -0.2, 0.05), yaw=0.4).shapes()
    return out


def test_kernel_matches_per_pair_functions():
    T, C = 700, 6
    p0, p1 = _trajectory(T, C)
    caps = [(f"link{i}", 0.01 * (i + 1)) for i in range(C)]
    shapes = _scene_shapes()
    pairs = [(c, s.name) for c, _ in caps for s in shapes]
    pairs += [("link0", "link3"), ("link1", "link5"), ("link4", "link2")]
    pairs = pairs[::-1]  # an order the product groups cannot write as slices
    kern = P.ProximityKernel(caps, shapes, pairs, chunk=1000)
    D = kern.distances(p0, p1)
    assert D.shape == (T, len(pairs))
    radius = dict(caps)
    by_name = {s.name: s for s in shapes}
    for k, (a, b) in enumerate(pairs):
        ia = int(a[4:])
        if b in radius:
            ib = int(b[4:])
            ref = PK.capsule_capsule(p0[:, ia], p1[:, ia], radius[a], p0[:, ib], p1[:, ib], radius[b])
        else:
            ref = PK.capsule_shape(p0[:, ia], p1[:, ia], radius[a], by_name[b])
        np.testing.assert_allclose(D[:, k], ref, atol=1e-12, err_msg=f"{a}|{b}")
    assert (D < 0).any() and (D > 0).any()
    # capsule-major order: the in-place path gives the same values
    pairs2 = [(c, s.name) for c, _ in caps for s in shapes]
    D2 = P.ProximityKernel(caps, shapes, pairs2).distances(p0, p1)
    col = {p: k for k, p in enumerate(pairs)}
    np.testing.assert_array_equal(D2, D[:, [col[p] for p in pairs2]])


def test_kernel_static_capsules_are_evaluated_once_and_exactly():
    T, C = 400, 4
    p0, p1 = _trajectory(T, C, seed=9)
    # capsules 0 and 2 do not move (a robot's base); capsule 0 sinks into the table
    p0[:, 0], p1[:, 0] = (0.0, 0.0, -0.05), (0.0, 0.0, 0.05)
    p0[:, 2], p1[:, 2] = (0.1, -0.2, 0.05), (0.12, -0.2, 0.15)
    caps = [(f"k{i}", 0.03) for i in range(C)]
    shapes = _scene_shapes(4)
    pairs = [(c, s.name) for c, _ in caps for s in shapes] + [("k0", "k2"), ("k1", "k3"), ("k0", "k3")]
    D = P.ProximityKernel(caps, shapes, pairs).distances(p0, p1)
    by_name = {s.name: s for s in shapes}
    for k, (a, b) in enumerate(pairs):
        ia = int(a[1:])
        if b in dict(caps):
            ib = int(b[1:])
            ref = PK.capsule_capsule(p0[:, ia], p1[:, ia], 0.03, p0[:, ib], p1[:, ib], 0.03)
        else:
            ref = PK.capsule_shape(p0[:, ia], p1[:, ia], 0.03, by_name[b])
        np.testing.assert_allclose(D[:, k], ref, atol=1e-12, err_msg=f"{a}|{b}")
    assert D[0, pairs.index(("k0", "table"))] == pytest.approx(-0.08)  # 5 cm into the table, plus the radius


def test_kernel_sparse_pairs_and_groups():
    T, C = 300, 4
    p0, p1 = _trajectory(T, C, seed=3)
    caps = [("a", 0.02), ("b", 0.03), ("c", 0.01), ("d", 0.04)]
    shapes = _scene_shapes(1)
    pairs = [("a", "table"), ("d", "plate"), ("b", "bin.floor"), ("b", "bin.wall_x-"), ("c", "apple"), ("a", "c")]
    kern = P.ProximityKernel(caps, shapes, pairs)
    D = kern.distances(p0, p1)
    by_name = {s.name: s for s in shapes}
    for k, (a, b) in enumerate(pairs[:-1]):
        ia = "abcd".index(a)
        np.testing.assert_allclose(D[:, k], PK.capsule_shape(p0[:, ia], p1[:, ia], dict(caps)[a], by_name[b]), atol=1e-12)
    groups = kern.groups()
    assert groups[("b", "bin")] == [2, 3]
    R = P.reduce_min(D, groups)
    assert R.shape == (T, len(groups))
    assert np.array_equal(R[:, list(groups).index(("b", "bin"))], np.minimum(D[:, 2], D[:, 3]))
    assert kern.names[0] == "a|table"
    assert kern.owners[2] == "bin"


def test_kernel_moving_objects():
    T, C = 200, 3
    p0, p1 = _trajectory(T, C, seed=5)
    caps = [("u", 0.02), ("v", 0.03), ("w", 0.01)]
    poses = np.tile(np.eye(4), (T, 1, 1))
    poses[:, :3, 3] = np.linspace([-0.3, -0.2, 0.02], [0.3, 0.25, 0.2], T)
    for i in range(T):
        poses[i, :3, :3] = rpy_matrix((0.1 * i / T, -0.3, 2.0 * i / T))
    poses[150:] = poses[150]  # released: at rest from sample 150
    for kind, size in [("box", (0.05, 0.04, 0.08)), ("cylinder", (0.03, 0.1)), ("sphere", (0.035,))]:
        held = Shape("held", "held", kind, size, np.eye(4))
        shapes = _scene_shapes(2) + [held]
        by_name = {s.name: s for s in shapes}
        pairs = [("u", "held"), ("w", "held"), ("held", "table"), ("held", "apple"), ("held", "plate"), ("v", "table"), ("u", "bin.floor")]
        kern = P.ProximityKernel(caps, shapes, pairs, moving={"held"})
        with pytest.raises(ValueError, match="poses"):
            kern.distances(p0, p1)
        D = kern.distances(p0, p1, poses={"held": poses})
        for k, ia in ((0, 0), (1, 2)):
            np.testing.assert_allclose(D[:, k], PK.capsule_shape(p0[:, ia], p1[:, ia], caps[ia][1], held, poses), atol=1e-12)
        np.testing.assert_allclose(D[:, 5], PK.capsule_shape(p0[:, 1], p1[:, 1], 0.03, by_name["table"]), atol=1e-12)
        for k, name in ((2, "table"), (3, "apple"), (4, "plate")):
            s = by_name[name]
            g2, t2 = _coal_shape(s.kind, s.size, s.pose)
            for i in range(0, T, 7):
                g1, t1 = _coal_shape(kind, size, poses[i])
                ref = coal_distance(g1, t1, g2, t2)
                tol = 1e-4 if "cylinder" in (kind, s.kind) and ref < 0 else 1e-8  # coal's EPA on cylinders
                assert D[i, k] == pytest.approx(ref, abs=tol), f"{kind}|{name} sample {i}"
        # capsule against the moving object, against coal
        for i in range(0, T, 23):
            g1, t1 = _coal_capsule(p0[i, 0], p1[i, 0], 0.02)
            g2, t2 = _coal_shape(kind, size, poses[i])
            ref = coal_distance(g1, t1, g2, t2)
            if kind == "sphere":
                assert D[i, 0] == pytest.approx(ref, abs=1e-9)
            else:
                assert_signed_close(kind, size, poses[i], p0[i, 0], p1[i, 0], 0.02, D[i, 0], ref)
    # an owner of several shapes cannot move as one pose
    with pytest.raises(ValueError, match="name the shapes"):
        P.ProximityKernel(caps, _scene_shapes(2), [("u", "bin.floor")], moving={"bin"})
    kern = P.ProximityKernel(caps, _scene_shapes(2), [("u", "bin.floor"), ("u", "table")], moving={"bin.floor"})
    D = kern.distances(p0, p1, poses={"bin.floor": poses})
    floor = [s for s in _scene_shapes(2) if s.name == "bin.floor"][0]
    np.testing.assert_allclose(D[:, 0], PK.capsule_shape(p0[:, 0], p1[:, 0], 0.02, floor, poses), atol=1e-12)


def test_shape_shape_far_cutoff_is_a_lower_bound():
    T = 40
    poses = np.tile(np.eye(4), (T, 1, 1))
    poses[:, 0, 3] = np.linspace(-1, 1, T)
    a = Shape("a", "a", "box", (0.1, 0.1, 0.1), np.eye(4))
    b = Shape("b", "b", "cylinder", (0.05, 0.2), np.eye(4))
    exact = PS.shape_shape(a, b, poses, None)
    culled = PS.shape_shape(a, b, poses, None, far_m=0.2)
    near = exact <= 0.2
    np.testing.assert_array_equal(culled[near], exact[near])
    assert (culled[~near] > 0.2).all() and (culled[~near] <= exact[~near] + 1e-12).all()
    assert exact.min() < 0  # passes through


@settings(max_examples=20, **SETTINGS)
@given(
    seed=st.integers(0, 2**31 - 1),
    far=st.sampled_from([0.0, 0.03, 0.1, 0.25]),
    n_tight=st.integers(0, 3),
    T=st.integers(1, 300),
)
def test_kernel_far_cutoff_is_exact_within_and_a_lower_bound_beyond(seed, far, n_tight, T):
    """``far_m`` and ``exact_min_of`` against the same kernel with every value exact (itself checked against the
    per-pair functions): a value within ``max(far_m, least exact value of the exact_min_of columns)`` at its
    sample is exact, every other one is a lower bound above ``far_m``, and the per-sample minimum over the
    exact_min_of columns is exact. Static, tilted, yawed-container and moving boxes and cylinders; capsules
    that stand still (a base) and short trajectories (one partial block)."""
    rng = np.random.default_rng(seed)
    C = 5
    p0, p1 = _trajectory(T, C, seed=seed % 1000)
    p0[:, 0], p1[:, 0] = p0[:1, 0], p1[:1, 0]  # capsule 0 stands still
    caps = [(f"link{i}", float(rng.uniform(0.005, 0.05))) for i in range(C)]
    shapes = _scene_shapes(seed % 7)
    held = Shape("held", "held", "cylinder" if seed % 2 else "box", (0.03, 0.04, 0.05)[: 2 if seed % 2 else 3], np.eye(4))
    pose = np.tile(np.eye(4), (T, 1, 1))
    pose[:, :3, 3] = p1[:, 1] + [0.0, 0.0, 0.05]  # rides near capsule 1
    pose[:, :3, :3] = rpy_matrix(tuple(rng.uniform(-1, 1, 3)))
    shapes = shapes + [held]
    pairs = [(c, sh.name) for c, _ in caps for sh in shapes] + [("link1", "link3")]
    kern = P.ProximityKernel(caps, shapes, pairs, moving={"held"})
    exact = kern.distances(p0, p1, poses={"held": pose})
    env = [k for k, (a, b) in enumerate(pairs) if b in {sh.name for sh in shapes}]
    tight = sorted(rng.choice(env, size=min(n_tight * 10, len(env)), replace=False).tolist())
    D = kern.distances(p0, p1, poses={"held": pose}, far_m=far, exact_min_of=tight or None)
    within = np.full(T, far)
    if tight:
        within = np.maximum(within, exact[:, tight].min(axis=1))
    inside = exact <= within[:, None]
    np.testing.assert_allclose(D[inside], exact[inside], rtol=0, atol=1e-12)
    assert (D[~inside] > far).all() and (D[~inside] <= exact[~inside] + 1e-12).all()
    if tight:
        np.testing.assert_allclose(D[:, tight].min(axis=1), exact[:, tight].min(axis=1), rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="far_m"):
        kern.distances(p0, p1, poses={"held": pose}, far_m=-0.01)


def test_kernel_rejects_bad_input():
    shapes = _scene_shapes()
    with pytest.raises(ValueError, match="not a capsule"):
        P.ProximityKernel([("a", 0.1)], shapes, [("zz", "table")])
    with pytest.raises(ValueError, match="neither"):
        P.ProximityKernel([("a", 0.1)], shapes, [("a", "nothing")])
    with pytest.raises(ValueError, match="moving"):
        P.ProximityKernel([("a", 0.1)], shapes, [("a", "table")], moving={"ghost"})
    with pytest.raises(ValueError, match="both a capsule and a shape"):
        P.ProximityKernel([("table", 0.1)], shapes, [])
    kern = P.ProximityKernel([("a", 0.1)], shapes, [("a", "table")])
    with pytest.raises(ValueError, match=r"\(T, 1, 3\)"):
        kern.distances(np.zeros((5, 2, 3)), np.zeros((5, 2, 3)))
    assert kern.distances(np.zeros((0, 1, 3)), np.zeros((0, 1, 3))).shape == (0, 1)


def _shape_shape_plain(a, b, pose_a, pose_b):
    """The slow obvious reference for a carried object: every sample, both poses set, one ``coal.distance`` call
    (GJK at 1e-12 when apart, EPA when overlapping)."""
    T = max(len(np.atleast_3d(pose_a).reshape(-1, 4, 4)), len(np.atleast_3d(pose_b).reshape(-1, 4, 4)))
    Pa = np.broadcast_to(np.asarray(pose_a, float).reshape(-1, 4, 4), (T, 4, 4))
    Pb = np.broadcast_to(np.asarray(pose_b, float).reshape(-1, 4, 4), (T, 4, 4))
    out = np.empty(T)
    for t in range(T):
        ga, ta = _coal_shape(a.kind, a.size, Pa[t])
        gb, tb = _coal_shape(b.kind, b.size, Pb[t])
        out[t] = coal_distance(ga, ta, gb, tb)
    return out


@settings(max_examples=25, **SETTINGS)
@given(seed=st.integers(0, 2**31 - 1), far=st.sampled_from([None, 0.05, 0.1]))
def test_carried_object_kernel_matches_the_per_sample_reference(seed, far):
    """The kernel's carried-object pairs (pose-change runs computed once per object, static poses set once) give
    the per-sample reference's distances: a carried box and cylinder, held still at times, against boxes and
    cylinders at rest and one object moved earlier (two per-sample poses)."""
    rng = np.random.default_rng(seed)
    T = 120
    path = np.cumsum(rng.normal(scale=0.01, size=(T, 3)), axis=0) + [0.1, 0.0, 0.1]
    path[30:50] = path[30]  # held still: one run
    carried = np.tile(np.eye(4), (T, 1, 1))
    carried[:, :3, 3] = path
    for t in range(T):
        carried[t, :3, :3] = rpy_matrix(tuple(0.02 * t * np.array([1.0, -0.5, 0.3])))
    moved = np.tile(np.eye(4), (T, 1, 1))
    moved[60:, :3, 3] = [0.05, 0.05, 0.0]  # set down elsewhere halfway
    shapes = [
        Shape("cup", "cup", "cylinder", (0.03, 0.1), np.eye(4)),
        Shape("box", "box", "box", (0.04, 0.06, 0.08), np.eye(4)),
        Shape("crate", "crate", "box", tuple(rng.uniform(0.05, 0.2, 3)), _pose_of(rng)),
        Shape("can", "can", "cylinder", (float(rng.uniform(0.02, 0.05)), float(rng.uniform(0.05, 0.15))), _pose_of(rng)),
        Shape("ball", "ball", "sphere", (0.03,), _pose_of(rng)),
    ]
    pairs = [("cup", "crate"), ("cup", "can"), ("cup", "box"), ("cup", "ball"), ("box", "crate"), ("box", "can")]
    kern = P.ProximityKernel([("link", 0.01)], shapes, pairs, moving={"cup", "box"})
    D = kern.distances(np.zeros((T, 1, 3)), np.zeros((T, 1, 3)), poses={"cup": carried, "box": moved}, far_m=far)
    by = {s.name: s for s in shapes}
    pose = {"cup": carried, "box": moved}
    near = 0
    for k, (a, b) in enumerate(pairs):
        ref = _shape_shape_plain(by[a], by[b], pose.get(a, by[a].pose), pose.get(b, by[b].pose))
        if "ball" in (a, b):  # closed form, not coal
            np.testing.assert_allclose(D[:, k], PK.sphere_shape(by["ball"].pose[:3, 3], 0.03, by[a], pose[a]), atol=1e-12)
            continue
        # exact up to the cutoff (apart: GJK at 1e-12; overlapping: EPA, boxes exact, cylinders ~1e-5 m) ...
        within = ref <= (np.inf if far is None else far)
        apart = ref > 1e-6
        near += int((ref <= (far or 0.1)).sum())
        np.testing.assert_allclose(D[within & apart, k], ref[within & apart], rtol=0, atol=1e-9)
        np.testing.assert_allclose(D[within & ~apart, k], ref[within & ~apart], rtol=0, atol=3e-5)
        # ... and beyond it a lower bound that is itself beyond
        assert (D[~within, k] > far).all() and (D[~within, k] <= ref[~within] + 1e-9).all()
    assert near > 0  # some samples really were near


def _pose_of(rng):
    pose = np.eye(4)
    pose[:3, :3] = rpy_matrix(tuple(rng.uniform(-0.5, 0.5, 3)))
    pose[:3, 3] = [0.1, 0.0, 0.1] + rng.normal(scale=0.08, size=3)
    return pose


@pytest.mark.parametrize("far_m", [None, 0.1])
def test_zero_samples_give_an_empty_result_for_every_kind_of_pair(far_m):
    shapes = [Shape("o", "o", "box", (0.1, 0.1, 0.1), np.eye(4)), Shape("t", "t", "box", (1.0, 1.0, 0.1), np.eye(4))]
    kernel = P.ProximityKernel([("c", 0.01), ("d", 0.01)], shapes, [("o", "t"), ("c", "t"), ("c", "d")], moving=["o"])
    empty = np.zeros((0, 2, 3))
    assert kernel.distances(empty, empty, poses={"o": np.zeros((0, 4, 4))}, far_m=far_m).shape == (0, 3)
