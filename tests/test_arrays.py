"""robocritics._arrays: the sort-based set operations give np.unique's answers (the slow obvious reference)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from robocritics._arrays import equal_row_groups, first_of_equal_rows, run_starts, squared_norms, unique_values

# few distinct values, so that repeats (and -0.0 next to 0.0) are common
small_floats = st.sampled_from([0.0, -0.0, 1.0, -1.0, 0.5, 1e-300, 2.0**-40, np.inf, -np.inf, np.nan])
float_arrays = hnp.arrays(np.float64, st.integers(0, 40), elements=small_floats)
int_arrays = hnp.arrays(np.int64, st.integers(0, 40), elements=st.integers(-5, 5))
row_arrays = hnp.arrays(np.float64, st.tuples(st.integers(0, 30), st.integers(1, 3)),
                        elements=small_floats.filter(lambda x: not np.isnan(x)))  # fmt: skip


@settings(max_examples=300, derandomize=True, deadline=None)
@given(st.one_of(float_arrays, int_arrays))
def test_unique_values_is_np_unique(x):
    got, want = unique_values(x), np.unique(x)
    assert got.dtype == want.dtype
    np.testing.assert_array_equal(got, want)  # NaNs compare equal here: one NaN in both


def test_unique_values_flattens_and_keeps_one_nan():
    np.testing.assert_array_equal(unique_values(np.array([[3, 1], [3, 2]])), [1, 2, 3])
    got = unique_values(np.array([np.nan, 1.0, np.nan, 1.0]))
    assert got.shape == (2,) and got[0] == 1.0 and np.isnan(got[1])


@settings(max_examples=300, derandomize=True, deadline=None)
@given(row_arrays)
def test_equal_row_groups_are_np_uniques_labels(A):
    group, counts = equal_row_groups(A)
    if len(A) == 0:
        assert group.shape == (0,) and counts.shape == (0,)
        return
    _, want_group, want_counts = np.unique(A, axis=0, return_inverse=True, return_counts=True)
    np.testing.assert_array_equal(group, want_group.reshape(-1))
    np.testing.assert_array_equal(counts, want_counts)


def test_equal_row_groups_puts_a_nan_row_alone():
    group, counts = equal_row_groups(np.array([[np.nan, 0.0], [np.nan, 0.0], [1.0, 0.0], [1.0, 0.0]]))
    assert group[0] != group[1] and group[2] == group[3]
    assert sorted(counts.tolist()) == [1, 1, 2]


def first_of_equal_reference(A, W):
    """The plain loop: for each row of A in order, keep it if it equals a row of W and no earlier row of A."""
    out, seen = [], []
    for i, row in enumerate(A):
        if any((row == w).all() for w in W) and not any((row == s).all() for s in seen):
            out.append(i)
        seen.append(row)
    return out


@settings(max_examples=300, derandomize=True, deadline=None)
@given(row_arrays, st.data())
def test_first_of_equal_rows_is_the_loop(A, data):
    k = A.shape[1]
    picks = data.draw(st.lists(st.integers(0, max(len(A) - 1, 0)), max_size=10)) if len(A) else []
    extra = data.draw(hnp.arrays(np.float64, (data.draw(st.integers(0, 3)), k), elements=st.floats(-3, 3)))
    W = np.concatenate([A[picks].reshape(-1, k), extra])  # rows of A (some repeated) and rows A may lack
    got = first_of_equal_rows(A, W)
    assert got.dtype == np.int64
    assert got.tolist() == first_of_equal_reference(A, W)


def test_first_of_equal_rows_counts_minus_zero_as_zero():
    A = np.array([[0.0, 1.0], [-0.0, 1.0], [2.0, 2.0]])
    assert first_of_equal_rows(A, np.array([[-0.0, 1.0]])).tolist() == [0]
    assert first_of_equal_rows(A, np.zeros((0, 2))).tolist() == []


@settings(max_examples=200, derandomize=True, deadline=None)
@given(hnp.arrays(np.float64, st.tuples(st.integers(0, 50), st.integers(1, 13)), elements=small_floats))
def test_row_max_and_row_any_are_numpys(A):
    from robocritics._arrays import row_any, row_max

    np.testing.assert_array_equal(row_max(A), A.max(axis=1))  # NaN where a row holds one, in both
    np.testing.assert_array_equal(row_any(A > 0.5), (A > 0.5).any(axis=1))
    np.testing.assert_array_equal(row_any(A[:, :0]), A[:, :0].any(axis=1))


@settings(max_examples=200, derandomize=True, deadline=None)
@given(hnp.arrays(np.float64, st.tuples(st.integers(0, 50), st.integers(1, 13)), elements=small_floats), st.data())
def test_min_over_columns_is_the_gathered_row_minimum(A, data):
    from robocritics._arrays import min_over_columns

    picked = data.draw(st.lists(st.integers(0, A.shape[1] - 1), max_size=A.shape[1], unique=True))
    columns = np.array(picked, dtype=np.intp)
    want = A[:, columns].min(axis=1) if len(columns) else np.full(len(A), np.inf)
    np.testing.assert_array_equal(min_over_columns(A, columns), want)


def test_first_of_equal_rows_compares_values_across_dtypes():
    # W is not cast to A's dtype: 0.5 is no int 0, 258 is no uint8 2; equal values of other dtypes do match
    assert first_of_equal_rows(np.array([[0, 0], [1, 1]]), np.array([[0, 0.5]])).tolist() == []
    assert first_of_equal_rows(np.array([[1, 2]], dtype=np.uint8), np.array([[1, 258]])).tolist() == []
    assert first_of_equal_rows(np.array([[0, 0], [1, 1]]), np.array([[1.0, 1.0]])).tolist() == [1]


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from(["", "apple", "cup"]), max_size=30))
def test_run_starts_are_where_a_value_differs_from_the_one_before(values):
    a = np.array(values, dtype=str)
    assert run_starts(a).tolist() == [i for i in range(len(values)) if i == 0 or values[i] != values[i - 1]]


@settings(max_examples=100, deadline=None)
@given(hnp.arrays(np.float64, hnp.array_shapes(min_dims=1, max_dims=3).map(lambda s: (*s, 3)), elements=st.floats(-1e3, 1e3)))
def test_squared_norms_equal_einsum_bit_for_bit(v):
    assert np.array_equal(squared_norms(v), np.einsum("...i,...i->...", v, v))
