"""Far pairs pruned over blocks of samples keep every value a consumer reads: checked against the plain kernel.

The plain computation is ``ProximityKernel.distances`` without ``far_m`` (every pair at every sample, exact;
itself checked against the per-pair functions and coal in tests/test_proximity.py). With ``far_m`` and column
sets (``exact_min_of``), a value within its column's cutoff must be the plain value bit for bit (the pruned
kernel evaluates the same elementwise formulas on the same numbers, batched differently), every other value a
lower bound above the cutoff, and the per-sample least distance over each set exact. At the pipeline level, the
reports of the bundled programs are the same with the pruned trajectory as with the plain one.
"""

from __future__ import annotations

import json
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robocritics import Robot, Scene, critique, simulate
from robocritics.geometry import blocks as blocks_module
from robocritics.geometry import proximity as P
from robocritics.geometry.blocks import column_sets
from robocritics.planning import trace
from robocritics.scene import Container, Shape, rpy_matrix

SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)
PROGRAMS = Path(__file__).resolve().parents[1] / "examples" / "programs"


def _trajectory(T, C, seed):
    """Capsule endpoints (T, C, 3) m wandering over the breakfast table, some fast (long blocks of motion)."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0, 1, T)[:, None, None]
    base = rng.uniform([-0.4, -0.4, 0.0], [0.4, 0.4, 0.3], (1, C, 3))
    amp = rng.uniform(-0.3, 0.3, (1, C, 3))
    p0 = base + amp * np.sin(2 * np.pi * s * rng.uniform(0.5, 4, (1, C, 1)))
    p1 = p0 + rng.normal(size=(1, C, 3)) * 0.1 * np.cos(3 * s + rng.uniform(0, 3, (1, C, 1)))
    return p0, p1


def _shapes(seed):
    rng = np.random.default_rng(seed)
    out = []
    for i, s in enumerate(Scene.builtin("breakfast").shapes()):
        pose = s.pose.copy()
        if i % 4 == 1:  # some tilted objects
            pose[:3, :3] = rpy_matrix(tuple(rng.uniform(-1, 1, 3)))
        out.append(Shape(s.name, s.owner, s.kind, s.size, pose))
    return out + Container(id="bin", size=(0.2, 0.15, 0.1), position=(0.1, -0.2, 0.05), yaw=0.4).shapes()


@settings(max_examples=25, **SETTINGS)
@given(
    seed=st.integers(0, 2**31 - 1),
    far=st.sampled_from([0.0, 0.03, 0.1, 0.25]),
    n_tight=st.integers(0, 3),
    T=st.integers(1, 300),
    held_kind=st.sampled_from(["box", "cylinder", "sphere"]),
)
def test_pruned_values_are_the_plain_ones_within_each_columns_cutoff(seed, far, n_tight, T, held_kind):
    """Two column sets (some environment columns; every self pair) and columns in no set: a value within
    ``max(far_m, least plain value of its set)`` (no set: the first set's) equals the plain value bit for bit,
    every other one is a lower bound above that cutoff, and the least value over each set, and over the first
    set with the columns in no set, is the plain one at every sample. Static, tilted, yawed-container and
    moving boxes, cylinders and spheres; a capsule that stands still; short trajectories (one partial block)."""
    rng = np.random.default_rng(seed)
    C = 6
    p0, p1 = _trajectory(T, C, seed % 1000)
    p0[:, 0], p1[:, 0] = p0[:1, 0], p1[:1, 0]  # capsule 0 stands still
    caps = [(f"link{i}", float(rng.uniform(0.005, 0.05))) for i in range(C)]
    size = {"box": (0.03, 0.04, 0.05), "cylinder": (0.03, 0.04), "sphere": (0.03,)}[held_kind]
    shapes = _shapes(seed % 7) + [Shape("held", "held", held_kind, size, np.eye(4))]
    pose = np.tile(np.eye(4), (T, 1, 1))
    pose[:, :3, 3] = p1[:, 1] + [0.0, 0.0, 0.05]  # rides near capsule 1
    pose[:, :3, :3] = rpy_matrix(tuple(rng.uniform(-1, 1, 3)))
    pairs = [(c, sh.name) for c, _ in caps for sh in shapes]
    pairs += [(f"link{i}", f"link{j}") for i in range(C) for j in range(i + 2, C)]
    own = [k for k, (_, b) in enumerate(pairs) if b.startswith("link")]
    env = [k for k, (_, b) in enumerate(pairs) if not b.startswith("link")]
    first = sorted(rng.choice(env, size=min(n_tight * 15, len(env)), replace=False).tolist())
    sets = [first, own] if first else [own]
    kern = P.ProximityKernel(caps, shapes, pairs, moving={"held"})
    plain = kern.distances(p0, p1, poses={"held": pose})
    D = kern.distances(p0, p1, poses={"held": pose}, far_m=far, exact_min_of=sets)
    cut = np.full((T, len(pairs)), far)
    for cols in sets:
        cut[:, cols] = np.maximum(far, plain[:, cols].min(axis=1))[:, None]
    loose = [k for k in range(len(pairs)) if not any(k in cols for cols in sets)]
    cut[:, loose] = np.maximum(far, plain[:, sets[0]].min(axis=1))[:, None]
    inside = plain <= cut
    np.testing.assert_array_equal(D[inside], plain[inside])
    assert (D[~inside] > cut[~inside]).all() and (D[~inside] <= plain[~inside] + 1e-12).all()
    for cols in sets + [sets[0] + loose]:
        np.testing.assert_array_equal(D[:, cols].min(axis=1), plain[:, cols].min(axis=1))
    # the self pairs are pruned: on a trajectory of some length most far blocks keep their bound
    if T >= 200 and far <= 0.1:
        assert (D[:, own] != plain[:, own]).any()


def test_one_list_is_one_set_and_bad_sets_are_refused():
    assert column_sets([2, 0], 4).tolist() == [0, -1, 0, -1]
    assert column_sets([[1], [3, 0]], 4).tolist() == [1, 0, -1, 1]
    assert column_sets([], 3).tolist() == [-1, -1, -1]
    with pytest.raises(ValueError, match="not a column index"):
        column_sets([[0], [4]], 4)
    with pytest.raises(ValueError, match="in set 0 and set 1"):
        column_sets([[0, 1], [1]], 4)


@pytest.fixture(scope="module")
def robot():
    return Robot.ur3e()


@pytest.mark.parametrize("name", ["breakfast_careful", "recycling_naive", "sorting_careful"])
def test_reports_of_pruned_and_plain_trajectories_are_the_same(robot, name, monkeypatch):
    """The bundled programs judged on the trajectory as simulated (far pairs pruned) and on the plain one (every
    value exact: the trace without a cutoff): the same report, every number equal; every proximity value within
    EXACT_WITHIN_M and the least distance of the arm and of the self pairs at every sample equal bit for bit."""
    source = (PROGRAMS / f"{name}.py").read_text()
    scene = Scene.builtin(name.split("_")[0])
    within = trace.EXACT_WITHIN_M
    pruned = simulate(source, scene, robot)
    monkeypatch.setattr(trace, "EXACT_WITHIN_M", None)  # far_m=None: the plain computation
    plain = simulate(source, scene, robot)
    Dp, Dx = pruned.trajectory.proximity, plain.trajectory.proximity
    near = Dx <= within
    np.testing.assert_array_equal(Dp[near], Dx[near])
    assert (Dp <= Dx + 1e-12).all()
    pairs = pruned.trajectory.pairs
    for cols in (
        [k for k, p in enumerate(pairs) if p.kind == "self"],
        [k for k, p in enumerate(pairs) if p.kind == "environment" and p.group_a == "arm"],
        [k for k, p in enumerate(pairs) if p.kind == "environment"],
    ):
        np.testing.assert_array_equal(Dp[:, cols].min(axis=1), Dx[:, cols].min(axis=1))
    assert (Dp != Dx).any()  # far values really were bounds, not exact
    assert json.loads(critique(pruned).to_json()) == json.loads(critique(plain).to_json())


def _long_case(T, seed=3):
    """Six capsules wandering through the breakfast scene for ``T`` samples: pairs and the two column sets."""
    C = 6
    p0, p1 = _trajectory(T, C, seed)
    caps = [(f"link{i}", 0.03) for i in range(C)]
    shapes = _shapes(1)
    pairs = [(c, sh.name) for c, _ in caps for sh in shapes]
    pairs += [(f"link{i}", f"link{j}") for i in range(C) for j in range(i + 2, C)]
    own = [k for k, (_, b) in enumerate(pairs) if b.startswith("link")]
    env = [k for k, (_, b) in enumerate(pairs) if not b.startswith("link")]
    return P.ProximityKernel(caps, shapes, pairs), p0, p1, [env, own]


@pytest.mark.parametrize("batch", [1, 45, 1000])
def test_the_batch_size_changes_no_value(monkeypatch, batch):
    """The near entries are gathered, evaluated and filled BATCH at a time (bounded memory); every value is the
    same bit for bit whichever batch holds it: a batch of one block per slice, an odd size, and the default."""
    kern, p0, p1, sets = _long_case(700)
    reference = {far: kern.distances(p0, p1, far_m=far, exact_min_of=sets) for far in (0.05, np.inf)}
    monkeypatch.setattr(P, "BATCH", batch)
    monkeypatch.setattr(blocks_module, "BATCH", batch)
    for far, D in reference.items():
        np.testing.assert_array_equal(kern.distances(p0, p1, far_m=far, exact_min_of=sets), D)


@pytest.mark.parametrize("far", [0.1, np.inf])
def test_pruning_takes_no_more_memory_than_the_plain_kernel(far):
    """16,000 samples of 130 pairs (a 16.6 MB result), measured with tracemalloc: with far pairs pruned (and with
    ``far_m`` infinite, every block near and every value exact) the peak is no more than the plain kernel's, whose
    temporaries are bounded by its chunks (h28geo's batches held every near entry: 725 MB here with far_m infinite)."""
    kern, p0, p1, sets = _long_case(16000)

    def peak(**kwargs):
        tracemalloc.start()
        try:
            kern.distances(p0, p1, **kwargs)
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    plain, pruned = peak(), peak(far_m=far, exact_min_of=sets)
    assert pruned <= plain, (pruned, plain)
