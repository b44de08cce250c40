"""Critics judged chunk by chunk give the verdicts of the whole arrays, bit for bit, wherever the chunk edges fall.

The runs are simulated twice: stored (the whole arrays, judged in one chunk) and compact (frames, proximity and
object poses made per chunk, as a long run is), and the compact one is judged in chunks of many sizes.

Every built-in critic (joint_speed, space_usage, collision, end_effector_pose, pinch_point, task_outcome,
contact_speed, separation, payload) judges real simulated runs at 500 Hz (sorting_naive: collisions, speeding,
leaving the workspace; workbench_naive: a person, masses) with the run in one chunk (the whole arrays) and in
chunks of many sizes (Hypothesis), with chunk edges inside every flagged window and at every grasp and release
(the carried object attached in one chunk, released in the next). Thresholds are moved so that every critic has a
flagged window (and every branch: OK, WARNING, ERROR). A compact trajectory (frames, proximity and object poses
made per chunk) gives the report of the stored one.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import robocritics.pipeline as pipeline
import robocritics.trajectory as trajectory_module
from robocritics import Robot, Scene, critique, simulate
from robocritics.critic import BUILTIN_CRITICS, get_critics, resolve_params
from robocritics.critic.chunked import judge_in_chunks

PROGRAMS = Path(__file__).resolve().parents[1] / "examples" / "programs"
ALL = list(BUILTIN_CRITICS) + ["task_outcome", "contact_speed", "separation", "payload"]
#: Thresholds that flag wide windows (every critic's WARNING or ERROR branch), besides the defaults.
TIGHT = {
    "pinch_point": {"d_min_m": 0.07, "d_max_m": 0.3},
    "space_usage": {"warn_fraction": 0.05, "hull_tolerance_m": 0.002},
    "collision": {"d_warn_m": 0.09},  # distances are exact up to 0.10 m (planning.trace.EXACT_WITHIN_M)
    "joint_speed": {"warn_speed_m_s": 0.3, "max_speed_m_s": 0.6},
    "end_effector_pose": {"warn_speed_m_s": 0.05, "max_speed_m_s": 0.1},
    "contact_speed": {"near_m": 0.5, "warn_fraction": 0.05},
    "payload": {"warn_fraction": 0.2},
}
RUNS = {"sorting_naive": ("sorting", ["green_apple in white_box", "red_apple_1 in white_box"]), "workbench_naive": ("workbench", None)}


@pytest.fixture(scope="module")
def robot():
    return Robot.ur3e()


@pytest.fixture(scope="module")
def runs(robot):
    return {
        name: simulate((PROGRAMS / f"{name}.py").read_text(), Scene.builtin(scene), robot, sample_rate_hz=500)
        for name, (scene, _) in RUNS.items()
    }


@pytest.fixture(scope="module")
def compact_runs(robot):
    """The same runs stored compactly (as a run of more than CHUNK_SAMPLES samples is)."""
    mp = pytest.MonkeyPatch()
    mp.setattr(pipeline, "CHUNK_SAMPLES", 0)
    try:
        return {
            name: simulate((PROGRAMS / f"{name}.py").read_text(), Scene.builtin(scene), robot, sample_rate_hz=500)
            for name, (scene, _) in RUNS.items()
        }
    finally:
        mp.undo()


def report(execution, name: str, params, size: int | None = None, align: int | None = None):
    """The report of ``execution`` judged in chunks of ``size`` samples (None: the default, one chunk here)."""
    mp = pytest.MonkeyPatch()
    try:
        if size is not None:
            mp.setattr(trajectory_module, "CHUNK_SAMPLES", size)
        if align is not None:
            mp.setattr(trajectory_module, "CHUNK_ALIGN", align)
        return critique(execution, critics=ALL, params=params, goals=RUNS[name][1]).model_dump()
    finally:
        mp.undo()


def test_the_runs_fill_every_branch(runs):
    """The fixtures are worth testing on: both runs are one chunk by default, and the thresholds flag windows."""
    flags = set()
    for name, execution in runs.items():
        assert not execution.trajectory.compact and len(execution.trajectory) < trajectory_module.CHUNK_SAMPLES
        for params in ({}, TIGHT):
            for v in critique(execution, critics=ALL, params=params, goals=RUNS[name][1]).verdicts:
                flags.add((v.critic, v.flag.value))
    for critic in ("joint_speed", "space_usage", "collision", "end_effector_pose", "pinch_point"):
        assert {(critic, "WARNING"), (critic, "ERROR")} & flags, critic
    assert ("task_outcome", "ERROR") in flags and ("separation", "ERROR") in flags


@settings(max_examples=10)
@given(k=st.integers(1, 100), run=st.sampled_from(sorted(RUNS)), tight=st.booleans())
def test_any_chunk_size_gives_the_whole_arrays_verdicts(runs, compact_runs, k, run, tight):
    params = TIGHT if tight else {}
    assert report(compact_runs[run], run, params, size=64 * k) == report(runs[run], run, params)


def edges_that_matter(execution, verdicts) -> set[int]:
    """Samples where a chunk edge tests something: inside every flagged window, at every grasp and release."""
    out = set()
    for v in verdicts:
        e = v["evidence"]
        if e["first_sample"] is not None and e["last_sample"] - e["first_sample"] > 2:
            out.add((e["first_sample"] + e["last_sample"]) // 2)
            for a, b in e["sample_ranges"][:3]:
                out.update({a, a + 1, b})
    attached = execution.trajectory.attached
    out.update((np.flatnonzero(attached[1:] != attached[:-1]) + 1).tolist())  # first sample held / let go
    return {s for s in out if 1 < s < len(attached) - 1}


@pytest.mark.parametrize("run", sorted(RUNS))
def test_chunk_edges_inside_flagged_windows_and_at_grasps(runs, compact_runs, run):
    """A chunk edge exactly at each sample that matters (chunks aligned to 1 sample: the critics whose
    reductions need no block alignment), and within the 64-sample grid before it (every critic)."""
    execution, compact = runs[run], compact_runs[run]
    for params in ({}, TIGHT):
        whole = report(execution, run, params)
        edges = edges_that_matter(execution, whole["verdicts"])
        assert len(edges) >= 4
        for edge in sorted(edges)[:: max(1, len(edges) // 6)]:
            aligned = max(64, edge - edge % 64)
            assert report(compact, run, params, size=aligned) == whole, (run, edge)
            exact = report(compact, run, {**params, "space_usage": {"hull_tolerance_m": 0.0}}, size=edge, align=1)
            assert exact == report(execution, run, {**params, "space_usage": {"hull_tolerance_m": 0.0}}), (run, edge)


@pytest.mark.parametrize("run", sorted(RUNS))
def test_a_compact_trajectory_gives_the_stored_ones_report(runs, compact_runs, run):
    """The same run stored compactly (frames, proximity, object poses made per chunk) is judged the same."""
    compact, stored = compact_runs[run], runs[run]
    assert compact.trajectory.compact
    assert compact.trajectory.content_hash() == stored.trajectory.content_hash()
    np.testing.assert_array_equal(compact.trajectory.frames, stored.trajectory.frames)
    np.testing.assert_array_equal(compact.trajectory.proximity, stored.trajectory.proximity)
    assert set(compact.object_poses) == set(stored.object_poses)
    for oid in stored.object_poses:
        np.testing.assert_array_equal(compact.object_poses[oid], stored.object_poses[oid])
    for params in ({}, TIGHT):
        for size in (None, 1024, 4096):
            assert report(compact, run, params, size=size) == report(stored, run, params), (params, size)
        # a stored run (judged in one chunk by default) asked for chunks is judged the same too
        for verdict in critique(stored, critics=ALL, params=params, goals=RUNS[run][1]).verdicts:
            critic = get_critics()[verdict.critic]
            if hasattr(critic, "reduction"):
                chunked = judge_in_chunks(critic, stored, resolve_params(critic, params.get(critic.name)), size=1024)
                assert chunked == verdict, critic.name
