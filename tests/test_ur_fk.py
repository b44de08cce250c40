"""The closed-form UR forward kinematics (robot/ur_fk.py, the IK's check) against Pinocchio on the DH chain's URDF."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics.robot.arms import DH, UR3E, UR10E
from robocritics.robot.ik import _Chain, dh_forward
from robocritics.robot.ur_fk import ur_flange_pose12, ur_pose_errors, ur_reproduces

# UR arms, and a UR-like chain with the d2 and d3 offsets the closed form folds into d4
OFFSET_DH = DH(d=(0.2, 0.03, -0.05, 0.11, 0.09, 0.08), a=(0.0, -0.3, -0.25, 0.0, 0.0, 0.0),
               alpha=UR3E.dh.alpha, name="offset")  # fmt: skip
ARMS = [UR3E.dh, UR10E.dh, OFFSET_DH]
special = st.sampled_from([0.0, 1e-13, -1e-9, math.pi, -math.pi, 0.5 * math.pi, 2.0 * math.pi, -6.2])
angle = st.one_of(st.floats(-7.0, 7.0, allow_nan=False), special)
joints = st.lists(angle, min_size=6, max_size=6)


@settings(max_examples=400, deadline=None)
@given(q=joints, arm=st.sampled_from(ARMS))
def test_the_flange_pose_is_pinocchios(q, arm):
    expected = dh_forward(arm, np.array(q))[:3].ravel()
    got = np.array(ur_flange_pose12(arm._ur, q))
    assert np.max(np.abs(got - expected)) <= 1e-14


@settings(max_examples=300, deadline=None)
@given(q=joints, dq=st.lists(st.floats(-1e-6, 1e-6), min_size=6, max_size=6), arm=st.sampled_from(ARMS))
def test_the_errors_are_pinocchios(q, dq, arm):
    """Position and rotation errors against a target a little off the pose, as _Chain.error computes them."""
    t = dh_forward(arm, np.array(q) + np.array(dq))[:3].ravel().tolist()
    dp, dr = ur_pose_errors(arm._ur, q, t)
    ep, er = _Chain(arm).error(q, t)
    assert abs(dp - ep) <= 1e-14 and abs(dr - er) <= 1e-14


@settings(max_examples=300, deadline=None)
@given(q=joints, dq=st.lists(st.floats(-1e-8, 1e-8), min_size=6, max_size=6), pick=st.integers(0, 3))
def test_reproduces_is_the_errors_within_tol_at_the_boundary(q, dq, pick):
    """``ur_reproduces`` decides as ``ur_pose_errors`` does, with the tolerance set to the error itself and the
    floats on either side of it."""
    k = UR3E.dh._ur
    t = dh_forward(UR3E.dh, np.array(q))[:3].ravel().tolist()
    moved = (np.array(q) + np.array(dq)).tolist()
    dp, dr = ur_pose_errors(k, moved, t)
    base = (dp, dr, max(dp, dr), min(dp, dr))[pick]
    for tol in (np.nextafter(base, 0.0), base, np.nextafter(base, 1.0)):
        assert ur_reproduces(k, moved, t, float(tol)) == (dp <= tol and dr <= tol)


def test_a_nan_joint_or_target_is_never_reproduced():
    k = UR3E.dh._ur
    q = [0.1, -1.0, 1.2, -0.5, 0.9, 0.3]
    t = dh_forward(UR3E.dh, np.array(q))[:3].ravel().tolist()
    assert ur_reproduces(k, q, t, 1e-9)
    assert not ur_reproduces(k, [math.nan] + q[1:], t, 1e-9)
    assert not ur_reproduces(k, q, [math.nan] + t[1:], 1e-9)
