"""Trajectory: validation, lossless JSON, per-sample states, content hash."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics import Robot, Scene, Trajectory, TrajectoryError, simulate


@pytest.fixture(scope="module")
def execution():
    return simulate("move_to(0.3, 0.1, 0.2)\nmove_down(0.05)\nclose_gripper()\n", Scene.builtin("sorting"))


def test_shapes_and_provenance(execution):
    traj = execution.trajectory
    T = len(traj)
    assert traj.q.shape == (T, 6)
    assert traj.frames.shape == (T, len(traj.frame_names), 4, 4)
    assert traj.proximity.shape == (T, len(traj.pairs))
    assert {p.kind for p in traj.pairs} == {"self", "environment"}
    assert np.all(np.diff(traj.time) > 0)
    assert [traj.steps[i].line for i in np.unique(traj.step)] == [1, 2, 3]
    assert traj.lines() == [1, 2, 3]


def test_json_round_trip_is_lossless(execution):
    traj = execution.trajectory
    back = Trajectory.from_json(traj.to_json())
    for name in ("q", "time", "frames", "proximity", "gripper_opening_m", "step"):
        assert np.array_equal(getattr(back, name), getattr(traj, name)), name
    assert back.pairs == traj.pairs and back.steps == traj.steps and back.limits == traj.limits
    assert back.content_hash() == traj.content_hash()


def test_states_are_views(execution):
    traj = execution.trajectory
    states = list(traj.states)
    assert len(states) == len(traj)
    s = states[7]
    assert s.index == 7 and s.tau == traj.time[7]
    assert np.shares_memory(s.J, traj.q) and np.array_equal(s.P, traj.proximity[7])


def _kwargs(T=4):
    robot = Robot.ur3e()
    q = np.tile(robot.home_q, (T, 1))
    return dict(
        q=q,
        time=np.arange(T) * 0.01,
        frames=robot.forward(q),
        frame_names=robot.frame_names,
        proximity=np.zeros((T, 0)),
        pairs=[],
        gripper_opening_m=np.full(T, 0.085),
        attached=[""] * T,
        step=np.zeros(T, int),
        steps=[],
        limits=robot.limits,
    )


@pytest.mark.parametrize(
    "patch, words",
    [
        ({"time": np.array([0.0, 0.01, 0.01, 0.02])}, "time must increase strictly: sample 2"),
        ({"q": np.full((4, 6), np.nan)}, "q is not finite at index (0, 0)"),
        ({"gripper_opening_m": np.zeros(3)}, "gripper_opening_m has 3 samples but q has 4"),
        ({"frames": np.zeros((4, 2, 4, 4))}, "frames hold 2 frames"),
        ({"step": np.array([0, 0, 1, 0])}, "step indices given without steps"),
        ({"tcp_frame": "fingertips"}, "the TCP frame 'fingertips' is not one of the frames (base_link"),
    ],
)
def test_validation_names_the_problem(patch, words):
    with pytest.raises(TrajectoryError) as info:
        Trajectory(**{**_kwargs(), **patch})
    assert words in str(info.value)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-3, 3), min_size=6, max_size=6), st.floats(1e-6, 1e-3))
def test_hash_binds_the_motion(values, nudge):
    kw = _kwargs()
    kw["q"] = np.tile(values, (4, 1))
    a = Trajectory(**kw)
    kw["q"] = kw["q"].copy()
    kw["q"][2, 1] += nudge
    assert Trajectory(**kw).content_hash() != a.content_hash()


def test_the_tcp_frame_is_the_robots_and_survives_the_round_trip(execution):
    traj = execution.trajectory
    assert traj.tcp_frame == execution.robot.tcp_frame
    # a robot whose TCP frame has another name: the trajectory says which frame it is
    kwargs = _kwargs()
    names = list(kwargs["frame_names"])
    names[names.index("tcp")] = "fingertips"
    other = Trajectory(**{**kwargs, "frame_names": names, "tcp_frame": "fingertips"})
    np.testing.assert_array_equal(other.tcp, kwargs["frames"][:, names.index("fingertips")])
    back = Trajectory.from_json(other.to_json())
    assert back.tcp_frame == "fingertips" and back.slice(0, 2).tcp_frame == "fingertips"


def test_positions_are_the_frame_origins_shared_read_only_and_not_pickled(execution):
    import pickle

    traj = Trajectory.from_json(execution.trajectory.to_json())  # a fresh one: nothing cached yet
    pos = traj.positions
    np.testing.assert_array_equal(pos, traj.frames[:, :, :3, 3])
    assert pos.flags.c_contiguous and not pos.flags.writeable
    assert traj.positions is pos  # one copy for every critic
    with pytest.raises(ValueError):
        pos[0, 0, 0] = 1.0
    blob = pickle.dumps(traj)
    assert len(blob) == len(pickle.dumps(Trajectory.from_json(traj.to_json())))  # the cache is not shipped
    again = pickle.loads(blob)
    assert "_positions" not in again.__dict__
    np.testing.assert_array_equal(again.positions, pos)
    assert again.content_hash() == traj.content_hash()
    part = traj.slice(3, 10)
    np.testing.assert_array_equal(part.positions, pos[3:10])


def test_position_planes_are_the_positions_transposed_kept_read_only_and_not_pickled(execution):
    import pickle

    traj = Trajectory.from_json(execution.trajectory.to_json())  # a fresh one: nothing cached yet
    planes = traj.position_planes
    np.testing.assert_array_equal(planes, np.asarray(traj.frames[:, :, :3, 3]).transpose(2, 1, 0))
    assert "_positions" not in traj.__dict__  # gathered from the frames, not through the positions copy
    assert planes.flags.c_contiguous and not planes.flags.writeable
    assert traj.position_planes is planes  # judged again: not transposed again
    with pytest.raises(ValueError):
        planes[0, 0, 0] = 1.0
    blob = pickle.dumps(traj)
    assert len(blob) == len(pickle.dumps(Trajectory.from_json(traj.to_json())))  # the cache is not shipped
    again = pickle.loads(blob)
    assert "_position_planes" not in again.__dict__
    np.testing.assert_array_equal(again.position_planes, planes)
    np.testing.assert_array_equal(traj.slice(3, 10).position_planes, planes[:, :, 3:10])


def _content_hash_reference(traj):
    """The hash written plainly: each array's little-endian bytes, then every sample's held-object id joined by NUL."""
    import hashlib

    h = hashlib.sha256()
    for arr in (traj.q, traj.time, traj.gripper_opening_m):
        h.update(np.ascontiguousarray(arr, dtype="<f8").tobytes())
    h.update("\x00".join(traj.attached.tolist()).encode())
    h.update(",".join(traj.limits.joint_names).encode())
    return h.hexdigest()


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.lists(st.sampled_from(["", "apple", "cup_é", "a\x00b", "apple2"]), min_size=1, max_size=12))
def test_content_hash_is_the_plain_per_sample_hash(attached):
    kw = _kwargs(len(attached))
    kw["attached"] = attached
    traj = Trajectory(**kw)
    assert traj.content_hash() == _content_hash_reference(traj)


def test_content_hash_is_kept_and_follows_the_content():
    """The hash is computed once, and nothing that changes the hashed content keeps the old one: a view of the
    caller's writeable array is copied (writing into the caller's array changes nothing), assigning another array
    is hashed again, and an unpickled trajectory is frozen again."""
    import pickle

    kw = _kwargs(6)
    big = np.tile(kw["q"], (1, 2))  # the caller's writeable array; q is a view of it
    kw["q"] = big[:, :6]
    traj = Trajectory(**kw)
    first = traj.content_hash()
    assert traj.content_hash() is first  # kept, not recomputed
    big[2, 0] += 0.5  # the caller writes into its own array
    assert traj.content_hash() == _content_hash_reference(traj) == first
    with pytest.raises(ValueError):
        traj.q[0, 0] = 1.0  # read-only
    moved = traj.q.copy()
    moved[3, 1] += 0.25
    traj.q = moved
    assert traj.content_hash() == _content_hash_reference(traj) != first
    back = pickle.loads(pickle.dumps(traj))
    assert not back.q.flags.writeable and back.content_hash() == traj.content_hash()
    piece = back.slice(1, 4)  # views of read-only memory: not copied
    assert np.shares_memory(piece.q, back.q) and piece.content_hash() == _content_hash_reference(piece)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([1e308, -1e308, 1.7e308])),
        min_size=1,
        max_size=40,
    )
)
def test_finiteness_check_raises_exactly_where_a_value_is_not_finite(values):
    from robocritics.trajectory import _array

    arr = np.array(values)
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        with pytest.raises(TrajectoryError, match=rf"not finite at index \({bad[0]},\)"):
            _array("proximity", arr)
    else:  # finite values whose sum overflows (1e308 + 1e308) are still accepted
        assert np.array_equal(_array("proximity", arr), arr)


# --- compact trajectories (a long motion's form) ------------------------------------------------------------

CARRY = (
    "move_above(red_apple_1, 0.1)\nmove_linear(red_apple_1.x, red_apple_1.y, red_apple_1.z)\nclose_gripper()\n"
    "move_up(0.1)\nmove_to(0.3, -0.1, 0.2)\nopen_gripper()\nmove_up(0.05)\n"
)


@pytest.fixture(scope="module")
def stored_and_compact():
    import robocritics.pipeline as pipeline

    scene = Scene.builtin("sorting")
    stored = simulate(CARRY, scene, sample_rate_hz=500)
    mp = pytest.MonkeyPatch()
    mp.setattr(pipeline, "CHUNK_SAMPLES", 0)  # every motion compact
    try:
        compact = simulate(CARRY, scene, sample_rate_hz=500)
    finally:
        mp.undo()
    return stored, compact


def test_a_compact_trajectory_computes_what_a_stored_one_holds(stored_and_compact):
    stored, compact = stored_and_compact
    a, b = stored.trajectory, compact.trajectory
    assert b.compact and not a.compact and len(a) == len(b) > 1000
    assert a.content_hash() == b.content_hash() and a.pairs == b.pairs
    np.testing.assert_array_equal(a.frames, b.frames)
    np.testing.assert_array_equal(a.proximity, b.proximity)
    assert list(a.attached) == list(b.attached) and set(b.attached) == {"", "red_apple_1"}
    np.testing.assert_array_equal(a.positions, b.positions)
    idx = np.array([0, 7, 500, len(a) - 1])
    np.testing.assert_array_equal(b.frames_at(idx), a.frames[idx])
    for oid in stored.object_poses:
        assert oid in compact.object_poses
        np.testing.assert_array_equal(compact.object_poses[oid], stored.object_poses[oid])
        np.testing.assert_array_equal(compact.object_poses.at(oid, idx), stored.object_poses[oid][idx])
    assert "green_apple" not in compact.object_poses


@settings(max_examples=20)
@given(k=st.integers(1, 40), halo=st.integers(0, 2), a=st.integers(0, 1500), n=st.integers(1, 300))
def test_chunks_cover_every_sample_once_with_the_whole_runs_rows(stored_and_compact, k, halo, a, n):
    stored, compact = stored_and_compact
    whole, b = stored.trajectory, compact.trajectory
    size = 64 * k
    seen = np.zeros(len(b), dtype=int)
    for chunk in b.chunks(size, halo=halo):
        piece = chunk.trajectory
        assert chunk.start % 64 == 0 and chunk.lo == max(chunk.start - halo, 0)
        assert len(piece) == min(chunk.stop + halo, len(b)) - chunk.lo
        seen[chunk.start : chunk.stop] += 1
        rows = slice(chunk.lo, chunk.lo + len(piece))
        np.testing.assert_array_equal(piece.frames, whole.frames[rows])
        np.testing.assert_array_equal(piece.time, whole.time[rows])
        # proximity is the whole run's wherever it is exact (up to 0.10 m, planning.trace.EXACT_WITHIN_M, and the
        # arm's closest distance); beyond, a far pair's value is some lower bound above 0.10 m in both
        near = whole.proximity[rows] <= 0.10
        np.testing.assert_array_equal(piece.proximity[near], whole.proximity[rows][near])
        assert np.all(piece.proximity[~near] > 0.10)
        arm = [k for k, p in enumerate(whole.pairs) if p.kind == "environment" and p.group_a == "arm"]
        np.testing.assert_array_equal(piece.proximity[:, arm].min(axis=1), whole.proximity[rows][:, arm].min(axis=1))
        for oid, poses in chunk.object_poses.items():
            np.testing.assert_array_equal(poses, stored.object_poses[oid][rows])
    assert np.all(seen == 1)
    # any slice: frames exact; proximity exact up to 0.10 m
    a = min(a, len(b) - 1)
    piece, ref = b.slice(a, a + n), whole.slice(a, a + n)
    np.testing.assert_array_equal(piece.frames, ref.frames)
    near = ref.proximity <= 0.10
    np.testing.assert_array_equal(piece.proximity[near], ref.proximity[near])
    assert piece.content_hash() == ref.content_hash()


def test_a_compact_trajectory_pickles_and_gives_its_states(stored_and_compact):
    import pickle

    stored, compact = stored_and_compact
    back = pickle.loads(pickle.dumps(compact))
    assert back.trajectory.compact
    np.testing.assert_array_equal(back.trajectory.proximity, stored.trajectory.proximity)
    states = list(compact.trajectory.states)
    assert len(states) == len(stored.trajectory)
    np.testing.assert_array_equal(states[333].F, stored.trajectory.frames[333])
    np.testing.assert_array_equal(states[-1].P, stored.trajectory.proximity[-1])
    with pytest.raises(TrajectoryError, match="multiple of 64"):
        next(compact.trajectory.chunks(100))


def test_the_deploy_gate_rehashes_a_motion_written_behind_the_kept_hash():
    """The kept content hash follows assignment; code that turns a sample array's write flag back on and writes
    to it is not seen by the kept hash, so the gate hashes again (``recompute=True``) and refuses the motion."""
    from robocritics import Robot, Scene, critique, simulate
    from robocritics.deploy.gate import check_report

    execution = simulate("lib.move_to(0.3, 0.1, 0.2)\n", Scene.builtin("sorting"), Robot.ur3e())
    report = critique(execution)
    traj = execution.trajectory
    kept = traj.content_hash()
    traj.q.setflags(write=True)
    traj.q[-1, 0] += 0.01
    assert traj.content_hash() == kept  # the kept hash cannot see it
    assert traj.content_hash(recompute=True) != kept
    assert "hash_mismatch" in [reason[0] for reason in check_report(traj, report, allow_errors=True)]
