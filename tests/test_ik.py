"""Inverse kinematics: closed-form UR IK (round trips, branch choice, limits,
singularities, unreachable targets) and the Pinocchio damped-least-squares IK."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from ik_reference import near_seed_postures, self_motion_descent

from robocritics.errors import PlanningError, RobotModelError
from robocritics.robot.ik import (
    DH,
    UR3E_DH,
    dh_forward,
    dh_urdf,
    ur_ik,
    ur_ik_all,
    ur_reach,
)
from robocritics.robot.ik_numeric import numeric_ik

TWO_PI = 2.0 * math.pi
LIMIT_SLACK_RAD = 1e-10  # ur_ik's documented clamp of a solution onto a limit it overshoots by rounding
UR_LOWER = np.full(6, -TWO_PI)
UR_UPPER = np.full(6, TWO_PI)

angle = st.floats(-TWO_PI, TWO_PI, allow_nan=False, allow_infinity=False)
joint_vector = st.lists(angle, min_size=6, max_size=6).map(np.array)


def wrapped_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Element-wise a - b wrapped to [-pi, pi)."""
    return (np.asarray(a) - np.asarray(b) + math.pi) % TWO_PI - math.pi


def pose_errors(T: np.ndarray, target: np.ndarray) -> tuple[float, float]:
    """(position error m, rotation angle rad) between two 4x4 poses."""
    dp = float(np.linalg.norm(T[:3, 3] - target[:3, 3]))
    dr = float(np.linalg.norm(pin.log3(T[:3, :3].T @ target[:3, :3])))
    return dp, dr


def near_singular(q: np.ndarray, dh: DH = UR3E_DH, eps: float = 1e-4) -> bool:
    """Wrist (sin q5 ≈ 0), elbow (sin q3 ≈ 0) or shoulder (wrist-2 centre at
    distance ≈ d4 from the base axis) singularity: branches merge or q6 is free.

    Near one, the pose is still reproduced to ~1e-15 m, but the joint angles
    are only determined to ~1e-11 / eps rad (acos and atan2 lose digits), so
    comparisons of angles are skipped within ``eps``."""
    T = dh_forward(dh, q)
    p5 = T[:3, 3] - dh.d6 * T[:3, 2]
    r = math.hypot(p5[0], p5[1])
    shoulder = r <= dh.d4 or math.sqrt(max(0.0, 1.0 - (dh.d4 / r) ** 2)) < eps
    return abs(math.sin(q[4])) < eps or abs(math.sin(q[2])) < eps or shoulder


# UR3e e-series DH as Universal Robots publish it, typed in again here on purpose:
# the textbook product below is an independent check of the library's FK.
_D = (0.15185, 0.0, 0.0, 0.13105, 0.08535, 0.0921)
_A = (0.0, -0.24355, -0.2132, 0.0, 0.0, 0.0)
_ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)


def textbook_flange(q) -> np.ndarray:
    """T_06 = prod_i Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i), one 4x4 matrix per joint."""
    T = np.eye(4)
    for qi, d, a, al in zip(q, _D, _A, _ALPHA):
        ct, st_, ca, sa = math.cos(qi), math.sin(qi), math.cos(al), math.sin(al)
        T = T @ np.array([[ct, -st_ * ca, st_ * sa, a * ct], [st_, ct * ca, -ct * sa, a * st_], [0, sa, ca, d], [0, 0, 0, 1]])
    return T


def nearest_reference(
    dh: DH, T: np.ndarray, seed: np.ndarray, lower: np.ndarray, upper: np.ndarray
) -> float | None:
    """Brute force: smallest squared joint distance to ``seed`` over every branch
    and every 2π shift (k = -3..3 per joint) within the limits; None if none.

    "Within" up to the 1e-10 rad that ur_ik documents it clamps onto a limit (a
    branch computed as 1 + 4e-12 rad against a limit of 1 rad is on the limit)."""
    best = None
    for b in ur_ik_all(dh, T, q6_singular=float(seed[5])):
        cost = 0.0
        for x, s, lo, hi in zip(b, seed, lower, upper):
            opts = [x + k * TWO_PI for k in range(-3, 4)]
            opts = [min(max(v, lo), hi) for v in opts if lo - LIMIT_SLACK_RAD <= v <= hi + LIMIT_SLACK_RAD]
            if not opts:
                break
            cost += min((v - s) ** 2 for v in opts)
        else:
            best = cost if best is None else min(best, cost)
    return best


# --------------------------------------------------------------------------- #
# DH parameters and forward kinematics
# --------------------------------------------------------------------------- #


def test_ur3e_dh_values():
    assert UR3E_DH.d == (0.15185, 0.0, 0.0, 0.13105, 0.08535, 0.0921)
    assert UR3E_DH.a == (0.0, -0.24355, -0.2132, 0.0, 0.0, 0.0)
    assert UR3E_DH.alpha == pytest.approx((math.pi / 2, 0, 0, math.pi / 2, -math.pi / 2, 0))
    assert (UR3E_DH.d1, UR3E_DH.a2, UR3E_DH.a3) == (0.15185, -0.24355, -0.2132)
    assert (UR3E_DH.d4, UR3E_DH.d5, UR3E_DH.d6) == (0.13105, 0.08535, 0.0921)
    assert UR3E_DH.is_ur_like


def test_dh_validation():
    with pytest.raises(RobotModelError, match="6 values"):
        DH(d=(0.1,) * 5, a=(0.0,) * 6, alpha=(0.0,) * 6)
    with pytest.raises(RobotModelError, match="finite"):
        DH(d=(0.1,) * 6, a=(0.0, math.nan, 0, 0, 0, 0), alpha=(0.0,) * 6)
    planar = DH(d=(0.1,) * 6, a=(0.2,) * 6, alpha=(0.0,) * 6, name="planar")
    assert not planar.is_ur_like
    with pytest.raises(RobotModelError, match="not UR-like"):
        ur_ik_all(planar, np.eye(4))


def test_dh_forward_zero_pose():
    # At q = 0 a UR arm lies stretched along -x: flange at (a2 + a3, -(d4 + d6), d1 - d5).
    T = dh_forward(UR3E_DH, np.zeros(6))
    assert T[:3, 3] == pytest.approx([-0.45675, -(0.13105 + 0.0921), 0.15185 - 0.08535], abs=1e-12)
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.allclose(T[3], [0, 0, 0, 1])


def test_dh_forward_vectorised_matches_single():
    rng = np.random.default_rng(1)
    Q = rng.uniform(-TWO_PI, TWO_PI, (50, 6))
    batch = dh_forward(UR3E_DH, Q)
    assert batch.shape == (50, 4, 4)
    for q, T in zip(Q, batch):
        assert np.allclose(dh_forward(UR3E_DH, q), T, atol=1e-14)
    assert dh_forward(UR3E_DH, Q.reshape(5, 10, 6)).shape == (5, 10, 4, 4)
    with pytest.raises(RobotModelError):
        dh_forward(UR3E_DH, np.zeros(5))


def test_dh_forward_matches_the_textbook_dh_product():
    rng = np.random.default_rng(2)
    Q = rng.uniform(-TWO_PI, TWO_PI, (200, 6))
    batch = dh_forward(UR3E_DH, Q)
    for q, T in zip(Q, batch):
        assert np.allclose(T, textbook_flange(q), atol=1e-13)


def test_reach():
    reach = ur_reach(UR3E_DH)
    # upper arm + forearm 0.457 m plus the wrist offsets; a little over the 0.5 m data-sheet radius
    assert 0.59 < reach < 0.61
    rng = np.random.default_rng(3)
    T = dh_forward(UR3E_DH, rng.uniform(-math.pi, math.pi, (20000, 6)))
    dist = np.linalg.norm(T[:, :3, 3] - [0, 0, UR3E_DH.d1], axis=1)
    assert dist.max() <= reach + 1e-12
    assert dist.max() > reach - 0.02


# --------------------------------------------------------------------------- #
# Closed-form IK: round trips
# --------------------------------------------------------------------------- #


@settings(max_examples=2000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(q=joint_vector)
def test_every_branch_reproduces_the_pose_and_the_original_is_found(q):
    T = dh_forward(UR3E_DH, q)
    sols = ur_ik_all(UR3E_DH, T)
    assert 1 <= len(sols) <= 8
    assert np.all(sols > -math.pi) and np.all(sols <= math.pi)
    F = dh_forward(UR3E_DH, sols)
    for Fi in F:
        dp, dr = pose_errors(Fi, T)
        assert dp < 1e-6 and dr < 1e-6
    # distinct configurations
    for a, b in itertools.combinations(sols, 2):
        assert np.abs(wrapped_diff(a, b)).max() > 1e-9
    if not near_singular(q):
        assert np.abs(wrapped_diff(sols, q)).max(axis=1).min() < 1e-6


@settings(max_examples=600, deadline=None)
@given(q=joint_vector, noise=st.lists(st.floats(-0.3, 0.3), min_size=6, max_size=6))
def test_ur_ik_returns_the_nearest_solution_within_limits(q, noise):
    seed = np.clip(q + np.array(noise), UR_LOWER, UR_UPPER)
    T = dh_forward(UR3E_DH, q)
    sol = ur_ik(UR3E_DH, T, seed, UR_LOWER, UR_UPPER)
    assert sol.shape == (6,)
    assert np.all(sol >= UR_LOWER - 1e-12) and np.all(sol <= UR_UPPER + 1e-12)
    dp, dr = pose_errors(dh_forward(UR3E_DH, sol), T)
    assert dp < 1e-9 and dr < 1e-9
    ref = nearest_reference(UR3E_DH, T, seed, UR_LOWER, UR_UPPER)
    assert ref is not None
    assert np.sum((sol - seed) ** 2) <= ref + 1e-9
    if not near_singular(q):
        # the generating configuration is a candidate, so the answer is no farther
        assert np.sum((sol - seed) ** 2) <= np.sum((q - seed) ** 2) + 1e-9


@settings(max_examples=300, deadline=None)
@given(q=joint_vector)
def test_ur_ik_with_the_exact_seed_returns_it(q):
    assume(not near_singular(q))
    sol = ur_ik(UR3E_DH, dh_forward(UR3E_DH, q), q, UR_LOWER, UR_UPPER)
    assert np.allclose(sol, q, atol=1e-7)


def test_ur_ik_uses_two_pi_shifted_equivalents():
    q = np.array([-0.1, -1.2, 1.0, 0.9, 1.1, -0.4])
    T = dh_forward(UR3E_DH, q)
    seed = q + np.array([TWO_PI, 0, 0, -TWO_PI, 0, TWO_PI]) + 0.01
    sol = ur_ik(UR3E_DH, T, seed, UR_LOWER, UR_UPPER)
    assert np.allclose(sol, q + [TWO_PI, 0, 0, -TWO_PI, 0, TWO_PI], atol=1e-9)


def test_weights_change_the_choice():
    q = np.array([0.3, -1.0, 1.4, -0.6, 0.9, 0.2])
    T = dh_forward(UR3E_DH, q)
    sols = ur_ik_all(UR3E_DH, T)
    assert len(sols) == 8
    seed = np.zeros(6)
    plain = ur_ik(UR3E_DH, T, seed, UR_LOWER, UR_UPPER)
    # make the base joint overwhelmingly expensive: the result must keep q1 closest to 0
    heavy = ur_ik(UR3E_DH, T, seed, UR_LOWER, UR_UPPER, weights=[1e6, 1, 1, 1, 1, 1])
    q1_opts = np.unique(np.round(np.abs(wrapped_diff(sols[:, 0], 0.0)), 9))
    assert abs(heavy[0]) == pytest.approx(q1_opts.min(), abs=1e-9)
    assert np.sum((plain - seed) ** 2) <= np.sum((heavy - seed) ** 2) + 1e-12


def test_pinocchio_se3_target_accepted():
    q = np.array([0.2, -1.3, 1.2, -0.4, 0.7, -0.3])
    M = pin.SE3(dh_forward(UR3E_DH, q))
    assert np.allclose(ur_ik(UR3E_DH, M, q, UR_LOWER, UR_UPPER), q, atol=1e-9)
    assert len(ur_ik_all(UR3E_DH, M)) >= 1


# --------------------------------------------------------------------------- #
# Singularities
# --------------------------------------------------------------------------- #


@pytest.mark.parametrize("q5", [0.0, math.pi, -math.pi, 1e-13, math.pi - 1e-13])
@pytest.mark.parametrize("seed6", [0.0, 0.7, -2.5])
def test_wrist_singularity_keeps_the_seeds_q6(q5, seed6):
    q = np.array([0.4, -1.1, 1.3, -0.7, q5, 0.9])
    T = dh_forward(UR3E_DH, q)
    seed = q.copy()
    seed[5] = seed6
    sol = ur_ik(UR3E_DH, T, seed, UR_LOWER, UR_UPPER)
    dp, dr = pose_errors(dh_forward(UR3E_DH, sol), T)
    assert dp < 1e-9 and dr < 1e-9
    assert sol[5] == pytest.approx(seed6, abs=1e-9)
    for s in ur_ik_all(UR3E_DH, T, q6_singular=seed6):
        dp, dr = pose_errors(dh_forward(UR3E_DH, s), T)
        assert dp < 1e-9 and dr < 1e-9


def test_fully_degenerate_upright_pose():
    # shoulder singular (wrist above the base at distance d4), elbow straight, wrist singular
    for q6 in (0.0, 0.3, -1.0):
        q = np.array([0.2, -math.pi / 2, 0.0, -math.pi / 2, 0.0, q6])
        T = dh_forward(UR3E_DH, q)
        for seed in (q, np.zeros(6), q + 0.05):
            sol = ur_ik(UR3E_DH, T, seed, UR_LOWER, UR_UPPER)
            dp, dr = pose_errors(dh_forward(UR3E_DH, sol), T)
            assert dp < 1e-9 and dr < 1e-9


@pytest.mark.parametrize("q3", [0.0, math.pi])
def test_elbow_singularity(q3):
    q = np.array([-0.5, -1.0, q3, 0.4, 1.2, 0.3])
    T = dh_forward(UR3E_DH, q)
    sols = ur_ik_all(UR3E_DH, T)
    assert np.abs(wrapped_diff(sols, q)).max(axis=1).min() < 1e-6
    sol = ur_ik(UR3E_DH, T, q, UR_LOWER, UR_UPPER)
    assert np.allclose(sol, q, atol=1e-6)


# --------------------------------------------------------------------------- #
# Unreachable targets and joint limits
# --------------------------------------------------------------------------- #


def _pose(p, R=None):
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    T[:3, 3] = p
    return T


def test_one_metre_away_is_out_of_reach():
    with pytest.raises(PlanningError) as exc:
        ur_ik(UR3E_DH, _pose([1.0, 0.0, 0.3]), np.zeros(6), UR_LOWER, UR_UPPER)
    msg = str(exc.value)
    assert "(1.000, 0.000, 0.300) m" in msg
    assert "out of reach" in msg
    assert "1.011 m from the shoulder" in msg
    assert f"reaches {ur_reach(UR3E_DH):.3f} m" in msg
    assert exc.value.line == 0
    assert len(ur_ik_all(UR3E_DH, _pose([1.0, 0.0, 0.3]))) == 0


@pytest.mark.parametrize("p", [[0.0, 0.0, 0.3], [0.0, 0.0, 0.0], [0.02, -0.01, 0.1]])
def test_inside_the_base_axis_cylinder(p):
    with pytest.raises(PlanningError, match="too close to the base axis") as exc:
        ur_ik(UR3E_DH, _pose(p), np.zeros(6), UR_LOWER, UR_UPPER)
    assert f"({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m" in str(exc.value)


def test_reachable_distance_but_impossible_orientation():
    # 0.55 m from the shoulder is within reach, but not with the flange pointing back at the base
    p = np.array([0.55, 0.0, UR3E_DH.d1])
    R = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # flange z = -x
    with pytest.raises(PlanningError, match="out of reach in this orientation"):
        ur_ik(UR3E_DH, _pose(p, R), np.zeros(6), UR_LOWER, UR_UPPER)


def test_bad_target_poses():
    with pytest.raises(PlanningError, match="not a rotation"):
        ur_ik(UR3E_DH, _pose([0.3, 0.1, 0.2], 2.0 * np.eye(3)), np.zeros(6), UR_LOWER, UR_UPPER)
    with pytest.raises(PlanningError, match="NaN"):
        ur_ik(UR3E_DH, _pose([math.nan, 0.1, 0.2]), np.zeros(6), UR_LOWER, UR_UPPER)
    with pytest.raises(PlanningError, match="4x4"):
        ur_ik(UR3E_DH, np.eye(3), np.zeros(6), UR_LOWER, UR_UPPER)


def test_no_solution_within_the_joint_limits():
    q = np.array([0.3, -1.0, 1.4, -0.6, 0.9, 0.2])
    T = dh_forward(UR3E_DH, q)
    lower = np.full(6, -0.1)
    upper = np.full(6, 0.1)
    with pytest.raises(PlanningError) as exc:
        ur_ik(UR3E_DH, T, np.zeros(6), lower, upper)
    msg = str(exc.value)
    assert "no solution within the joint limits (branches found: 8" in msg
    assert "joint" in msg and "rad" in msg


@settings(max_examples=300, deadline=None)
@given(
    q=st.lists(st.floats(-math.pi, math.pi), min_size=6, max_size=6).map(np.array),
    width=st.lists(st.floats(0.05, 4.0), min_size=6, max_size=6).map(np.array),
    centre=st.lists(st.floats(-math.pi, math.pi), min_size=6, max_size=6).map(np.array),
)
def test_joint_limits_are_respected(q, width, centre):
    lower, upper = centre - width, centre + width
    T = dh_forward(UR3E_DH, q)
    seed = np.clip(q, lower, upper)
    ref = nearest_reference(UR3E_DH, T, seed, lower, upper)
    try:
        sol = ur_ik(UR3E_DH, T, seed, lower, upper)
    except PlanningError as exc:
        assert "no solution within the joint limits" in str(exc)
        assert ref is None
        return
    assert np.all(sol >= lower - 1e-12) and np.all(sol <= upper + 1e-12)
    dp, dr = pose_errors(dh_forward(UR3E_DH, sol), T)
    assert dp < 1e-9 and dr < 1e-9
    if ref is None:
        # Only at a singularity: two branches closer than 1e-7 rad are one configuration to
        # ur_ik_all, which keeps one of them, and the kept one lies a hair outside a limit
        # (e.g. the straight elbow at q3 = ±3e-8 rad, wrist 1 at ∓1.6e-8 against a limit of 0).
        # ur_ik searches every branch and returned the twin inside the limits.
        twins = ur_ik_all(UR3E_DH, T, q6_singular=float(seed[5]))
        assert np.abs(wrapped_diff(twins, sol)).max(axis=1).min() < 1e-7
    else:
        assert np.sum((sol - seed) ** 2) <= ref + 1e-9


def test_stretched_arm_outside_the_joint_limits_is_a_limits_error():
    # Found by Hypothesis: the arm fully stretched (elbow straight, wrist 2 at 2.8e-7 rad).
    # Its exact solutions need wrist 1 near 0 (or 2 pi), outside [2, 4] rad; the only branch
    # inside the limits is the wrist-down one nudged to reach, which misses the orientation
    # by 1e-7 rad, so it is not a solution, and the error must say the limits rule it out.
    q = np.array([0.0, 0.0, 0.0, 0.0, 2.78e-07, 0.0])
    lower = np.array([-1.0, -1.0, -1.0, 2.0, -1.0, -3.0])
    upper = np.array([1.0, 1.0, 1.0, 4.0, 1.0, 3.0])
    T = dh_forward(UR3E_DH, q)
    seed = np.clip(q, lower, upper)
    assert nearest_reference(UR3E_DH, T, seed, lower, upper) is None
    with pytest.raises(PlanningError) as exc:
        ur_ik(UR3E_DH, T, seed, lower, upper)
    assert "no solution within the joint limits" in str(exc.value)
    assert "joint 4 (wrist 1) [2.000, 4.000] rad rules out" in str(exc.value)
    # with wrist 1 free the same pose is solved exactly
    lower[3], upper[3] = -1.0, 1.0
    sol = ur_ik(UR3E_DH, T, np.clip(q, lower, upper), lower, upper)
    dp, dr = pose_errors(dh_forward(UR3E_DH, sol), T)
    assert dp < 1e-9 and dr < 1e-9


def test_a_branch_a_rounding_error_past_a_limit_is_on_it():
    # Found by Hypothesis: q6 = 1 rad exactly on its upper limit comes out of the closed
    # form as 1 + 3.6e-12 rad; it is clamped onto the limit, not ruled out.
    q = np.array([0.0, 0.0, 0.0, 0.0, 6.103515625e-05, 1.0])
    lower, upper = -np.ones(6), np.ones(6)
    T = dh_forward(UR3E_DH, q)
    sol = ur_ik(UR3E_DH, T, q, lower, upper)
    assert np.all(sol >= lower) and np.all(sol <= upper)
    dp, dr = pose_errors(dh_forward(UR3E_DH, sol), T)
    assert dp < 1e-9 and dr < 1e-9
    assert np.sum((sol - q) ** 2) <= nearest_reference(UR3E_DH, T, q, lower, upper) + 1e-9


def test_a_nearest_branch_that_misses_the_pose_is_passed_over():
    # Same stretched pose, seeded at its nudged wrist-down branch (q6 = 2.77 rad), which is
    # the nearest branch but misses the orientation by 1e-7 rad: the exact solution nearest
    # to the seed comes back instead.
    q = np.array([0.0, 0.0, 0.0, 0.0, 2.78e-07, 0.0])
    T = dh_forward(UR3E_DH, q)
    seed = np.array([0.0, 0.3694664, 0.0, -math.pi, -2.8e-7, 2.77212625])
    sol = ur_ik(UR3E_DH, T, seed, UR_LOWER, UR_UPPER)
    dp, dr = pose_errors(dh_forward(UR3E_DH, sol), T)
    assert dp < 1e-9 and dr < 1e-9
    assert np.sum((sol - seed) ** 2) <= nearest_reference(UR3E_DH, T, seed, UR_LOWER, UR_UPPER) + 1e-9


def test_ur_ik_argument_shapes():
    with pytest.raises(PlanningError, match="6 values"):
        ur_ik(UR3E_DH, np.eye(4), np.zeros(5), UR_LOWER, UR_UPPER)


# --------------------------------------------------------------------------- #
# Numeric IK (Pinocchio DLS) on a non-UR arm
# --------------------------------------------------------------------------- #

_ARM_URDF = """<?xml version="1.0"?>
<robot name="test_arm">
  <link name="base"/>
  <link name="l1"/><link name="l2"/><link name="l3"/><link name="l4"/><link name="l5"/><link name="l6"/>
  <link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.2" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2.9" upper="2.9" effort="10" velocity="2"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0.05 0.1" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2.0" upper="2.0" effort="10" velocity="2"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.3 0 0.02" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2.5" upper="2.5" effort="10" velocity="2"/></joint>
  <joint name="j4" type="revolute"><parent link="l3"/><child link="l4"/>
    <origin xyz="0.25 0 0" rpy="0 0 0"/><axis xyz="1 0 0"/>
    <limit lower="-3.0" upper="3.0" effort="10" velocity="2"/></joint>
  <joint name="j5" type="revolute"><parent link="l4"/><child link="l5"/>
    <origin xyz="0.05 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2.0" upper="2.0" effort="10" velocity="2"/></joint>
  <joint name="j6" type="revolute"><parent link="l5"/><child link="l6"/>
    <origin xyz="0.03 0 0" rpy="0 0 0"/><axis xyz="1 0 0"/>
    <limit lower="-3.0" upper="3.0" effort="10" velocity="2"/></joint>
  <joint name="tool" type="fixed"><parent link="l6"/><child link="tip"/>
    <origin xyz="0.08 0.01 0" rpy="0 0.3 0"/></joint>
</robot>
"""


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    path = tmp_path_factory.mktemp("urdf") / "test_arm.urdf"
    path.write_text(_ARM_URDF)
    model = pin.buildModelFromUrdf(str(path))
    return model, model.createData(), model.getFrameId("tip", pin.FrameType.BODY)


def _fk(model, data, fid, q) -> pin.SE3:
    pin.framesForwardKinematics(model, data, q)
    return data.oMf[fid].copy()


def test_numeric_ik_round_trips_full_pose(arm):
    model, data, fid = arm
    rng = np.random.default_rng(10)
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    for i in range(25):
        q = rng.uniform(lo * 0.9, hi * 0.9)
        target = _fk(model, data, fid, q)
        seed = np.clip(q + rng.normal(0.0, 0.4, 6), lo, hi) if i % 2 else np.zeros(6)
        sol = numeric_ik(model, data, fid, target, seed)
        assert np.all(sol >= lo) and np.all(sol <= hi)
        M = _fk(model, data, fid, sol)
        assert np.linalg.norm(M.translation - target.translation) < 1e-6
        assert np.linalg.norm(pin.log3(M.rotation.T @ target.rotation)) < 1e-6


def test_numeric_ik_accepts_a_matrix_and_a_frame_name(arm):
    model, data, fid = arm
    q = np.array([0.3, -0.5, 1.0, 0.2, -0.7, 0.4])
    T = _fk(model, data, fid, q).homogeneous
    sol = numeric_ik(model, data, "tip", T, q + 0.2)
    assert np.allclose(_fk(model, data, fid, sol).homogeneous, T, atol=1e-8)
    with pytest.raises(RobotModelError):
        numeric_ik(model, data, 10_000, T, q)
    with pytest.raises(RobotModelError, match="no link 'j3'"):
        numeric_ik(model, data, "j3", T, q)  # a joint, not a link


def test_numeric_ik_finds_the_link_when_a_joint_has_its_name(tmp_path):
    # the joint that turns link l2 is called "l3", the name of the next link
    urdf = _ARM_URDF.replace('joint name="j2"', 'joint name="l3"')
    model = pin.buildModelFromXML(urdf)
    data = model.createData()
    link = model.getFrameId("l3", pin.FrameType.BODY)
    assert model.frames[link].type == pin.FrameType.BODY
    q = np.array([0.3, -0.5, 1.0, 0.2, -0.7, 0.4])
    target = _fk(model, data, link, q).homogeneous
    sol = numeric_ik(model, data, "l3", target, q + 0.1)
    assert np.allclose(_fk(model, data, link, sol).homogeneous, target, atol=1e-8)


def test_numeric_ik_position_only(arm):
    model, data, fid = arm
    q = np.array([-0.8, 0.4, 0.9, 1.0, 0.5, -1.0])
    p = _fk(model, data, fid, q).translation.copy()
    for target in (p, (p, None)):
        sol = numeric_ik(model, data, fid, target, np.zeros(6))
        assert np.linalg.norm(_fk(model, data, fid, sol).translation - p) < 1e-8


def test_numeric_ik_respects_tighter_limits(arm):
    model, data, fid = arm
    q = np.array([0.2, 0.3, 0.4, 0.1, 0.2, 0.3])
    target = _fk(model, data, fid, q)
    lo, hi = q - 0.25, q + 0.25
    sol = numeric_ik(model, data, fid, target, np.clip(np.zeros(6), lo, hi), lo, hi)
    assert np.all(sol >= lo) and np.all(sol <= hi)
    assert np.linalg.norm(_fk(model, data, fid, sol).translation - target.translation) < 1e-6


def test_numeric_ik_unreachable_reports_the_residual(arm):
    model, data, fid = arm
    with pytest.raises(PlanningError) as exc:
        numeric_ik(model, data, fid, np.array([2.0, 0.0, 0.3]), np.zeros(6), restarts=2, max_iter=60)
    msg = str(exc.value)
    assert "did not converge" in msg and "(2.000, 0.000, 0.300) m" in msg
    assert " m, " in msg and " rad" in msg


def test_numeric_ik_agrees_with_the_closed_form_on_a_ur3e_model():
    model = pin.buildModelFromXML(dh_urdf(UR3E_DH))
    data = model.createData()
    fid = model.getFrameId("tool0", pin.FrameType.BODY)
    rng = np.random.default_rng(11)
    for _ in range(10):
        q = rng.uniform(-math.pi, math.pi, 6)
        T = dh_forward(UR3E_DH, q)
        sol = numeric_ik(model, data, fid, T, q + rng.normal(0, 0.2, 6))
        dp, dr = pose_errors(dh_forward(UR3E_DH, sol), T)
        assert dp < 1e-9 and dr < 1e-9
        # the numeric answer is one of the closed-form branches
        assert np.abs(wrapped_diff(ur_ik_all(UR3E_DH, T, q6_singular=sol[5]), sol)).max(axis=1).min() < 1e-6


def test_seven_joint_ik_returns_a_solution_near_its_seed_deterministically():
    """The Panda's numeric IK slides along the self-motion towards the seed and looks near the seed before
    anywhere else: targets made from a posture 0.3 rad (per joint, s.d.) off the seed (both 0.05 rad inside the
    limits) are solved within 1.5 rad of it on every joint, nearer the seed than the posture that made the
    target in at least 97 of 100 cases (plain damped least squares from the seed: 89), and the same call gives
    the same answer."""
    from robocritics import Robot

    panda = Robot.panda()
    rng = np.random.default_rng(11)
    nearer = 0
    inner_lo, inner_hi = panda.lower + 0.05, panda.upper - 0.05
    for _ in range(100):
        seed = np.clip(panda.home_q + rng.normal(0, 0.5, panda.n), inner_lo, inner_hi)
        made = np.clip(seed + rng.normal(0, 0.3, panda.n), inner_lo, inner_hi)
        target = panda.tcp_pose(made)
        q = panda.ik(target[:3, 3], target[:3, :3], seed=seed)
        np.testing.assert_allclose(panda.tcp_pose(q), target, atol=1e-8)
        assert np.abs(q - seed).max() < 1.5
        nearer += np.linalg.norm(q - seed) <= np.linalg.norm(made - seed) + 1e-9
        np.testing.assert_array_equal(q, panda.ik(target[:3, 3], target[:3, :3], seed=seed))
    assert nearer >= 97


def test_seven_joint_ik_lands_where_the_self_motion_descent_does_or_nearer():
    """A redundant arm's numeric IK takes the Newton (KKT) answer for ``min |q - seed|`` on the pose from the
    damped-least-squares solution; the reference is the slow descent along the null space it replaced
    (``_towards_seed``: up to 30 re-converged steps). On 40 Panda targets the answer holds the pose, is no
    farther from the seed than the descent's end (to 1e-6 rad), and is stationary: with no joint at a limit,
    ``q - seed`` has no component along the self-motion (the Jacobian's null space)."""
    from robocritics import Robot

    panda = Robot.panda()
    model, data, fid = panda.model, panda.data, panda._tcp_frame_id
    stationary = 0
    for seed, made in near_seed_postures(panda, np.random.default_rng(5), 40, 0.5, 0.3):
        target = panda.tcp_pose(made)
        q = panda.ik(target[:3, 3], target[:3, :3], seed=seed)
        np.testing.assert_allclose(panda.tcp_pose(q), target, atol=1e-8)
        descended = self_motion_descent(panda, target, seed, made)
        assert np.linalg.norm(q - seed) <= np.linalg.norm(descended - seed) + 1e-6
        if np.all((q > panda.lower + 1e-6) & (q < panda.upper - 1e-6)):
            J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
            null = np.eye(panda.n) - np.linalg.pinv(J) @ J
            assert np.linalg.norm(null @ (q - seed)) < 1e-6
            stationary += 1
    assert stationary >= 30


def test_pointing_ik_answers_near_the_seed_are_stationary_for_the_distance_to_it():
    """Pointing IK (position and finger axis, the turn about the axis free) tries Newton on ``min |q - seed|``
    first: on 30 Panda targets made 0.2 rad (s.d. per joint) off the seed, the answer meets the five constraints
    and, with no joint at a limit, ``q - seed`` has no component along the motions that keep them (the null
    space of the rows ``[J_v; (z x u)ᵀ J_w; (z x v)ᵀ J_w]``): no nearer solution is one small step away. A
    damped descent alone (the path before Newton first) is stationary only by chance."""
    from robocritics import Robot
    from robocritics.robot.ik_numeric import pointing_ik

    panda = Robot.panda()
    model, data, fid = panda.model, panda.data, panda._tcp_frame_id
    stationary = 0
    for seed, made in near_seed_postures(panda, np.random.default_rng(8), 30, 0.4, 0.2):
        pose = panda.tcp_pose(made)
        axis = pose[:3, 2]
        q = pointing_ik(model, data, fid, pose[:3, 3], axis, seed, panda.lower, panda.upper)
        got = panda.tcp_pose(q)
        assert np.linalg.norm(got[:3, 3] - pose[:3, 3]) < 1e-8 and np.linalg.norm(np.cross(got[:3, 2], axis)) < 1e-8
        assert got[:3, 2] @ axis > 0
        if np.all((q > panda.lower + 1e-6) & (q < panda.upper - 1e-6)):
            J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
            u = np.cross(axis, np.eye(3)[int(np.argmin(np.abs(axis)))])
            u /= np.linalg.norm(u)
            v = np.cross(axis, u)
            z = got[:3, 2]
            A = np.vstack([J[:3], np.cross(z, u) @ J[3:], np.cross(z, v) @ J[3:]])
            null = np.eye(panda.n) - np.linalg.pinv(A) @ A
            stationary += np.linalg.norm(null @ (q - seed)) < 1e-6
    # where Newton does not settle (1 of these 30), the damped descent answers: a solution, not the nearest
    assert stationary >= 27
