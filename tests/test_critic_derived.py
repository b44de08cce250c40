"""The critics' shared derived arrays and the plane-layout kernels, against the plain interleaved formulas.

The space-usage and joint-speed critics read the positions as coordinate planes ``(3, L, T)``
(:func:`robocritics.critic.derived.position_planes`); these tests hold them to the ``(T, L, 3)`` formulas they
replaced, bit for bit (a flipped rounding could move a hull-thinning stride and so a reported volume).
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from robocritics._arrays import row_max, squared_norms
from robocritics.critic import as_execution
from robocritics.critic.builtin.joint_speed import squared_steps
from robocritics.critic.builtin.space_usage import _outside, second_differences
from robocritics.critic.derived import position_planes, shared
from robocritics.scene import Scene, Workspace
from synth import realistic_trajectory

coordinates = st.floats(-2.0, 2.0, allow_nan=False, width=64)


def positions(min_samples: int = 1):
    return st.tuples(st.integers(min_samples, 40), st.integers(1, 5)).flatmap(
        lambda shape: arrays(np.float64, (shape[0], shape[1], 3), elements=coordinates)
    )


def planes_of(X: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(X.transpose(2, 1, 0))


@settings(max_examples=200, deadline=None)
@given(X=positions(min_samples=3))
def test_second_differences_are_the_interleaved_ones_bit_for_bit(X):
    T = len(X)
    d2 = X[2:] - X[1:-1]  # the formula of the (T, L, 3) version: ((p_{t+1} - p_t) - p_t) + p_{t-1}
    d2 -= X[1:-1]
    d2 += X[:-2]
    want = squared_norms(d2).T  # (L, T-2)
    got = second_differences(planes_of(X), slice(1, T - 1))
    np.testing.assert_array_equal(got, want)
    out = np.full((X.shape[1], T + 3), -1.0)
    second_differences(planes_of(X), slice(1, T - 1), out=out[:, 2 : T])
    np.testing.assert_array_equal(out[:, 2:T], want)
    assert (out[:, :2] == -1).all() and (out[:, T:] == -1).all()


@settings(max_examples=200, deadline=None)
@given(X=positions(min_samples=2))
def test_squared_steps_are_link_speeds_squares_bit_for_bit(X):
    T = len(X)
    want = squared_norms(X[1:] - X[:-1]).T  # (L, T-1), as link_speeds squares the steps
    np.testing.assert_array_equal(squared_steps(planes_of(X), slice(0, T - 1)), want)


@settings(max_examples=200, deadline=None)
@given(X=positions(), centre=st.tuples(coordinates, coordinates, coordinates), radius=st.floats(0.01, 2.0))
def test_outside_from_squared_distances_is_outside_distance_bit_for_bit(X, centre, radius):
    ws = Workspace(center=centre, radius_m=radius)
    reference = np.asarray(ws.outside_distance(X))  # (T, L), point by point
    T, L, _ = X.shape
    per_sample, outside, farthest = _outside(ws, planes_of(X), slice(0, T))
    np.testing.assert_array_equal(per_sample, row_max(reference))
    rows, frames = np.arange(T)[:, None], np.arange(L)[None, :]
    np.testing.assert_array_equal(outside(rows, frames), reference)
    some = np.arange(0, T, 2)
    np.testing.assert_array_equal(farthest(some), reference[some].max(axis=0))


def test_a_custom_workspace_is_asked_for_every_point():
    class Slab(Workspace):
        def outside_distance(self, points):
            return np.asarray(points)[..., 2] - 0.3

    X = np.random.default_rng(3).uniform(-1, 1, (20, 4, 3))
    per_sample, outside, farthest = _outside(Slab(center=(0, 0, 0), radius_m=1.0), planes_of(X), slice(0, 20))
    np.testing.assert_array_equal(per_sample, (X[..., 2] - 0.3).max(axis=1))
    np.testing.assert_array_equal(farthest(np.arange(20)), (X[..., 2] - 0.3).max(axis=0))


def test_derived_arrays_are_computed_once_per_run_and_not_kept_by_critique():
    trajectory = realistic_trajectory(duration_s=1.0, rate_hz=100)
    execution = as_execution(trajectory, Scene.builtin("sorting"))
    planes = position_planes(execution)
    assert planes is position_planes(execution)  # the second reader gets the same array
    np.testing.assert_array_equal(planes, trajectory.positions.transpose(2, 1, 0))
    assert planes.flags.c_contiguous and not planes.flags.writeable
    calls = []
    assert shared(execution, "k", lambda: calls.append(1) or np.zeros(3)) is shared(execution, "k", lambda: None)
    assert calls == [1]
    from dataclasses import replace

    assert replace(execution).derived == {}  # a copy (a chunk, critique's) starts empty
    assert pickle.loads(pickle.dumps(execution)).derived == {}
    from robocritics.critic import critique

    fresh = as_execution(trajectory, Scene.builtin("sorting"))
    critique(fresh)
    assert fresh.derived == {}  # critique judged a copy: nothing derived outlives the call


@pytest.mark.parametrize("frames", [None, ("tool0",)])
def test_planes_feed_the_frame_selection(frames):
    trajectory = realistic_trajectory(duration_s=0.5, rate_hz=100)
    execution = as_execution(trajectory, Scene.builtin("sorting"))
    sel = [trajectory.frame_index(n) for n in frames] if frames else slice(None)
    np.testing.assert_array_equal(position_planes(execution)[:, sel], planes_of(trajectory.positions[:, sel]))


@settings(max_examples=150, deadline=None)
@given(
    X=positions(min_samples=3),
    layout=st.lists(st.integers(-2, 6), min_size=1, max_size=6),
    centre=st.tuples(coordinates, coordinates, coordinates),
    tolerance=st.sampled_from([0.0005, 0.01, 1.0]),
)
def test_still_and_copied_frames_are_judged_as_if_computed(X, layout, centre, tolerance):
    """Frames still over the window (-1: at a point; -2: at the origin) and copies of other frames (k >= 0: of
    frame k mod L) get the kept samples and outside distances of the computation over every frame."""
    from robocritics.critic.builtin.space_usage import kept_samples
    from robocritics.critic.derived import Frames, frame_kinds

    T, L, _ = X.shape
    extra = []
    for k in layout:
        extra.append(np.broadcast_to(X[0, 0] if k == -1 else np.zeros(3), (T, 3)) if k < 0 else X[:, k % L])
    X = np.ascontiguousarray(np.concatenate([X, np.stack(extra, axis=1)], axis=1))
    Y = planes_of(X)
    every = Frames([(0, X.shape[1])], *(np.zeros(0, dtype=np.int64),) * 3)  # every frame its own work
    kinds = frame_kinds(Y)
    assert sum(b - a for a, b in kinds.runs) + kinds.still.size + kinds.copies.size == X.shape[1]
    for got, want in zip(kept_samples(Y, 0, 0, T, T, tolerance, kinds), kept_samples(Y, 0, 0, T, T, tolerance, every)):
        np.testing.assert_array_equal(got, want)
    ws = Workspace(center=centre, radius_m=0.5)
    reference = np.asarray(ws.outside_distance(X))  # (T, L'), point by point
    per_sample, outside, farthest = _outside(ws, Y, slice(0, T), kinds)
    np.testing.assert_array_equal(per_sample, row_max(reference))
    rows, frames = np.arange(T)[:, None], np.arange(X.shape[1])[None, :]
    np.testing.assert_array_equal(outside(rows, frames), reference)
    np.testing.assert_array_equal(farthest(np.arange(0, T, 2)), reference[::2].max(axis=0))
