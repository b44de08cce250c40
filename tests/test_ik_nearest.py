"""The closed-form UR IK's fast paths against their plain references.

- ``ur_ik`` (branch-and-bound over the closed form, steps written out) against the plain search: every branch of
  :func:`robocritics.robot.ik._branches` evaluated, each joint moved to its seed-nearest equivalent within the
  limits, the FK-verified branch of least weighted cost taken.
- ``ur_ik_all`` against its previous implementation (kept here verbatim as the reference).
- The certificate that lets ``ur_ik`` skip the FK check (an exact branch of a target whose rotation is one)
  against Pinocchio's FK, at the singularities.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics.errors import PlanningError
from robocritics.robot.ik import (
    _CERTIFIED_ERROR,
    _DUPLICATE_TOL,
    _VERIFY_TOL,
    UR3E_DH,
    _branches,
    _certified,
    _Chain,
    _flagged_branches,
    _nearest_equivalent,
    _nearest_search,
    _wrap,
    dh_forward,
    ur_ik,
    ur_ik_all,
)

TWO_PI = 2.0 * math.pi
SAME_RAD = 1e-12  # the brief: bit-identical, or this close
# joint values that put the arm at or near a wrist, elbow or shoulder-pan special case, mixed with any angle
special = st.sampled_from([0.0, 1e-13, -1e-9, 1e-7, math.pi, -math.pi, math.pi - 1e-12, 0.5 * math.pi])
angle = st.one_of(st.floats(-math.pi, math.pi, allow_nan=False), special)
joints = st.lists(angle, min_size=6, max_size=6).map(np.array)


def plain_nearest(dh, T, seed, lower, upper, weights, tol=_VERIFY_TOL):
    """The plain search: all branches, each joint's equivalent within the limits nearest the seed, the least
    ``sum w_i (q_i - seed_i)²`` (summed in the fast search's order: q1, q5, q6, q3, q2, q4) among the branches
    whose FK reproduces ``T``; ``(cost, q)`` or None."""
    t = T[:3].ravel().tolist()
    chain = _Chain(dh)
    best = None
    for b in _branches(dh._ur, t, float(seed[5])):
        v = [_nearest_equivalent(b[j], seed[j], lower[j], upper[j]) for j in range(6)]
        if any(x is None for x in v):
            continue
        cost = 0.0
        for j in (0, 4, 5, 2, 1, 3):
            cost += weights[j] * (v[j] - seed[j]) * (v[j] - seed[j])
        dp, dr = chain.error(v, t)
        if dp <= tol and dr <= tol and (best is None or cost < best[0]):
            best = (cost, np.array(v))
    return best


def previous_ur_ik_all(dh, T, q6_singular=0.0):
    """``ur_ik_all`` as it was before the written-out duplicate test and FK check (the reference)."""
    t = T[:3].ravel().tolist()
    chain = _Chain(dh)
    sols = []
    for b in _branches(dh._ur, t, q6_singular):
        w = [_wrap(x) for x in b]
        if any(max(abs(_wrap(u - v)) for u, v in zip(w, s)) < _DUPLICATE_TOL for s in sols):
            continue
        dp, dr = chain.error(w, t)
        if dp <= _VERIFY_TOL and dr <= _VERIFY_TOL:
            sols.append(w)
    return np.array(sols, dtype=float).reshape(-1, 6)


def assert_same_choice(got, expected, seed, weights):
    """``got`` is the reference's choice to 1e-12 rad, or (a tie between branches) another branch of the same
    least cost."""
    if expected is None:
        assert got is None
        return
    assert got is not None
    cost_expected, q_expected = expected
    if np.max(np.abs(got - q_expected)) <= SAME_RAD:
        return
    cost_got = sum(weights[j] * (got[j] - seed[j]) ** 2 for j in (0, 4, 5, 2, 1, 3))
    assert cost_got == pytest.approx(cost_expected, rel=1e-12, abs=1e-24), (got, q_expected)


def solve(T, seed, lower, upper, weights):
    try:
        return ur_ik(UR3E_DH, T, seed, lower, upper, weights=weights)
    except PlanningError:
        return None


@settings(max_examples=1500, deadline=None)
@given(
    q=joints,
    noise=st.lists(st.floats(-0.4, 0.4), min_size=6, max_size=6).map(np.array),
    far_seed=st.one_of(st.none(), joints),
)
def test_ur_ik_is_the_plain_search_with_the_ur3e_limits(q, noise, far_seed):
    """A seed near the pose's own joints (the planner's case) or anywhere (another branch wins)."""
    lower, upper = np.full(6, -TWO_PI), np.full(6, TWO_PI)
    seed = np.clip(q + noise if far_seed is None else far_seed, lower, upper)
    T = dh_forward(UR3E_DH, q)
    ones = np.ones(6)
    assert_same_choice(solve(T, seed, lower, upper, None), plain_nearest(UR3E_DH, T, seed, lower, upper, ones), seed, ones)


@settings(max_examples=1000, deadline=None)
@given(
    q=joints,
    seed=joints,
    centre=st.lists(st.floats(-3.0, 3.0), min_size=6, max_size=6).map(np.array),
    width=st.lists(st.floats(0.3, 7.0), min_size=6, max_size=6).map(np.array),
    weights=st.lists(st.floats(0.01, 100.0), min_size=6, max_size=6).map(np.array),
)
def test_ur_ik_is_the_plain_search_with_tight_limits_and_weights(q, seed, centre, width, weights):
    """Limits that rule out branches and equivalents, and weights that change which branch is nearest."""
    lower, upper = centre - 0.5 * width, centre + 0.5 * width
    seed = np.clip(seed, lower, upper)
    T = dh_forward(UR3E_DH, q)
    got = solve(T, seed, lower, upper, weights)
    assert_same_choice(got, plain_nearest(UR3E_DH, T, seed, lower, upper, weights), seed, weights)


@settings(max_examples=1500, deadline=None)
@given(q=joints, q6=st.one_of(st.just(0.0), st.floats(-math.pi, math.pi)))
def test_ur_ik_all_is_the_previous_implementation(q, q6):
    T = dh_forward(UR3E_DH, q)
    got = ur_ik_all(UR3E_DH, T, q6_singular=q6)
    expected = previous_ur_ik_all(UR3E_DH, T, q6)
    assert got.shape == expected.shape
    assert np.array_equal(got, expected)  # bit for bit: the same floats, the same order


def shoulder_singular(q: np.ndarray, dh=UR3E_DH) -> np.ndarray:
    """``q`` with ``q2`` moved to put the wrist-2 centre at distance ``d4`` from the base axis (the shoulder
    singularity: ``a2 cos q2 + a3 cos q23 + d5 sin q234 = 0``, so the two shoulder pans meet)."""
    _, a2, a3, _, d5, _, _, _ = dh._ur
    q = q.copy()
    c3, s3, c34, s34 = math.cos(q[2]), math.sin(q[2]), math.cos(q[2] + q[3]), math.sin(q[2] + q[3])
    x, y = a2 + a3 * c3 + d5 * s34, -a3 * s3 + d5 * c34  # cos q2 x + sin q2 y = 0
    q[1] = math.atan2(-x, y)
    return q


@settings(max_examples=1500, deadline=None)
@given(
    q=joints,
    shoulder=st.sampled_from([None, 0.0, 1e-12, -1e-9, 1e-6]),
    noise=st.lists(st.floats(-0.4, 0.4), min_size=6, max_size=6).map(np.array),
    far_seed=st.one_of(st.none(), joints),
    defect=st.one_of(st.just(0.0), st.floats(-1e-12, 1e-12), st.floats(-1e-6, 1e-6)),
    tight=st.booleans(),
)
def test_a_certified_branch_reproduces_its_target(q, shoulder, noise, far_seed, defect, tight):
    """The certificate that lets ur_ik skip the FK check: an exact branch (nothing clipped, nudged or clamped) of a
    target whose rotation is one reproduces it within _CERTIFIED_ERROR, measured by Pinocchio, at every
    singularity (the special angles: wrist, elbow; the shoulder's by construction), for seeds near and far,
    limits wide and tight, and target rotations a little off orthonormal."""
    if shoulder is not None:
        q = shoulder_singular(q)
        q[1] += shoulder
    T = dh_forward(UR3E_DH, q)
    T[:3, :3] *= 1.0 + defect  # no longer a rotation when defect != 0
    lower, upper = (q - 0.5, q + 0.5) if tight else (np.full(6, -TWO_PI), np.full(6, TWO_PI))
    seed = np.clip(q + noise if far_seed is None else far_seed, lower, upper)
    t = T[:3].ravel().tolist()
    found = _nearest_search(UR3E_DH._ur, t, seed.tolist(), lower.tolist(), upper.tolist(), (1.0,) * 6)
    if found is None or not found[2] or not _certified(t):
        return
    dp, dr = _Chain(UR3E_DH).error(found[1], t)
    assert dp <= _CERTIFIED_ERROR and dr <= _CERTIFIED_ERROR, (dp, dr)


@settings(max_examples=800, deadline=None)
@given(q=joints, shoulder=st.sampled_from([None, 0.0, 1e-12, -1e-9]), q6=st.floats(-math.pi, math.pi))
def test_every_exact_branch_of_a_certified_target_reproduces_it(q, shoulder, q6):
    """The certificate ur_ik_all relies on: each branch _flagged_branches calls exact, of a _certified target,
    reproduces it within _CERTIFIED_ERROR (Pinocchio), at the special angles and the shoulder singularity."""
    if shoulder is not None:
        q = shoulder_singular(q)
        q[1] += shoulder
    t = dh_forward(UR3E_DH, q)[:3].ravel().tolist()
    if not _certified(t):
        return
    chain = _Chain(UR3E_DH)
    for b, exact in _flagged_branches(UR3E_DH._ur, t, q6):
        if exact:
            dp, dr = chain.error(b, t)
            assert dp <= _CERTIFIED_ERROR and dr <= _CERTIFIED_ERROR, (b, dp, dr)


def test_the_certificate_refuses_what_is_not_a_rotation_and_clamped_or_clipped_branches():
    q = np.array([0.3, -1.2, 1.4, -0.9, 1.1, 0.4])
    T = dh_forward(UR3E_DH, q)
    t = T[:3].ravel().tolist()
    wide = [-TWO_PI] * 6, [TWO_PI] * 6
    assert _certified(t)
    assert _nearest_search(UR3E_DH._ur, t, q.tolist(), *wide, (1.0,) * 6)[2]
    scaled = (np.diag([1.0 + 1e-9, 1.0, 1.0, 1.0]) @ T)[:3].ravel().tolist()
    reflected = (np.diag([1.0, -1.0, 1.0, 1.0]) @ T @ np.diag([1.0, -1.0, 1.0, 1.0]))
    reflected[:3, 1] *= -1.0  # y6 = -(z6 × x6): a left-handed frame
    assert not _certified(scaled) and not _certified(reflected[:3].ravel().tolist())
    # a joint on the limit the solution just overshoots: clamped, not exact
    lower = np.full(6, -TWO_PI)
    upper = np.full(6, TWO_PI)
    upper[2] = q[2] - 0.5e-10
    found = _nearest_search(UR3E_DH._ur, t, q.tolist(), lower.tolist(), upper.tolist(), (1.0,) * 6)
    assert found is not None and found[1][2] == upper[2] and not found[2]
    # the elbow stretched straight, a little beyond: cos q3 clipped
    straight = dh_forward(UR3E_DH, np.array([0.3, -1.2, 0.0, -0.9, 1.1, 0.4]))
    straight[:3, 3] *= 1.0 + 1e-10
    found = _nearest_search(UR3E_DH._ur, straight[:3].ravel().tolist(), q.tolist(), *wide, (1.0,) * 6)
    assert found is not None and not found[2]


def test_the_nearest_of_several_candidates_is_found_when_the_seed_is_between_branches():
    """A seed half-way between two branches of the same pose: both are candidates, the plain search decides."""
    q = np.array([0.3, -1.2, 1.4, -0.9, 1.1, 0.4])
    T = dh_forward(UR3E_DH, q)
    branches = ur_ik_all(UR3E_DH, T)
    assert len(branches) == 8
    lower, upper, ones = np.full(6, -TWO_PI), np.full(6, TWO_PI), np.ones(6)
    for a in branches:
        for b in branches:
            seed = 0.5 * (a + b)
            got = ur_ik(UR3E_DH, T, seed, lower, upper)
            assert_same_choice(got, plain_nearest(UR3E_DH, T, seed, lower, upper, ones), seed, ones)
