"""The UR closed form searched for the branch nearest a seed: branch-and-bound over its steps (rad, m).

:func:`_nearest_solution` is :func:`robocritics.robot.ik.ur_ik`'s search: the steps of the closed form (see
:mod:`robocritics.robot.ik`; the same expressions as :func:`robocritics.robot.ik._branches`, so the same floats),
each angle moved to its ``2 pi``-equivalent within the limits nearest the seed as soon as it is known. The cost
``sum_i w_i (q_i - seed_i)²`` only grows as joints are added, so its partial sum is a lower bound on every branch
below: a branch is abandoned as soon as it reaches the best complete one (shoulder pan, then the wrists, then the
elbow, shoulder lift and wrist 1), and at each level the cheaper alternative is tried first, so the elbow of a
branch that cannot win is never computed. The steps are written out rather than called per step or per joint,
and :func:`_nearest_equivalent`'s common case (the seed-nearest equivalent within the limits) inline at each use:
on CPython a call per step was half the time of a solve. ``tests/test_ik_nearest.py`` holds the plain search
(every branch evaluated) as the reference.

:func:`_nearest_search` runs this search (:func:`_nearest_search_plain`) compiled where it can: on CPython the
Python search executes about 1,200 bytecodes per solve (some 50,000 machine instructions), the C module
``robocritics.robot._ur_nearest`` (``_ur_nearest.c``, built by ``setup.py``) the same expressions in the same order
on doubles, so the same floats (``tests/test_ik_nearest_compiled.py``), in a tenth of the time. It leaves the
wrist near its singularity (``q6`` nudged), non-finite input and a ``verify`` callback to the Python search.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from math import acos, atan2, cos, sin, sqrt  # names, not attributes: one lookup less per call in the search

from .ik_many import _CLIP_TOL, _HALF_PI, _LIMIT_SLACK, _PI, _TWO_PI, _WRIST_NEAR_SINGULAR, _WRIST_SINGULAR

__all__: list[str] = []  # the closed form's internals: robocritics.robot.ik is the API


def _load_compiled() -> Callable[..., object] | None:
    """The compiled search's entry point, configured with this module's constants, or None if it is not built."""
    try:
        from . import _ur_nearest  # type: ignore[attr-defined]  # C (setup.py); optional
    except ImportError:
        return None
    _ur_nearest.configure(_PI, _CLIP_TOL, _WRIST_NEAR_SINGULAR, _WRIST_SINGULAR, _LIMIT_SLACK)
    return _ur_nearest.nearest_search


_compiled_search = _load_compiled()

Verify = Callable[[list[float]], bool]


def _wrap(x: float) -> float:
    """Angle wrapped to (-pi, pi]."""
    x = math.remainder(x, _TWO_PI)
    return x + _TWO_PI if x <= -_PI else x


def _nearest_equivalent(x: float, seed: float, lo: float, hi: float) -> float | None:
    """``x + 2 pi n`` within ``[lo, hi]`` nearest to ``seed`` (clamped into the
    limits if it is at most ``_LIMIT_SLACK`` outside), or None if none fits."""
    v = x + round((seed - x) / _TWO_PI) * _TWO_PI
    if lo <= v <= hi:  # the common case: the seed-nearest equivalent is within the limits
        return v
    n_min = math.ceil((lo - _LIMIT_SLACK - x) / _TWO_PI)
    n_max = math.floor((hi + _LIMIT_SLACK - x) / _TWO_PI)
    if n_min > n_max:
        return None
    v = x + (n_max if v > hi else n_min) * _TWO_PI
    return hi if v > hi else (lo if v < lo else v)


def _wrist1_planar(
    k: tuple[float, ...], t: Sequence[float], c1: float, s1: float, p5x: float, p5y: float, q6: float
) -> tuple[float, float]:
    """Step 4, first half: the wrist-1 centre ``p4 = p5 - d5 z4`` (``z4 = -(sin q6 x6 + cos q6 y6)``)
    in the planar coordinates ``(X, Y)`` of frame 1 (m)."""
    d1, d5, d6 = k[0], k[4], k[5]
    xx, yx, _, _, xy, yy, _, _, xz, yz, zz, pz = t
    c6 = math.cos(q6)
    s6 = math.sin(q6)
    z4x = -(s6 * xx + c6 * yx)
    z4y = -(s6 * xy + c6 * yy)
    z4z = -(s6 * xz + c6 * yz)
    return (p5x - d5 * z4x) * c1 + (p5y - d5 * z4y) * s1, pz - d6 * zz - d5 * z4z - d1


def _singular_q6(
    k: tuple[float, ...],
    t: Sequence[float],
    c1: float,
    s1: float,
    p5x: float,
    p5y: float,
    q6: float,
    too_far: bool,
) -> float | None:
    """At the wrist singularity (flange z parallel to the shoulder axes), the
    value of ``q6`` nearest to ``q6`` that brings the wrist-1 centre within the
    elbow's range, or None.

    In the arm plane the wrist-1 centre is ``P4 = P5 - d5 u`` with ``u`` the
    planar direction of ``z4 = -(sin q6 x6 + cos q6 y6)``; so
    ``|P4|² = R² + d5² - 2 d5 R cos(psi - theta)`` with ``P5 = R e^{i theta}``,
    ``u = e^{i psi}``. The elbow reaches ``|P4|² = a2² + a3² ± 2 a2 a3``; the
    boundary ``psi = theta ± acos((R² + d5² - D²) / (2 d5 R))`` nearest to the
    current ``psi`` is taken and mapped back to ``q6 = atan2(-u·x6, -u·y6)``.
    """
    d1, a2, a3, d4, d5, d6, a2a3_sq, two_a2a3 = k
    xx, yx, zx, px, xy, yy, zy, py, xz, yz, zz, pz = t
    PX = p5x * c1 + p5y * s1
    PY = pz - d6 * zz - d1
    R = math.hypot(PX, PY)
    if R == 0.0 or d5 == 0.0:
        return None
    D2 = a2a3_sq + (two_a2a3 if too_far else -two_a2a3)
    cb = (R * R + d5 * d5 - D2) / (2.0 * d5 * R)
    if not -1.0 - _CLIP_TOL <= cb <= 1.0 + _CLIP_TOL:
        return None
    cb = 1.0 if cb > 1.0 else (-1.0 if cb < -1.0 else cb)
    x6p = (xx * c1 + xy * s1, xz)
    y6p = (yx * c1 + yy * s1, yz)
    s6, c6 = math.sin(q6), math.cos(q6)
    psi0 = math.atan2(-(s6 * x6p[1] + c6 * y6p[1]), -(s6 * x6p[0] + c6 * y6p[0]))
    theta = math.atan2(PY, PX)
    beta = math.acos(cb)
    psi = min((theta + beta, theta - beta), key=lambda a: abs(_wrap(a - psi0)))
    ux, uy = math.cos(psi), math.sin(psi)
    return math.atan2(-(ux * x6p[0] + uy * x6p[1]), -(ux * y6p[0] + uy * y6p[1]))


def _off_seed(x: float, seed: float, lo: float, hi: float, w: float, cost: float) -> tuple[float | None, float, bool]:
    """For an angle ``x`` more than pi from ``seed`` or outside ``[lo, hi]``: ``(v, cost + w (v - seed)², exact)``
    with ``v`` :func:`_nearest_equivalent` (None and cost inf if none fits) and ``exact`` whether ``v`` was not
    clamped onto a limit (``_LIMIT_SLACK``); the slow path of the search, out of its way."""
    n = (seed - x) / _TWO_PI
    # _nearest_equivalent's common case; one turn away, round(n) is +-1 without the call (half its cost here)
    if 0.5 < n < 1.5:
        v = x + _TWO_PI
    elif -1.5 < n < -0.5:
        v = x - _TWO_PI
    else:
        v = x + round(n) * _TWO_PI
    if lo <= v <= hi:
        return v, cost + w * (v - seed) * (v - seed), True
    v = _nearest_equivalent(x, seed, lo, hi)
    if v is None:
        return None, math.inf, False
    return v, cost + w * (v - seed) * (v - seed), not (v == lo or v == hi)  # on a limit: perhaps clamped


def _nearest_solution(
    k: tuple[float, ...],
    t: Sequence[float],
    sd: Sequence[float],
    lo: Sequence[float],
    hi: Sequence[float],
    w: Sequence[float],
    verify: Verify | None = None,
) -> list[float] | None:
    """The branch of the closed form with the smallest ``sum w_i (q_i - seed_i)²``
    within the limits (and, if ``verify`` is given, that passes it), or None: :func:`_nearest_search`'s joints."""
    found = _nearest_search(k, t, sd, lo, hi, w, verify)
    return None if found is None else found[1]


def _nearest_search(
    k: tuple[float, ...],
    t: Sequence[float],
    sd: Sequence[float],
    lo: Sequence[float],
    hi: Sequence[float],
    w: Sequence[float],
    verify: Verify | None = None,
) -> tuple[float, list[float], bool] | None:
    """:func:`_nearest_search_plain`, by the compiled search (``robocritics.robot._ur_nearest``, the same floats)
    when it is built, ``verify`` is None and the case is its common one (finite inputs, the wrist away from its
    singularity); by the Python search otherwise."""
    if verify is None and _compiled_search is not None:
        found = _compiled_search(k, t, sd, lo, hi, w)
        if found is not NotImplemented:
            return found
    return _nearest_search_plain(k, t, sd, lo, hi, w, verify)


def _nearest_search_plain(
    k: tuple[float, ...],
    t: Sequence[float],
    sd: Sequence[float],
    lo: Sequence[float],
    hi: Sequence[float],
    w: Sequence[float],
    verify: Verify | None = None,
) -> tuple[float, list[float], bool] | None:
    """``(cost, q, exact)`` of the branch of the closed form with the smallest ``cost = sum w_i (q_i - seed_i)²``
    within the limits (and, if ``verify`` is given, that passes it), or None.

    ``t`` the 12-float row-major flange target (m), ``sd``, ``lo``, ``hi``, ``w`` 6 floats each (rad, weights).
    ``exact``: no step of the branch was clipped or nudged (``|d4 / r| <= 1``, ``|cos q3| <= 1``, ``|sin q5| >=
    _WRIST_NEAR_SINGULAR``), so for a target whose rotation is orthonormal the branch reproduces it to rounding
    (see :func:`robocritics.robot.ik.ur_ik`). Step 1 here (the two shoulder pans, the cheaper first);
    :func:`_nearest_wrists` below each. At the wrist singularity ``q6`` keeps the seed's.
    """
    d6 = k[5]
    # step 1 (_shoulder_pans)
    p5x = t[3] - d6 * t[2]
    p5y = t[7] - d6 * t[6]
    r = sqrt(p5x * p5x + p5y * p5y)
    if r == 0.0:
        return None
    ratio = k[3] / r
    exact = -1.0 <= ratio <= 1.0
    if not exact:
        if not -1.0 - _CLIP_TOL <= ratio <= 1.0 + _CLIP_TOL:
            return None
        ratio = 1.0 if ratio > 1.0 else -1.0
    phi = atan2(p5y, p5x) + _HALF_PI
    dphi = acos(ratio)
    s0, l0, h0, w0 = sd[0], lo[0], hi[0], w[0]
    inf = math.inf
    qa = phi + dphi
    d = s0 - qa
    ea = eb = True  # whether the equivalent was not clamped onto a limit (see _certified)
    if -_PI < d < _PI and l0 <= qa <= h0:  # the seed-nearest equivalent, within the limits
        va, ca = qa, w0 * d * d  # (v - s)² = d²: the same float
    else:
        va, ca, exact_v = _off_seed(qa, s0, l0, h0, w0, 0.0)
        ea = ea and exact_v
    qb = phi - dphi
    d = s0 - qb
    if -_PI < d < _PI and l0 <= qb <= h0:
        vb, cb = qb, w0 * d * d
    else:
        vb, cb, exact_v = _off_seed(qb, s0, l0, h0, w0, 0.0)
        eb = eb and exact_v
    if cb < ca:
        qa, va, ca, ea, qb, vb, cb, eb = qb, vb, cb, eb, qa, va, ca, ea
    if ca == inf:
        return None
    found = _nearest_wrists(k, t, p5x, p5y, qa, va, ca, exact and ea, inf, sd, lo, hi, w, verify)
    best = inf if found is None else found[0]
    if cb < best:
        other = _nearest_wrists(k, t, p5x, p5y, qb, vb, cb, exact and eb, best, sd, lo, hi, w, verify)
        if other is not None:
            found = other
    return found


def _nearest_wrists(
    k: tuple[float, ...], t: Sequence[float], p5x: float, p5y: float, q1: float, v1: float, cost1: float,
    exact: bool, best: float, sd: Sequence[float], lo: Sequence[float], hi: Sequence[float], w: Sequence[float],
    verify: Verify | None,
) -> tuple[float, list[float], bool] | None:
    """Steps 2 and 3 (``_wrists``) for the shoulder pan ``q1`` (its equivalent ``v1`` costs ``cost1``; ``exact``
    whether step 1 was): the two wrists, the cheaper first, each searched by :func:`_nearest_elbow`; ``(cost, q,
    exact)`` cheaper than ``best``, or None. The wrist down's ``q6`` is only computed when that wrist can still
    win (its ``q5`` cost alone is a lower bound). Near the wrist singularity (``|sin q5| <
    _WRIST_NEAR_SINGULAR``) the elbow step may nudge ``q6``, so its cost is left to :func:`_nearest_elbow`."""
    xx, yx, zx, _, xy, yy, zy, _, _, _, _, _ = t
    c1, s1 = cos(q1), sin(q1)
    xz1 = xx * s1 - xy * c1  # z1 = (s1, -c1, 0) in flange axes: cos q6 sin q5
    yz1 = yx * s1 - yy * c1  # -sin q6 sin q5
    zz1 = zx * s1 - zy * c1  # cos q5
    s5abs = sqrt(xz1 * xz1 + yz1 * yz1)
    _, _, _, _, s4, s5 = sd
    _, _, _, _, l4, l5 = lo
    _, _, _, _, h4, h5 = hi
    _, _, _, _, w4, w5 = w
    free = s5abs < _WRIST_NEAR_SINGULAR  # q6 is not final: the elbow step may nudge it
    if free:
        exact = False
    singular = s5abs < _WRIST_SINGULAR  # q6 is the seed's
    # the wrist up, with its q6
    q5u = atan2(s5abs, zz1)
    q6u = s5 if singular else atan2(-yz1, xz1)
    eu = exact
    d = s4 - q5u
    if -_PI < d < _PI and l4 <= q5u <= h4:  # the seed-nearest equivalent, within the limits
        v5u, cu = q5u, cost1 + w4 * d * d  # (v - s)² = d²: the same float
    else:
        v5u, cu, exact_v = _off_seed(q5u, s4, l4, h4, w4, cost1)
        eu = eu and exact_v
    v6u = None
    if not free and v5u is not None:
        d = s5 - q6u
        if -_PI < d < _PI and l5 <= q6u <= h5:
            v6u, cu = q6u, cu + w5 * d * d
        else:
            v6u, cu, exact_v = _off_seed(q6u, s5, l5, h5, w5, cu)
            eu = eu and exact_v
    # the wrist down: q5 first (a lower bound on its cost)
    q5d = atan2(-s5abs, zz1)
    ed = exact
    d = s4 - q5d
    if -_PI < d < _PI and l4 <= q5d <= h4:
        v5d, cd = q5d, cost1 + w4 * d * d
    else:
        v5d, cd, exact_v = _off_seed(q5d, s4, l4, h4, w4, cost1)
        ed = ed and exact_v
    found = None
    up_done = cu <= cd  # then the wrist up is the cheaper whatever the wrist down's q6 costs: it goes first
    if up_done:
        if cu >= best:
            return None
        found = _nearest_elbow(k, t, c1, s1, p5x, p5y, s5abs, q5u, q6u, v1, v5u, v6u, cu, eu, best, sd, lo, hi, w, verify)
        if found is not None:
            best = found[0]
        if cd >= best:
            return found
    q6d = s5 if singular else atan2(yz1, -xz1)
    v6d = None
    if not free and v5d is not None:
        d = s5 - q6d
        if -_PI < d < _PI and l5 <= q6d <= h5:
            v6d, cd = q6d, cd + w5 * d * d
        else:
            v6d, cd, exact_v = _off_seed(q6d, s5, l5, h5, w5, cd)
            ed = ed and exact_v
    if not up_done and not cd < cu:  # the wrist up first after all
        if cu >= best:
            return None
        found = _nearest_elbow(k, t, c1, s1, p5x, p5y, s5abs, q5u, q6u, v1, v5u, v6u, cu, eu, best, sd, lo, hi, w, verify)
        if found is not None:
            best = found[0]
        up_done = True
    if cd < best:
        other = _nearest_elbow(k, t, c1, s1, p5x, p5y, s5abs, q5d, q6d, v1, v5d, v6d, cd, ed, best, sd, lo, hi, w, verify)
        if other is not None:
            found = other
            best = other[0]
    if not up_done and cu < best:
        other = _nearest_elbow(k, t, c1, s1, p5x, p5y, s5abs, q5u, q6u, v1, v5u, v6u, cu, eu, best, sd, lo, hi, w, verify)
        if other is not None:
            found = other
    return found


def _nearest_elbow(
    k: tuple[float, ...], t: Sequence[float], c1: float, s1: float, p5x: float, p5y: float, s5abs: float,
    q5: float, q6: float, v1: float, v5: float, v6: float | None, cost56: float, exact: bool, best: float,
    sd: Sequence[float], lo: Sequence[float], hi: Sequence[float], w: Sequence[float],
    verify: Verify | None,
) -> tuple[float, list[float], bool] | None:
    """Step 4 for one (shoulder, wrist) branch whose shoulder pan and wrist angles cost ``cost56``: ``(cost, q,
    exact)`` of its elbow cheaper than ``best``, or None (``exact``: the wrist is not near its singularity and
    ``cos q3`` was not clipped). ``v6`` None: ``q6`` may still be nudged (near the wrist singularity), so its
    cost is not yet in ``cost56``."""
    d1, a2, a3, _, d5, d6, a2a3_sq, two_a2a3 = k
    xx, yx, zx, _, xy, yy, zy, _, xz, yz, zz, pz = t
    # _elbow and _wrist1_planar
    c6, s6 = cos(q6), sin(q6)
    z4x = -(s6 * xx + c6 * yx)
    z4y = -(s6 * xy + c6 * yy)
    z4z = -(s6 * xz + c6 * yz)
    X = (p5x - d5 * z4x) * c1 + (p5y - d5 * z4y) * s1
    Y = pz - d6 * zz - d5 * z4z - d1
    c3 = (X * X + Y * Y - a2a3_sq) / two_a2a3
    if not -1.0 <= c3 <= 1.0:
        exact = False
        if s5abs < _WRIST_NEAR_SINGULAR:
            nudged = _singular_q6(k, t, c1, s1, p5x, p5y, q6, c3 > 1.0)
            if nudged is not None:
                q6 = nudged
                c6, s6 = cos(q6), sin(q6)
                X, Y = _wrist1_planar(k, t, c1, s1, p5x, p5y, q6)
                c3 = (X * X + Y * Y - a2a3_sq) / two_a2a3
        if not -1.0 <= c3 <= 1.0:
            if not -1.0 - _CLIP_TOL <= c3 <= 1.0 + _CLIP_TOL:
                return None
            c3 = 1.0 if c3 > 1.0 else -1.0
    if v6 is None:
        s5, l5, h5 = sd[5], lo[5], hi[5]
        v6 = _nearest_equivalent(q6, s5, l5, h5)
        if v6 is None:
            return None
        cost56 += w[5] * (v6 - s5) * (v6 - s5)
        if cost56 >= best:
            return None
    # one unpacking per list: a third of the opcodes of indexing each
    _, s1_, s2, s3, _, _ = sd
    _, l1, l2, l3, _, _ = lo
    _, h1, h2, h3, _, _ = hi
    _, w1, w2, w3, _, _ = w
    # the two elbows (q3 = +acos, -acos), the one nearer the seed in q3 first: the other then rarely gets further
    t3 = acos(c3)
    d = s2 - t3
    ep = em = exact
    if -_PI < d < _PI and l2 <= t3 <= h2:  # the seed-nearest equivalent, within the limits
        v3p, cp = t3, cost56 + w2 * d * d  # (v - s)² = d²: the same float
    else:
        v3p, cp, exact_v = _off_seed(t3, s2, l2, h2, w2, cost56)
        ep = ep and exact_v
    d = s2 - (-t3)
    if -_PI < d < _PI and l2 <= -t3 <= h2:  # the seed-nearest equivalent, within the limits
        v3m, cm = -t3, cost56 + w2 * d * d  # (v - s)² = d²: the same float
    else:
        v3m, cm, exact_v = _off_seed(-t3, s2, l2, h2, w2, cost56)
        em = em and exact_v
    if cp >= best and cm >= best:
        return None
    c5, s5_ = cos(q5), sin(q5)
    # x4 = c5 x5 - s5 z6 with x5 = c6 x6 - s6 y6
    x4x = c5 * (c6 * xx - s6 * yx) - s5_ * zx
    x4y = c5 * (c6 * xy - s6 * yy) - s5_ * zy
    x4z = c5 * (c6 * xz - s6 * yz) - s5_ * zz
    base = atan2(Y, X)
    q234 = atan2(x4z, x4x * c1 + x4y * s1)
    found = None
    for cost3, q3, v3, e3 in ((cm, -t3, v3m, em), (cp, t3, v3p, ep)) if cm < cp else ((cp, t3, v3p, ep), (cm, -t3, v3m, em)):
        if cost3 >= best:
            break
        q2 = base - atan2(a3 * sin(q3), a2 + a3 * c3)  # _shoulder_lift
        d = s1_ - q2
        if -_PI < d < _PI and l1 <= q2 <= h1:  # the seed-nearest equivalent, within the limits
            v2, cost2 = q2, cost3 + w1 * d * d  # (v - s)² = d²: the same float
        else:
            v2, cost2, exact_v = _off_seed(q2, s1_, l1, h1, w1, cost3)
            if v2 is None:
                continue
            e3 = e3 and exact_v
        if cost2 >= best:
            continue
        q4 = q234 - q2 - q3
        d = s3 - q4
        if -_PI < d < _PI and l3 <= q4 <= h3:
            v4, cost = q4, cost2 + w3 * d * d
        else:
            v4, cost, exact_v = _off_seed(q4, s3, l3, h3, w3, cost2)
            if v4 is None:
                continue
            e3 = e3 and exact_v
        if cost < best:
            q = [v1, v2, v3, v4, v5, v6]
            if verify is None or verify(q):
                best = cost
                found = (cost, q, e3)
    return found
