"""The compiled nearest-branch search (``robocritics.robot._ur_nearest``) against the Python search it mirrors.

``_nearest_search_plain`` (Python) is the reference: on every target, seed, set of limits and weights the compiled
search answers either the very same ``(cost, q, exact)``, bit for bit, or ``NotImplemented`` (its uncommon cases:
the wrist near its singularity, non-finite input), and then ``_nearest_search`` runs the Python search.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics.robot import ik_nearest
from robocritics.robot.ik import UR3E_DH, dh_forward
from robocritics.robot.ik_many import _WRIST_NEAR_SINGULAR

K = UR3E_DH._ur
TWO_PI = 2.0 * math.pi
special = st.sampled_from([0.0, 1e-13, -1e-9, 1e-7, 1e-5, math.pi, -math.pi, math.pi - 1e-12, 0.5 * math.pi])
angle = st.one_of(st.floats(-math.pi, math.pi, allow_nan=False), special)
joints = st.lists(angle, min_size=6, max_size=6).map(np.array)
wide = st.just((np.full(6, -TWO_PI), np.full(6, TWO_PI)))
tight = st.tuples(
    st.lists(st.floats(-3.0, 3.0), min_size=6, max_size=6), st.lists(st.floats(0.3, 7.0), min_size=6, max_size=6)
).map(lambda cw: (np.array(cw[0]) - 0.5 * np.array(cw[1]), np.array(cw[0]) + 0.5 * np.array(cw[1])))
weights = st.one_of(st.just([1.0] * 6), st.lists(st.floats(0.01, 100.0), min_size=6, max_size=6))


def target(q: np.ndarray) -> list[float]:
    return dh_forward(UR3E_DH, q)[:3].ravel().tolist()


def test_the_compiled_search_is_built():
    """setup.py builds it with the package; a missing compiler would leave only the Python search (5-8 us)."""
    assert ik_nearest._compiled_search is not None


@settings(max_examples=1500, deadline=None)
@given(q=joints, noise=st.lists(st.floats(-0.5, 0.5), min_size=6, max_size=6), far_seed=st.one_of(st.none(), joints),
       limits=st.one_of(wide, tight), w=weights)
def test_the_compiled_search_is_the_python_search_bit_for_bit(q, noise, far_seed, limits, w):
    lo, hi = limits
    seed = np.clip(q + np.array(noise) if far_seed is None else far_seed, lo, hi).tolist()
    t = target(q)
    got = ik_nearest._compiled_search(K, t, seed, lo.tolist(), hi.tolist(), w)
    expected = ik_nearest._nearest_search_plain(K, t, seed, lo.tolist(), hi.tolist(), w)
    if got is NotImplemented:  # only the cases left to Python
        assert _near_singular_wrist(t), (q, seed)
        return
    assert got == expected  # floats compared exactly; cost, joints and the exact flag


def _shoulder_pans(t: list[float]) -> list[float]:
    """The two shoulder pans of the closed form's step 1 (the wrist-2 centre outside the base cylinder)."""
    d4, d6 = K[3], K[5]
    p5x, p5y = t[3] - d6 * t[2], t[7] - d6 * t[6]
    r = math.hypot(p5x, p5y)
    ratio = max(-1.0, min(1.0, d4 / r))
    phi = math.atan2(p5y, p5x) + 0.5 * math.pi
    return [phi + math.acos(ratio), phi - math.acos(ratio)]


def _near_singular_wrist(t: list[float]) -> bool:
    """Whether ``|sin q5|`` is near zero (within 10x the threshold: the search visits one pan or both) for a pan."""
    for q1 in _shoulder_pans(t):
        s1, c1 = math.sin(q1), math.cos(q1)
        s5 = math.hypot(t[0] * s1 - t[4] * c1, t[1] * s1 - t[5] * c1)
        if s5 < 10.0 * _WRIST_NEAR_SINGULAR:
            return True
    return False


def test_the_wrist_singularity_and_non_finite_input_are_left_to_python():
    ones, lo, hi = [1.0] * 6, [-TWO_PI] * 6, [TWO_PI] * 6
    q = np.array([0.3, -1.2, 1.0, -0.5, 0.0, 0.7])  # q5 = 0: joints 4 and 6 aligned
    t = target(q)
    assert ik_nearest._compiled_search(K, t, q.tolist(), lo, hi, ones) is NotImplemented
    found = ik_nearest._nearest_search(K, t, q.tolist(), lo, hi, ones)  # the dispatch falls back to Python
    assert found == ik_nearest._nearest_search_plain(K, t, q.tolist(), lo, hi, ones) and found is not None
    bad = list(t)
    bad[3] = math.nan
    assert ik_nearest._compiled_search(K, bad, q.tolist(), lo, hi, ones) is NotImplemented
    assert ik_nearest._nearest_search(K, bad, q.tolist(), lo, hi, ones) is None
    assert ik_nearest._compiled_search(K, target(q + 0.1), q.tolist(), lo, hi, [1.0, math.inf, 1, 1, 1, 1]) is (
        NotImplemented
    )


def test_a_pose_out_of_reach_and_limits_that_rule_every_branch_out_give_none():
    ones = [1.0] * 6
    far = np.eye(4)
    far[:3, 3] = (2.0, 0.0, 0.3)  # 2 m away: the UR3e reaches about 0.5 m
    t = far[:3].ravel().tolist()
    assert ik_nearest._compiled_search(K, t, [0.0] * 6, [-TWO_PI] * 6, [TWO_PI] * 6, ones) is None
    q = np.array([0.3, -1.2, 1.0, -0.5, 1.1, 0.7])
    lo, hi = (q + 0.5).tolist(), (q + 0.6).tolist()  # no branch of this pose within them
    assert ik_nearest._nearest_search_plain(K, target(q), lo, lo, hi, ones) is None
    assert ik_nearest._compiled_search(K, target(q), lo, lo, hi, ones) is None


def test_bad_arguments_raise():
    with pytest.raises(ValueError):
        ik_nearest._compiled_search(K, [0.0] * 11, [0.0] * 6, [-1.0] * 6, [1.0] * 6, [1.0] * 6)
    with pytest.raises(TypeError):
        ik_nearest._compiled_search(K, [0.0] * 12, ["a"] * 6, [-1.0] * 6, [1.0] * 6, [1.0] * 6)
