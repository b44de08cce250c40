"""geometry.hull: coal's hull and the numpy quickhull against scipy's Qhull (the slow reference, tests only)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import ConvexHull

from robocritics.geometry.hull import convex_hull, quickhull

IMPLEMENTATIONS = [convex_hull, quickhull]


@st.composite
def clouds(draw):
    """Random 3-D point sets in general position: a Gaussian blob, a box, or points on a sphere (all vertices)."""
    seed = draw(st.integers(0, 2**32 - 1))
    n = draw(st.integers(4, 400))
    kind = draw(st.sampled_from(["normal", "box", "sphere"]))
    rng = np.random.default_rng(seed)
    P = rng.normal(size=(n, 3)) if kind != "box" else rng.uniform(-1, 1, size=(n, 3))
    if kind == "sphere":
        P /= np.linalg.norm(P, axis=1, keepdims=True)
    scale = draw(st.sampled_from([0.01, 0.3, 1.0, 50.0]))
    offset = np.array(draw(st.tuples(*[st.floats(-2, 2)] * 3)))
    if draw(st.booleans()):  # repeated points (a robot frame visiting a place twice)
        P = np.concatenate([P, P[rng.integers(0, n, size=n // 3)]])
    return P * scale + offset


@pytest.mark.parametrize("hull_of", IMPLEMENTATIONS)
@settings(max_examples=150, deadline=None, derandomize=True)
@given(P=clouds())
def test_matches_scipy(hull_of, P):
    ref = ConvexHull(P)
    got = hull_of(P)
    assert got.volume_m3 == pytest.approx(ref.volume, rel=1e-9)
    assert got.area_m2 == pytest.approx(ref.area, rel=1e-9)
    # in general position the vertex sets agree; ours names the first of equal points
    _, first = np.unique(P, axis=0, return_index=True)
    first_of = {tuple(P[i]): i for i in first}
    assert got.vertices.tolist() == sorted({first_of[tuple(P[i])] for i in ref.vertices})


def _fan(n: int) -> np.ndarray:
    """A bipyramid over an n-gon: each apex has n hull neighbours (coal refuses more than 255)."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.concatenate([np.c_[np.cos(a), np.sin(a), np.zeros(n)], [[0, 0, 1.0], [0, 0, -1.0]]])


def test_a_vertex_with_many_neighbours_falls_back_to_quickhull():
    P = _fan(1000)
    ref = ConvexHull(P)
    got = convex_hull(P)
    assert got.volume_m3 == pytest.approx(ref.volume, rel=1e-9)
    assert got.area_m2 == pytest.approx(ref.area, rel=1e-9)
    assert got.vertices.tolist() == sorted(ref.vertices.tolist())


rng = np.random.default_rng(7)
FLAT = {
    "three points": rng.normal(size=(3, 3)),
    "one point repeated": np.ones((10, 3)),
    "collinear": np.outer(np.linspace(-1, 1, 30), [0.3, -0.2, 0.9]),
    "coplanar": np.c_[rng.normal(size=(50, 2)), np.zeros(50)] @ np.linalg.qr(rng.normal(size=(3, 3)))[0],
    "1e-14 thin": np.c_[rng.normal(size=(50, 2)), 1e-14 * rng.normal(size=50)],  # below quickhull's 1e-12
}


@pytest.mark.parametrize("hull_of", IMPLEMENTATIONS)
@pytest.mark.parametrize("name", list(FLAT))
def test_flat_sets_have_no_volume_and_do_not_crash(hull_of, name):
    got = hull_of(FLAT[name])
    assert got.volume_m3 == 0.0 and got.area_m2 == 0.0 and len(got.vertices) == 0


@pytest.mark.parametrize("hull_of", IMPLEMENTATIONS)
def test_non_finite_points_have_no_volume(hull_of):
    P = np.random.default_rng(0).normal(size=(20, 3))
    P[3, 1] = np.nan
    assert hull_of(P).volume_m3 == 0.0


@pytest.mark.parametrize("thickness", [1e-4, 1e-6, 1e-9])
def test_thin_sets_are_measured(thickness):
    # 1e-4 relative: coal measures it; 1e-6 and 1e-9 (below FLAT_RATIO; 1e-9 crashed coal): quickhull does
    P = np.c_[rng.uniform(-1, 1, size=(200, 2)), thickness * rng.uniform(-1, 1, size=200)]
    assert convex_hull(P).volume_m3 == pytest.approx(ConvexHull(P).volume, rel=1e-6)


def _normalised_reference(P):
    """The normalisation written plainly with np.ldexp (geometry/hull.py, once robot/hull.py, before its reductions were reordered)."""
    if len(P) < 4 or not np.isfinite(P).all():
        return None
    a = int(np.frexp(np.abs(P).max())[1])
    S = np.ldexp(P, -a)
    lo, hi = S.min(axis=0), S.max(axis=0)
    C = S - (lo + (hi - lo) / 2)
    top = float(np.abs(C).max())
    if top == 0.0:
        return None
    b = int(np.frexp(top)[1])
    return np.ldexp(C, -b), a + b


@settings(max_examples=300, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 40),
    exponent=st.integers(-1074, 1020),  # the points' scale 2^exponent: subnormal up to near overflow
    offset=st.sampled_from([0.0, 1.0, -3.0, 1e6]),  # far from the origin in units of the scale
    repeats=st.booleans(),
)
def test_normalised_is_bit_identical_to_the_ldexp_formula(seed, n, exponent, offset, repeats):
    from robocritics.geometry.hull import _normalised

    rng = np.random.default_rng(seed)
    with np.errstate(over="ignore"):  # near overflow some points are infinite: both give None
        P = np.ldexp(rng.normal(size=(n, 3)) + offset, exponent)
    if repeats:
        P = np.concatenate([P, P[: n // 2]])
    got, want = _normalised(P), _normalised_reference(P)
    assert (got is None) == (want is None)
    if got is not None:
        assert got[1] == want[1]
        np.testing.assert_array_equal(got[0], want[0])
        assert np.array_equal(np.signbit(got[0]), np.signbit(want[0]))  # -0.0 too


@pytest.mark.parametrize("k", [-1200, -1075, -1074, -1023, -1022, -600, 0, 600, 1023, 1024, 1100])
def test_times_pow2_is_ldexp(k):
    from robocritics.geometry.hull import _times_pow2

    x = np.array([0.0, -0.0, 1.0, -1.5, 3.0 * 2.0**-1074, 2.0**-1022, 0.7 * 2.0**-1000, 1.9 * 2.0**1000, 1e300])
    x = np.r_[x, -x / 3]
    with np.errstate(over="ignore", under="ignore"):
        got, want = _times_pow2(x, k), np.ldexp(x, k)
    np.testing.assert_array_equal(got, want)
    assert np.array_equal(np.signbit(got), np.signbit(want))


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 40))
def test_written_out_cross_product_is_numpys_bit_for_bit(seed, n):
    from robocritics.geometry.hull import _cross

    rng = np.random.default_rng(seed)
    u, v = rng.standard_normal((n, 3)) * 10.0 ** rng.integers(-8, 8), rng.standard_normal((n, 3))
    np.testing.assert_array_equal(_cross(u, v), np.cross(u, v))
