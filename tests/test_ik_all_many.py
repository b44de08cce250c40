"""ur_ik_all_many (every branch of many poses at once, numpy) against the scalar ur_ik_all, pose by pose, and
against Pinocchio's FK (dh_forward); its closed-form FK check against the scalar ur_pose_errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robocritics.errors import PlanningError
from robocritics.robot.ik import UR3E_DH, dh_forward, ur_ik_all, ur_ik_all_many
from robocritics.robot.ik_many import _pose_errors_many
from robocritics.robot.ur_fk import ur_pose_errors

TWO_PI = 2.0 * math.pi
angle = st.floats(-TWO_PI, TWO_PI, allow_nan=False, allow_infinity=False)
# joints at the singularities too: q5 = 0 (wrist: q6 free, the scalar path), q3 = 0 (elbow: branches merge)
special = st.sampled_from([0.0, math.pi, -math.pi, 1e-9, 1e-7])
joint = st.one_of(angle, angle, angle, special)
configurations = st.lists(st.lists(joint, min_size=6, max_size=6), min_size=1, max_size=12).map(np.array)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(q=configurations, q6_singular=angle)
def test_the_rows_of_every_pose_are_the_scalar_ones(q, q6_singular):
    T = dh_forward(UR3E_DH, q)
    got, valid = ur_ik_all_many(UR3E_DH, T, q6_singular=q6_singular)
    assert got.shape == (len(q), 8, 6) and valid.shape == (len(q), 8)
    assert np.isnan(got[~valid]).all()
    for i in range(len(q)):
        ref = ur_ik_all(UR3E_DH, T[i], q6_singular=q6_singular)
        rows = got[i][valid[i]]
        assert rows.shape == ref.shape
        # numpy's and libm's sines may round differently: the same angles to a few ulps (a little more where
        # acos / atan2 lose digits at a singularity)
        assert np.abs(rows - ref).max(initial=0.0) < 1e-9
        assert np.all(rows > -math.pi) and np.all(rows <= math.pi)
        for Fi in dh_forward(UR3E_DH, rows):  # Pinocchio: every row reproduces the pose
            assert np.abs(Fi[:3, 3] - T[i][:3, 3]).max() < 1e-9
            assert np.abs(Fi[:3, :3] - T[i][:3, :3]).max() < 1e-9


def test_unreachable_poses_have_no_rows():
    T = dh_forward(UR3E_DH, np.zeros((3, 6)))
    T[1, :3, 3] = (1.0, 0.0, 0.2)  # a metre out: beyond the UR3e's reach
    T[2, :3, 3] = (0.0, 0.0, 0.3)  # on the base axis: inside the shoulder offset's cylinder
    got, valid = ur_ik_all_many(UR3E_DH, T)
    assert valid[0].sum() == len(ur_ik_all(UR3E_DH, T[0])) > 0
    assert not valid[1:].any() and np.isnan(got[1:]).all()
    assert len(ur_ik_all(UR3E_DH, T[1])) == len(ur_ik_all(UR3E_DH, T[2])) == 0


def test_bad_shape_is_a_planning_error():
    with pytest.raises(PlanningError, match=r"ur_ik_all_many: flange_poses must have shape \(n, 4, 4\)"):
        ur_ik_all_many(UR3E_DH, np.eye(4))


@settings(max_examples=200, deadline=None)
@given(q=st.lists(st.lists(angle, min_size=6, max_size=6), min_size=1, max_size=8).map(np.array),
       dq=st.floats(-1e-3, 1e-3))  # fmt: skip
def test_vectorised_fk_errors_equal_the_scalar_ones(q, dq):
    T = dh_forward(UR3E_DH, q + dq)  # errors of the order of dq
    t12 = T[:, :3].reshape(-1, 12)
    dp, dr = _pose_errors_many(UR3E_DH._ur, q, t12)
    for i in range(len(q)):
        p_ref, r_ref = ur_pose_errors(UR3E_DH._ur, q[i].tolist(), t12[i].tolist())
        assert dp[i] == pytest.approx(p_ref, rel=1e-9, abs=1e-15)
        assert dr[i] == pytest.approx(r_ref, rel=1e-9, abs=1e-15)
