"""Robot.ik_line (one call for a straight line's grid) against the point-by-point Robot.ik walk it replaces."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from robocritics import Robot, Scene, simulate
from robocritics.errors import PlanningError

ROBOT = Robot.ur3e()
PROGRAMS = Path(__file__).resolve().parents[1] / "examples" / "programs"


def sequential(robot: Robot, points: np.ndarray, seed: np.ndarray, yaw: float):
    """The reference: Robot.ik at each point in turn, seeded by the previous solution."""
    rows = []
    for p in points:
        try:
            seed = robot.ik(p, seed=seed, yaw_rad=yaw)
        except PlanningError as exc:
            return np.array(rows).reshape(-1, robot.n), exc
        rows.append(seed)
    return np.array(rows).reshape(-1, robot.n), None


def assert_same(robot, points, seed, yaw):
    q, err = robot.ik_line(points, seed=seed, yaw_rad=yaw)
    q_ref, err_ref = sequential(robot, points, seed, yaw)
    assert q.shape == q_ref.shape
    if len(q):
        assert np.max(np.abs(q - q_ref)) <= 1e-12
    assert (err is None) == (err_ref is None)
    if err is not None:
        assert str(err) == str(err_ref)
    return q, err


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    start=st.tuples(*(st.floats(-0.45, 0.45),) * 2, st.floats(-0.1, 0.5)),
    step=st.tuples(*(st.floats(-0.4, 0.4),) * 3),
    yaw=st.floats(-3.0, 3.0),
    n=st.integers(2, 120),
)
def test_ik_line_equals_the_point_by_point_walk(start, step, yaw, n):
    points = np.asarray(start) + np.linspace(0.0, 1.0, n)[:, None] * np.asarray(step)
    assert_same(ROBOT, points, ROBOT.home_q, yaw)


def test_ik_line_stops_at_the_first_unreachable_point_with_ik_s_error():
    # from a reachable point straight out beyond the arm's reach
    points = np.array([0.3, 0.1, 0.2]) + np.linspace(0.0, 1.0, 80)[:, None] * np.array([0.8, 0.0, 0.0])
    q, err = assert_same(ROBOT, points, ROBOT.home_q, 0.0)
    assert 0 < len(q) < len(points)
    assert isinstance(err, PlanningError) and "cannot put the TCP at" in err.reason


def test_ik_line_non_finite_point_is_a_typed_error():
    points = np.array([[0.3, 0.1, 0.2], [0.3, 0.1, np.nan]])
    q, err = ROBOT.ik_line(points)
    assert len(q) == 1 and isinstance(err, PlanningError) and "not a finite position" in err.reason


def test_bundled_programs_lines_equal_the_point_by_point_walk(monkeypatch):
    calls = []
    real = Robot.ik_line

    def checked(self, positions, seed=None, *, yaw_rad=0.0, tilt_rad=0.0):
        assert tilt_rad == 0.0  # the bundled arm approaches fingers down
        q, err = real(self, positions, seed=seed, yaw_rad=yaw_rad, tilt_rad=tilt_rad)
        q_ref, err_ref = sequential(self, np.asarray(positions), self.home_q if seed is None else seed, yaw_rad)
        calls.append((len(q), float(np.max(np.abs(q - q_ref), initial=0.0)), str(err) == str(err_ref)))
        return q, err

    monkeypatch.setattr(Robot, "ik_line", checked)
    for path in sorted(PROGRAMS.glob("*.py")):
        simulate(path.read_text(), Scene.builtin(path.stem.split("_")[0]), ROBOT)
    assert len(calls) >= 6
    assert all(same_err and diff <= 1e-12 for _, diff, same_err in calls)
    assert sum(n for n, _, _ in calls) > 500


@pytest.mark.parametrize("shape", [(4, 4), (2, 3, 4)])
def test_ur_ik_line_rejects_bad_pose_shapes(shape):
    from robocritics.robot.ik import ur_ik_line

    with pytest.raises(PlanningError, match="shape"):
        ur_ik_line(ROBOT.dh, np.zeros(shape), ROBOT.home_q, ROBOT.lower, ROBOT.upper)


@settings(max_examples=40, deadline=None)
@given(q=st.lists(st.tuples(*(st.floats(-6.2, 6.2),) * 6), min_size=1, max_size=8), shift=st.floats(-1e-6, 1e-6))
def test_flange_errors_equal_pinocchio_s_check(q, shift):
    from robocritics.robot.ik import _Chain, _flange_errors, dh_forward

    q = np.array(q)
    poses = dh_forward(ROBOT.dh, q + shift)  # targets near, not at, the poses of q
    dp, dr = _flange_errors(ROBOT.dh, q, poses)
    chain = _Chain(ROBOT.dh)
    ref = np.array([chain.error(qi.tolist(), P[:3].ravel().tolist()) for qi, P in zip(q, poses)])
    assert np.max(np.abs(dp - ref[:, 0])) <= 1e-13
    assert np.max(np.abs(dr - ref[:, 1])) <= 1e-13


@pytest.mark.parametrize("tol", [1e-9, 5e-16, 3e-16])
def test_ur_ik_line_equals_ur_ik_per_pose_whatever_the_tolerance(tol):
    # tiny tolerances reject some (or all) fast rows: the per-pose fallback must then give what ur_ik gives
    from robocritics.robot.ik import ur_ik, ur_ik_line
    from robocritics.robot.model import fingers_down

    points = np.array([0.25, -0.1, 0.15]) + np.linspace(0.0, 1.0, 40)[:, None] * np.array([0.05, 0.2, 0.1])
    targets = np.broadcast_to(np.eye(4), (len(points), 4, 4)).copy()
    targets[:, :3, :3], targets[:, :3, 3] = fingers_down(0.3), points
    flanges = targets @ ROBOT._flange_in_tcp
    q, err = ur_ik_line(ROBOT.dh, flanges, ROBOT.home_q, ROBOT.lower, ROBOT.upper, tol=tol)
    seed, rows, err_ref = ROBOT.home_q, [], None
    for F in flanges:
        try:
            seed = ur_ik(ROBOT.dh, F, seed, ROBOT.lower, ROBOT.upper, tol=tol)
        except PlanningError as exc:
            err_ref = exc
            break
        rows.append(seed)
    assert q.shape == (len(rows), 6)
    if rows:
        assert np.max(np.abs(q - np.array(rows))) <= 1e-12
    assert str(err) == str(err_ref)


def test_ik_line_of_an_arm_without_closed_form_is_its_ik_point_by_point():
    from importlib import resources

    urdf = resources.files("robocritics.robot") / "models" / "ur3e.urdf"
    robot = Robot.from_urdf(str(urdf))
    assert robot.dh is not None  # a UR chain is recognised in its URDF (robot/dh_chain.py) ...
    robot.dh = None  # ... so take its closed form away: Pinocchio's numeric IK, as on an arm without one
    points = np.array([0.3, 0.1, 0.2]) + np.linspace(0.0, 1.0, 6)[:, None] * np.array([0.0, 0.03, 0.03])
    q, err = assert_same(robot, points, robot.home_q, 0.2)
    assert err is None and q.shape == (6, robot.n)


# --- the vectorised walk of long lines (ik._unverified_walk above _VECTORISED_WALK_POSES poses) ---------------


@pytest.fixture
def always_vectorised(monkeypatch):
    """Every walk vectorised, in short runs (so runs, the chain's passes and their seams are all exercised)."""
    from robocritics.robot import ik, ik_many

    monkeypatch.setattr(ik, "_VECTORISED_WALK_POSES", 1)
    monkeypatch.setattr(ik, "_LINE_CHUNK", 7)
    monkeypatch.setattr(ik_many, "_CHAIN_PASSES", 2)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(
    start=st.tuples(*(st.floats(-0.45, 0.45),) * 2, st.floats(-0.1, 0.5)),
    step=st.tuples(*(st.floats(-0.6, 0.6),) * 3),
    yaw=st.floats(-3.0, 3.0),
    n=st.integers(2, 60),
)
def test_vectorised_ik_line_equals_the_point_by_point_walk(always_vectorised, start, step, yaw, n):
    # lines that leave the workspace too (the step reaches 0.6 m per axis)
    points = np.asarray(start) + np.linspace(0.0, 1.0, n)[:, None] * np.asarray(step)
    assert_same(ROBOT, points, ROBOT.home_q, yaw)


@settings(max_examples=150, deadline=None)
@given(
    q=st.lists(st.floats(-6.0, 6.0), min_size=6, max_size=6),
    seed=st.lists(st.floats(-6.0, 6.0), min_size=6, max_size=6),
    lo=st.lists(st.floats(-6.3, 0.5), min_size=6, max_size=6),
    width=st.lists(st.floats(0.5, 12.6), min_size=6, max_size=6),
)
def test_vectorised_choice_is_the_branch_and_bound_choice(q, seed, lo, width):
    # any orientation (not only fingers down, so the wrist may be near its singularity), narrow or wide limits:
    # the vectorised selection of one pose is _nearest_solution's, to the last bit or two
    from robocritics.robot import ik, ik_many

    # At the stretched elbow (sin q3 = 0) the elbow angle is acos of a number at 1: the square root turns the two
    # implementations' last-bit differences into 1e-8 rad, which a joint limit at exactly that angle tells apart.
    assume(abs(math.sin(q[2])) > 1e-4)
    lo = np.asarray(lo)
    hi = lo + np.asarray(width)
    pose = ik.dh_forward(ROBOT.dh, np.asarray(q))
    t12 = pose[:3].reshape(1, 12)
    expected = ik._nearest_solution(ROBOT.dh._ur, t12[0].tolist(), list(seed), lo.tolist(), hi.tolist(), (1.0,) * 6)
    branches, exists, scalar = ik_many._branches_many(ROBOT.dh._ur, t12)
    if scalar[0]:  # left to _nearest_solution by the walk
        assert not exists[0].any()
        return
    got, solved = ik_many._nearest_chain(branches, exists, np.asarray(seed), lo, hi)
    assert solved == (0 if expected is None else 1)
    if expected is not None:
        assert np.max(np.abs(got[0] - expected)) <= 1e-12


def test_vectorised_walk_stops_where_the_pose_by_pose_walk_does(always_vectorised):
    from robocritics.robot import ik, ik_many

    points = np.array([0.3, 0.1, 0.2]) + np.linspace(0.0, 1.0, 80)[:, None] * np.array([0.8, 0.0, 0.0])
    q, err = assert_same(ROBOT, points, ROBOT.home_q, 0.0)
    assert 0 < len(q) < len(points) and err is not None
    # and the chain itself reports the first pose without a branch
    poses = np.broadcast_to(np.eye(4), (len(points), 4, 4)).copy()
    from robocritics.robot.model import fingers_down

    poses[:, :3, :3], poses[:, :3, 3] = fingers_down(0.0), points
    t12 = (poses @ ROBOT._flange_in_tcp)[:, :3].reshape(-1, 12)
    branches, exists, _ = ik_many._branches_many(ROBOT.dh._ur, t12)
    _, solved = ik_many._nearest_chain(branches, exists, ROBOT.home_q, ROBOT.lower, ROBOT.upper)
    assert solved == len(q)
