r"""Piecewise cubic interpolation in numpy (no scipy on the simulate and deploy paths).

Both interpolants are cubic Hermite: on ``[x_i, x_{i+1}]`` with ``h_i = x_{i+1} - x_i``, ``t = x - x_i``,
secant ``m_i = (y_{i+1} - y_i) / h_i`` and knot slopes ``s_i``,

    y(x) = y_i + s_i t + c2_i t^2 + c3_i t^3,
    c2_i = (m_i - s_i) / h_i - (s_i + s_{i+1} - 2 m_i) / h_i,   c3_i = (s_i + s_{i+1} - 2 m_i) / h_i^2,

and outside ``[x_0, x_{n-1}]`` the end pieces extend (extrapolation). They differ in the slopes:

* :func:`cubic_spline` — the C^2 interpolating spline with *not-a-knot* ends (the third derivative is
  continuous at ``x_1`` and ``x_{n-2}``), the same slopes as ``scipy.interpolate.CubicSpline``'s default:
  the tridiagonal system ``h_i s_{i-1} + 2 (h_{i-1} + h_i) s_i + h_{i-1} s_{i+1} = 3 (h_i m_{i-1} + h_{i-1} m_i)``
  with scipy's not-a-knot end rows; two points give the straight line, three the parabola through them.
* :func:`pchip` — the monotone piecewise cubic of Fritsch and Carlson (``scipy.interpolate.PchipInterpolator``):
  ``s_i = 0`` where the secants change sign or one is 0, else the weighted harmonic mean
  ``(w1 + w2) / (w1 / m_{i-1} + w2 / m_i)`` with ``w1 = 2 h_i + h_{i-1}``, ``w2 = h_i + 2 h_{i-1}``; the end
  slopes by the one-sided three-point formula, limited to keep the shape.

``x`` must be strictly increasing; ``y`` is ``(n,)`` or ``(n, k)`` (each column interpolated). Units are the
caller's (the planner: path length m to joint angle rad; deploy: time s to rad and m).
"""

from __future__ import annotations

import numpy as np

__all__ = ["cubic_spline", "pchip", "hermite"]


def _check(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.ndim != 1 or len(x) < 2 or y.shape[:1] != x.shape:
        raise ValueError(f"need x (n,) with n >= 2 and y (n, ...), got x {x.shape} and y {y.shape}")
    if not np.all(np.diff(x) > 0):
        raise ValueError("x must be strictly increasing")
    return x, y


def hermite(x: np.ndarray, y: np.ndarray, slopes: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """The cubic Hermite interpolant with knot values ``y`` and knot slopes ``slopes``, evaluated at ``xs``."""
    x, y = _check(x, y)
    return _hermite(x, y, np.asarray(slopes, dtype=float), xs)


def _hermite(
    x: np.ndarray, y: np.ndarray, slopes: np.ndarray, xs: np.ndarray, h: np.ndarray | None = None, m: np.ndarray | None = None
) -> np.ndarray:
    """:func:`hermite` for knots already checked by :func:`_check` (``h``, ``m``: the knot spacing and secants, if
    the caller has them)."""
    xs = np.asarray(xs, dtype=float)
    if h is None:
        h = np.diff(x)
    hr = h.reshape((-1,) + (1,) * (y.ndim - 1))
    if m is None:
        m = np.diff(y, axis=0) / hr
    t = (slopes[:-1] + slopes[1:] - 2 * m) / hr
    c3 = t / hr
    c2 = (m - slopes[:-1]) / hr - t
    # the piece of each xs: x_i <= xs < x_{i+1}, the last piece closed, the end pieces extended outward (the
    # count of inner knots at or below xs)
    i = np.searchsorted(x[1:-1], xs, side="right")
    dt = (xs - x[i]).reshape(xs.shape + (1,) * (y.ndim - 1))
    # the four coefficients of every piece in one array, so one gather fetches them for every xs
    c0, c1, c2, c3 = np.take(np.stack([y[:-1], slopes[:-1], c2, c3]), i, axis=1)  # take: a third of [:, i]'s CPU
    # power sums in scipy's PPoly order (not Horner), so the two agree to the last bit or two
    z = dt.copy()
    out = c0 + c1 * z
    z *= dt
    out += c2 * z
    z *= dt
    out += c3 * z
    return out


def _not_a_knot_system(x: np.ndarray, y: np.ndarray, h: np.ndarray, hr: np.ndarray, m: np.ndarray):
    """``(diag, upper, lower, rhs)`` of the not-a-knot slopes' tridiagonal system (``n >= 4`` knots):
    ``lower[i] s_{i-1} + diag[i] s_i + upper[i] s_{i+1} = rhs[i]``; ``h`` the knot spacing, ``m`` the secants."""
    n = len(x)
    diag = np.empty(n)
    upper = np.zeros(n)
    lower = np.zeros(n)
    rhs = np.empty_like(y)
    diag[1:-1] = 2 * (h[:-1] + h[1:])
    upper[1:-1] = h[:-1]
    lower[1:-1] = h[1:]
    rhs[1:-1] = 3 * (hr[1:] * m[:-1] + hr[:-1] * m[1:])
    d = x[2] - x[0]
    diag[0], upper[0] = h[1], d
    rhs[0] = ((hr[0] + 2 * d) * hr[1] * m[0] + hr[0] ** 2 * m[1]) / d
    d = x[-1] - x[-3]
    diag[-1], lower[-1] = h[-2], d
    rhs[-1] = (hr[-1] ** 2 * m[-2] + (2 * d + hr[-1]) * hr[-2] * m[-1]) / d
    return diag, upper, lower, rhs


def _not_a_knot_slopes(x: np.ndarray, y: np.ndarray, h: np.ndarray | None = None, m: np.ndarray | None = None) -> np.ndarray:
    """The not-a-knot spline's knot slopes (``h``, ``m``: the knot spacing and secants, if the caller has them)."""
    n = len(x)
    if h is None:
        h = np.diff(x)
    hr = h.reshape((-1,) + (1,) * (y.ndim - 1))
    if m is None:
        m = np.diff(y, axis=0) / hr
    if n == 2:  # one piece: not-a-knot is the straight line
        return np.stack([m[0], m[0]])
    if n == 3:  # both ends' conditions coincide: the parabola through the three points
        A = np.array([[1.0, 1.0, 0.0], [h[1], 2 * (h[0] + h[1]), h[0]], [0.0, 1.0, 1.0]])
        b = np.stack([2 * m[0], 3 * (hr[0] * m[1] + hr[1] * m[0]), 2 * m[1]])
        return np.linalg.solve(A, b.reshape(3, -1)).reshape(y.shape)
    diag, upper, lower, rhs = _not_a_knot_system(x, y, h, hr, m)
    # Thomas algorithm (the system is diagonally dominant inside; scipy uses LAPACK's banded LU, which
    # pivots, so the two agree to rounding, not bit for bit). Each step is a few scalar operations: on Python
    # floats (the same IEEE operations as numpy's, so the same bits), one column at a time, it costs a fraction
    # of a numpy call per step. The elimination's divisors depend on x only: once for every column.
    diag_l, upper_l, lower_l = diag.tolist(), upper.tolist(), lower.tolist()
    c = [0.0] * n
    denom = [0.0] * n
    c[0], denom[0] = upper_l[0] / diag_l[0], diag_l[0]
    for i in range(1, n):
        d = diag_l[i] - lower_l[i] * c[i - 1]
        denom[i], c[i] = d, upper_l[i] / d
    forward = list(zip(range(1, n), lower_l[1:], denom[1:]))
    backward = list(zip(range(n - 2, -1, -1), c[-2::-1]))
    columns = rhs.reshape(n, -1).T.tolist()
    for col in columns:  # solved in place: rhs -> r (forward) -> s (backward)
        prev = col[0] = col[0] / denom[0]
        for i, low, den in forward:
            prev = col[i] = (col[i] - low * prev) / den
        for i, ci in backward:
            prev = col[i] = col[i] - ci * prev
    return np.array(columns, dtype=float).T.reshape(rhs.shape)


def cubic_spline(x: np.ndarray, y: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """The not-a-knot cubic spline through ``(x, y)`` (as scipy's ``CubicSpline(x, y, axis=0)``) at ``xs``."""
    x, y = _check(x, y)
    h = np.diff(x)
    m = np.diff(y, axis=0) / h.reshape((-1,) + (1,) * (y.ndim - 1))
    return _hermite(x, y, _not_a_knot_slopes(x, y, h, m), xs, h, m)


def _pchip_slopes(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    h = np.diff(x)
    hr = h.reshape((-1,) + (1,) * (y.ndim - 1))
    m = np.diff(y, axis=0) / hr
    if len(x) == 2:
        return np.stack([m[0], m[0]])
    s = np.zeros_like(y)
    w1 = (2 * hr[1:] + hr[:-1])
    w2 = (hr[1:] + 2 * hr[:-1])
    same_sign = np.sign(m[1:]) * np.sign(m[:-1]) > 0
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # where a secant is 0 (or tiny), same_sign is False or the slope is 0
        harmonic = 1.0 / ((w1 / m[:-1] + w2 / m[1:]) / (w1 + w2))
    s[1:-1] = np.where(same_sign, harmonic, 0.0)
    s[0] = _pchip_end(h[0], h[1], m[0], m[1])
    s[-1] = _pchip_end(h[-1], h[-2], m[-1], m[-2])
    return s


def _pchip_end(h0: float, h1: float, m0: np.ndarray, m1: np.ndarray) -> np.ndarray:
    """One-sided three-point end slope, set to 0 against the secant's sign and capped at 3 m0 where the
    secants change sign (shape preserving, as scipy)."""
    d = ((2 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
    d = np.where(np.sign(d) != np.sign(m0), 0.0, d)
    return np.where((np.sign(m0) != np.sign(m1)) & (np.abs(d) > np.abs(3 * m0)), 3 * m0, d)


def pchip(x: np.ndarray, y: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """The monotone cubic (as scipy's ``PchipInterpolator(x, y, axis=0)``) through ``(x, y)`` at ``xs``."""
    x, y = _check(x, y)
    return _hermite(x, y, _pchip_slopes(x, y), xs)
