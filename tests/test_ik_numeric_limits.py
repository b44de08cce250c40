"""Numeric IK at the joint limits (robot/ik_numeric.py): the held joints of the damped least-squares step, and
the end of a descent that is stuck."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings, strategies as st

from robocritics import Robot
from robocritics.errors import PlanningError
from robocritics.robot import ik_numeric
from robocritics.robot.ik_numeric import STALL_ITERATIONS, numeric_ik

PANDA = Robot.panda()


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**31 - 1), st.sampled_from([3, 6]), st.sampled_from([1.0, -1.0]))
def test_the_held_step_pushes_no_joint_out_and_solves_the_linear_problem_with_the_rest(seed, rows, outward):
    rng = np.random.default_rng(seed)
    n = 7
    J = rng.normal(size=(rows, n))
    err = rng.normal(size=rows)
    lo, hi = -np.ones(n), np.ones(n)
    q = rng.uniform(-1.0, 1.0, n)
    at = rng.integers(0, 3, n)  # 0: inside, 1: at the lower limit, 2: at the upper
    q[at == 1], q[at == 2] = -1.0, 1.0
    lam = 1e-12
    dq = ik_numeric._held_step(J, err, lam, np.eye(rows), q, lo, hi, True, outward=outward)
    move = outward * dq
    # no joint at a limit is moved further out
    assert not np.any((q <= lo) & (move < 0.0)) and not np.any((q >= hi) & (move > 0.0))
    held = dq == 0.0
    free = ~held
    if free.sum() >= rows and np.linalg.svd(J[:, free], compute_uv=False).min() > 0.05:
        # enough joints left (not near singular: the damping's share is lam / sigma^2): the linearised
        # problem solved exactly with the held joints fixed
        np.testing.assert_allclose(J[:, free] @ dq[free], err, atol=1e-7)
    plain = J.T @ np.linalg.solve(J @ J.T + lam * np.eye(rows), err)
    pushed = ((q <= lo) & (outward * plain < 0.0)) | ((q >= hi) & (outward * plain > 0.0))
    if not pushed.any():  # nothing at a limit pushed out: the plain damped least-squares step, unchanged
        np.testing.assert_array_equal(dq, plain)
    else:  # only joints at a limit are held
        assert np.all((q[held] <= lo[held]) | (q[held] >= hi[held]))
    # without limits to clip to (a model whose configuration is not its angles): the plain step
    np.testing.assert_array_equal(ik_numeric._held_step(J, err, lam, np.eye(rows), q, lo, hi, False), plain)


def test_a_seed_at_a_limit_converges_from_the_seed():
    """Targets made from a Panda posture with one joint at a limit, seeded 0.3 rad (s.d.) off with that joint
    at the limit too: the first descent (no restarts) reaches every one of them (measured 100 of 100; clipping
    the plain step after the fact reached 62), and the solution is the target's pose inside the limits."""
    robot = PANDA
    lo, hi = robot.lower, robot.upper
    rng = np.random.default_rng(5)
    reached = 0
    for _ in range(100):
        made = rng.uniform(lo + 0.1, hi - 0.1)
        j = rng.integers(robot.n)
        made[j] = lo[j] if rng.random() < 0.5 else hi[j]
        target = robot.tcp_pose(made)
        seed = np.clip(made + rng.normal(0.0, 0.3, robot.n), lo, hi)
        seed[j] = made[j]
        try:
            q = numeric_ik(robot.model, robot.data, robot._tcp_frame_id, target, seed, lo, hi, restarts=0)
        except PlanningError:
            continue
        reached += 1
        assert np.all(q >= lo) and np.all(q <= hi)
        np.testing.assert_allclose(robot.tcp_pose(q), target, atol=1e-8)
    assert reached >= 95


class _CountingPin:
    """Pinocchio with its forward-kinematics calls counted (one per descent iteration in ``_dls``)."""

    def __init__(self):
        self.fk = 0

    def framesForwardKinematics(self, *args):
        self.fk += 1
        return pin.framesForwardKinematics(*args)

    def __getattr__(self, name):
        return getattr(pin, name)


def test_a_descent_that_makes_no_progress_ends_before_max_iter(monkeypatch):
    """A target 2 m away from a 0.85 m arm: each descent stops once its error has not fallen 1% in
    STALL_ITERATIONS iterations, not after all of max_iter, and the error still names the best residual."""
    robot = PANDA
    counting = _CountingPin()
    monkeypatch.setattr(ik_numeric, "pin", counting)
    with pytest.raises(PlanningError, match="did not converge.*best residual"):
        numeric_ik(robot.model, robot.data, robot._tcp_frame_id, np.array([2.0, 0.0, 0.3]), robot.home_q,
                   robot.lower, robot.upper, restarts=2, max_iter=1000)
    assert 3 * STALL_ITERATIONS <= counting.fk < 3 * 200  # three descents, none near its 1000 iterations
