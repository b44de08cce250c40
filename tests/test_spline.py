"""planning.spline: the numpy cubic spline and PCHIP against scipy's (the slow reference stays in the tests)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import CubicSpline, PchipInterpolator

from robocritics.planning.spline import cubic_spline, pchip

finite = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False)


@st.composite
def knots(draw, max_n=40, cols=(1, 6)):
    n = draw(st.integers(2, max_n))
    steps = draw(st.lists(st.floats(1e-3, 2.0), min_size=n - 1, max_size=n - 1))
    x = draw(finite) + np.cumsum([0.0, *steps])
    k = draw(st.integers(*cols))
    y = np.array(draw(st.lists(st.lists(finite, min_size=k, max_size=k), min_size=n, max_size=n)))
    if draw(st.booleans()):  # a 1-D y as well as columns
        y = y[:, 0]
    # evaluation points: the knots, points between them, a little beyond both ends
    xs = np.concatenate([x, np.linspace(x[0] - 0.1, x[-1] + 0.1, 97)])
    return x, y, xs


def close(a, b, y):
    # relative to the values compared: extrapolating 0.1 beyond knots 1 mm apart reaches |values| >> |y|
    scale = 1.0 + float(np.abs(y).max()) + float(np.abs(b).max())
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * scale)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(knots())
def test_cubic_spline_matches_scipy_not_a_knot(data):
    x, y, xs = data
    close(cubic_spline(x, y, xs), CubicSpline(x, y, axis=0)(xs), y)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(knots())
def test_pchip_matches_scipy(data):
    x, y, xs = data
    close(pchip(x, y, xs), PchipInterpolator(x, y, axis=0)(xs), y)


def test_spline_of_a_planner_like_grid_matches_scipy_to_rounding():
    # the planner's use: a uniform path-length grid of joint angles (rad), evaluated on a dense path sampling
    s_grid = np.linspace(0.0, 0.37, 75)
    q = np.column_stack([np.sin(3 * s_grid + j) for j in range(6)])
    s = np.sort(np.random.default_rng(1).uniform(0, 0.37, 5000))
    np.testing.assert_allclose(cubic_spline(s_grid, q, s), CubicSpline(s_grid, q, axis=0)(s), rtol=0, atol=1e-14)


def test_interpolates_the_knots_and_reproduces_cubics():
    x = np.array([0.0, 0.3, 1.0, 1.2, 2.5])
    cubic = 1 - 2 * x + 0.5 * x**2 - 0.25 * x**3
    xs = np.linspace(-0.5, 3.0, 50)
    np.testing.assert_allclose(cubic_spline(x, cubic, xs), 1 - 2 * xs + 0.5 * xs**2 - 0.25 * xs**3, atol=1e-12)
    np.testing.assert_allclose(pchip(x, cubic, x), cubic, atol=1e-15)


def test_pchip_does_not_overshoot_monotone_data():
    x = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    y = np.array([0.0, 0.0, 1.0, 1.0, 1.0])
    v = pchip(x, y, np.linspace(0, 4, 401))
    assert v.min() >= 0.0 and v.max() <= 1.0 and np.all(np.diff(v) >= -1e-15)


@pytest.mark.parametrize("fn", [cubic_spline, pchip])
def test_bad_knots_are_a_value_error(fn):
    with pytest.raises(ValueError, match="strictly increasing"):
        fn(np.array([0.0, 1.0, 1.0]), np.zeros(3), np.zeros(2))
    with pytest.raises(ValueError, match="n >= 2"):
        fn(np.array([0.0]), np.zeros(1), np.zeros(2))


def _numpy_thomas(diag, upper, lower, rhs):
    """The obvious Thomas algorithm on numpy rows (the reference for the Python-float one in _not_a_knot_slopes)."""
    n = len(diag)
    c, r = np.empty(n), np.empty_like(rhs)
    c[0], r[0] = upper[0] / diag[0], rhs[0] / diag[0]
    for i in range(1, n):
        denom = diag[i] - lower[i] * c[i - 1]
        c[i] = upper[i] / denom
        r[i] = (rhs[i] - lower[i] * r[i - 1]) / denom
    s = np.empty_like(rhs)
    s[-1] = r[-1]
    for i in range(n - 2, -1, -1):
        s[i] = r[i] - c[i] * s[i + 1]
    return s


@settings(max_examples=200, deadline=None, derandomize=True)
@given(knots(max_n=60))
def test_not_a_knot_slopes_are_the_numpy_thomas_solution_bit_for_bit(data):
    # the system _not_a_knot_slopes builds, solved by numpy row operations
    from robocritics.planning.spline import _not_a_knot_slopes, _not_a_knot_system

    x, y, _ = data
    if len(x) < 4:
        return
    h = np.diff(x)
    hr = h.reshape((-1,) + (1,) * (y.ndim - 1))
    diag, upper, lower, rhs = _not_a_knot_system(x, y, h, hr, np.diff(y, axis=0) / hr)
    assert np.array_equal(_not_a_knot_slopes(x, y), _numpy_thomas(diag, upper, lower, rhs))
