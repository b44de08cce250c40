"""The collaborative critics' pruned distances (block bounds from the parts' motion) against every triple computed
exactly, on random motions of random capsules near a random body: the nearest capsule, the sparse near triples,
and the contact cells beside the dense rule of contact_speed's definition."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics.critic.builtin import cobot
from robocritics.critic.builtin.cobot import Parts, part_body_distances, part_body_near, part_body_nearest
from robocritics.humans import BodyModel


def _random_case(seed: int, T: int, P: int, K: int, step_m: float):
    rng = np.random.default_rng(seed)
    start = rng.uniform(-0.5, 0.5, (1, P, 3))
    walk = np.cumsum(rng.normal(0.0, step_m, (T, P, 3)), axis=0)  # a random walk: parts move at any speed
    p0 = start + walk
    p1 = p0 + rng.uniform(-0.3, 0.3, (1, P, 3)) * (rng.random(P) > 0.2)[None, :, None]  # some are spheres
    present = rng.random((T, P)) > 0.1
    parts = Parts(tuple(f"part {i}" for i in range(P)), p0, p1, rng.uniform(0.01, 0.08, P), present)
    q0 = rng.uniform(-0.5, 0.5, (K, 3))
    body = BodyModel("someone", tuple(f"c{i}" for i in range(K)), ("hand",) * K, q0,
                     q0 + rng.uniform(-0.3, 0.3, (K, 3)), rng.uniform(0.02, 0.1, K))
    return parts, body


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), T=st.integers(1, 90), P=st.integers(1, 5), K=st.integers(1, 6),
       step=st.sampled_from([0.0, 0.002, 0.02, 0.2]), block=st.sampled_from([1, 3, 32]))
def test_pruned_distances_equal_every_triple_computed(seed, T, P, K, step, block):
    parts, body = _random_case(seed, T, P, K, step)
    saved, cobot.BLOCK = cobot.BLOCK, block
    try:
        full = part_body_distances(parts, body)  # every triple, exact
        assert np.array_equal(part_body_nearest(parts, body), full.min(axis=2))
        for within in (0.0, 0.05, 0.3):
            exact = full <= within
            exact[:-1] |= exact[1:]
            pruned = part_body_distances(parts, body, within_m=within)
            assert np.array_equal(pruned[exact], full[exact])
            assert np.all(pruned[~exact] > within) and np.all(pruned <= full)  # a lower bound elsewhere
            rows, p, k, d = part_body_near(parts, body, within)
            got = np.zeros(full.shape, dtype=bool)
            got[rows, p, k] = True
            assert np.all(got[exact & parts.present[:, :, None]])  # every near triple is held ...
            held = parts.present[rows, p]
            assert np.array_equal(d[held], full[rows, p, k][held])  # ... with its exact distance
            assert np.all(np.diff((rows * P + p) * K + k) > 0)  # in C order
    finally:
        cobot.BLOCK = saved
