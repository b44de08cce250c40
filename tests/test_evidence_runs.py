"""A finding's evidence lists at most 20 runs of flagged samples: for more, spread over the whole motion with the
worst one among them (a long program's timeline marks where its findings recur, not only its first minutes)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from robocritics.critic.verdict import kept_runs, make_evidence, runs

from synth import make_trajectory


@settings(max_examples=300, deadline=None)
@given(n=st.integers(1, 400), density=st.floats(0.05, 0.95), seed=st.integers(0, 2**31), max_runs=st.integers(1, 25),
       worst_at=st.floats(0, 1))
def test_kept_runs_are_bounded_ordered_spread_and_hold_the_worst(n, density, seed, max_runs, worst_at):
    mask = np.random.default_rng(seed).random(n) < density
    starts, ends = runs(mask)
    n = len(starts)
    worst = int(worst_at * (len(mask) - 1))
    kept = kept_runs(starts, ends, max_runs, worst)
    assert kept == sorted(set(kept)) and all(0 <= k < n for k in kept)
    if n <= max_runs:
        assert kept == list(range(n))
        return
    assert len(kept) == max_runs
    holding = [k for k in range(n) if starts[k] <= worst <= ends[k]]
    if holding:
        assert holding[0] in kept
    if max_runs >= 3 or (max_runs == 2 and not holding):
        assert kept[0] == 0 and kept[-1] == n - 1
    # spread: no two neighbours kept farther apart than twice the even spacing (one slot moved to the worst)
    spacing = (n - 1) / max(max_runs - 1, 1)
    assert np.max(np.diff(kept), initial=0) <= 2 * spacing + 1


def test_the_evidence_of_a_recurring_finding_marks_its_last_and_worst_windows():
    T = 3000
    trajectory = make_trajectory(np.arange(T) / 100.0)
    mask = np.zeros(T, dtype=bool)
    for start in range(10, T - 10, 60):  # 50 separate windows of 5 samples
        mask[start:start + 5] = True
    worst = 60 * 33 + 12
    evidence = make_evidence(trajectory, mask, worst=worst)
    ranges = evidence.sample_ranges
    assert len(ranges) == 20 and ranges == sorted(ranges)
    assert ranges[0][0] == 10 and ranges[-1][0] == 10 + 60 * 49
    assert any(a <= worst <= b for a, b in ranges)
    assert evidence.samples_flagged == 250 and (evidence.first_sample, evidence.last_sample) == (10, 60 * 49 + 14)
