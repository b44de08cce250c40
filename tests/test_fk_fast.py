"""The structure-of-arrays FK (``Robot.forward``, ``forward_with_capsules``, ``capsule_segments``) and the
trajectory assembly against slow, obvious references: Pinocchio per sample, plain 4x4 products per sample,
``dict.fromkeys`` over every sample."""

import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from fk_reference import capsule_reference, pinocchio_frames

from robocritics import Robot, Scene
from robocritics.robot import model as model_module
from robocritics.geometry import proximity as prox
from robocritics.planning.trace import EXACT_WITHIN_M, _carried_ids, build_trajectory


@pytest.fixture(scope="module", params=["ur3e", "panda"])
def robot(request):
    # the UR3e's placements are signed permutations (the shortcut paths); the Panda's come from rpy angles
    return getattr(Robot, request.param)()


samples = st.integers(1, 12).flatmap(
    lambda T: st.tuples(
        arrays(np.float64, (T, 7), elements=st.floats(-2 * math.pi, 2 * math.pi, allow_nan=False)),
        st.one_of(
            st.none(),
            st.floats(0.0, 0.085),
            arrays(np.float64, (T,), elements=st.floats(0.0, 0.085)),
        ),
    )
)


@settings(max_examples=60, deadline=None)
@given(case=samples)
def test_frames_and_capsules_match_pinocchio_and_the_4x4_products(robot, case):
    q7, opening = case
    q = q7[:, : robot.n]
    per_sample = None if opening is None else np.broadcast_to(opening, (len(q),))
    frames, p0, p1 = robot.forward_with_capsules(q, opening)
    np.testing.assert_allclose(frames, pinocchio_frames(robot, q, per_sample), rtol=0, atol=1e-12)
    # the fused pass gives what forward() and capsule_segments() of its frames give, bit for bit
    np.testing.assert_array_equal(frames, robot.forward(q, opening))
    s0, s1 = robot.capsule_segments(frames)
    np.testing.assert_array_equal(p0, s0)
    np.testing.assert_array_equal(p1, s1)
    r0, r1 = capsule_reference(robot, frames)
    np.testing.assert_allclose(p0, r0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(p1, r1, rtol=0, atol=1e-12)


def test_layouts(robot):
    """frames are C-ordered (T, L, 4, 4) homogeneous transforms; capsule endpoints are (T, C, 3) views of
    (3, C, T) time series, the proximity kernel's layout (its transpose back is free)."""
    q = np.random.default_rng(1).uniform(robot.lower, robot.upper, size=(50, robot.n))
    frames, p0, p1 = robot.forward_with_capsules(q, 0.03)
    assert frames.shape == (50, len(robot.frame_names), 4, 4) and frames.flags.c_contiguous
    np.testing.assert_array_equal(frames[:, :, 3, :], np.broadcast_to([0.0, 0.0, 0.0, 1.0], (50, len(robot.frame_names), 4)))
    for p in (p0, p1):
        assert p.shape == (50, len(robot.capsules), 3)
        assert p.transpose(2, 1, 0).flags.c_contiguous
    single = robot.forward(q[7], 0.03)
    np.testing.assert_array_equal(single, frames[7])


def test_capsules_for_any_joint_axis():
    """Capsule endpoints from the fused pass with the Rodrigues and prismatic branches (joint axes that no
    bundled arm has) against the per-sample 4x4 chain."""
    robot = Robot.ur3e()
    motions = {2: ("revolute", np.array([0.3, -0.4, 0.866])), 4: ("prismatic", np.array([0.6, 0.0, -0.8]))}
    robot._joint_motion = [motions.get(j, m) for j, m in enumerate(robot._joint_motion)]
    q = np.random.default_rng(2).uniform(-3, 3, size=(20, robot.n))
    frames, p0, p1 = robot.forward_with_capsules(q)
    reference = np.empty_like(frames)
    for t in range(len(q)):
        joints = [np.eye(4)]
        for j in range(1, robot.model.njoints):
            kind, axis = robot._joint_motion[j]
            X = np.eye(4)
            if kind == "revolute":
                X[:3, :3] = pin.AngleAxis(q[t, j - 1], axis / np.linalg.norm(axis)).matrix()
            else:
                X[:3, 3] = q[t, j - 1] * axis
            joints.append(joints[robot._joint_parents[j]] @ robot._joint_placements[j] @ X)
        for f, (parent, placement) in enumerate(zip(robot._frame_parent, robot._frame_placement)):
            reference[t, f] = joints[parent] @ placement
    np.testing.assert_allclose(frames, reference, rtol=0, atol=1e-13)
    r0, r1 = capsule_reference(robot, reference)
    np.testing.assert_allclose(p0, r0, rtol=0, atol=1e-13)
    np.testing.assert_allclose(p1, r1, rtol=0, atol=1e-13)


@settings(max_examples=200, deadline=None)
@given(
    weights=st.lists(st.sampled_from([0.0, 1.0, -1.0, 0.25, -0.0921, 3.5e-17]), min_size=3, max_size=3),
    constant=st.lists(st.booleans(), min_size=3, max_size=3),
)
def test_combine_is_the_matrix_vector_product(weights, constant):
    rng = np.random.default_rng(3)
    columns = tuple(rng.normal(size=(3, 1 if c else 9)) for c in constant)
    w = np.array(weights)
    total = model_module._combine(columns, w)
    expected = sum(col * wk for col, wk in zip(columns, weights))
    if not np.any(w):
        assert total is None
    else:
        np.testing.assert_allclose(np.broadcast_to(total, np.broadcast(*columns).shape), np.broadcast_to(expected, np.broadcast(*columns).shape), rtol=1e-15, atol=1e-300)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from(["", "", "apple", "cup", "fork_1"]), max_size=40))
def test_carried_ids_in_order_of_first_appearance(attached):
    expected = [a for a in dict.fromkeys(attached) if a]
    assert _carried_ids(np.asarray(attached, dtype=str)) == expected


def test_build_trajectory_with_or_without_the_callers_frames_and_segments():
    """The same trajectory whether build_trajectory runs FK itself, is given frames, or frames and segments."""
    robot = Robot.ur3e()
    scene = Scene.builtin("sorting")
    rng = np.random.default_rng(4)
    T = 300
    q = robot.home_q + np.cumsum(rng.normal(scale=0.01, size=(T, robot.n)), axis=0)
    time = np.arange(T) / 125.0
    opening = np.linspace(0.085, 0.02, T)
    attached = np.where(np.arange(T) > 150, "green_apple", "")
    poses = np.broadcast_to(np.eye(4), (T, 4, 4)).copy()
    poses[:, :3, 3] = robot.forward(q, opening)[:, robot.tcp_index, :3, 3]
    kwargs = dict(gripper_opening_m=opening, attached=attached, object_poses={"green_apple": poses})
    frames, p0, p1 = robot.forward_with_capsules(q, opening)
    built = [
        build_trajectory(robot, scene, q, time, **kwargs),
        build_trajectory(robot, scene, q, time, frames=frames, **kwargs),
        build_trajectory(robot, scene, q, time, frames=frames, segments=(p0, p1), **kwargs),
    ]
    for other in built[1:]:
        np.testing.assert_array_equal(other.frames, built[0].frames)
        np.testing.assert_array_equal(other.proximity, built[0].proximity)
        assert other.pairs == built[0].pairs
    traj = built[0]
    assert traj.attached.dtype.kind == "U" and list(traj.attached) == list(attached)
    assert [p.name for p in traj.pairs if p.a == "green_apple"]  # the carried object's pairs are there
    assert traj.proximity.flags.f_contiguous and traj.proximity.shape == (T, len(traj.pairs))  # a column per pair
    # a container pair is the least over the container's shapes (floor and walls): against every shape
    # exactly, one kernel column each, then the minimum; exact up to EXACT_WITHIN_M, a larger bound beyond
    containers = {c.id: [s.name for s in c.shapes()] for c in scene.containers}
    checked = exact = 0
    for k, pair in enumerate(traj.pairs):
        if pair.b not in containers or pair.group_a == "attached":
            continue
        shapes = containers[pair.b]
        kernel = prox.ProximityKernel(
            [(n, float(r)) for n, r in zip(robot.capsule_names, robot.capsule_radii)],
            scene.shapes(),
            [(pair.a, shape) for shape in shapes],
        )
        expected = kernel.distances(p0, p1).min(axis=1)
        near = expected <= EXACT_WITHIN_M
        np.testing.assert_allclose(traj.proximity[near, k], expected[near], rtol=0, atol=1e-12)
        assert np.all(traj.proximity[~near, k] > EXACT_WITHIN_M)
        checked += len(shapes) > 1
        exact += int(near.sum())
    assert checked and exact


@pytest.mark.parametrize("block", [1, 7, 2000])
def test_frames_laid_out_block_by_block(robot, block, monkeypatch):
    """The (T, L, 4, 4) frames written a block of samples at a time (full blocks, a partial last one, blocks
    longer than the trajectory) are the frames written in one go, and Pinocchio's."""
    q = np.random.default_rng(5).uniform(robot.lower, robot.upper, size=(53, robot.n))
    opening = np.linspace(0.0, robot.max_opening_m, 53)
    whole = robot.forward(q, opening)
    monkeypatch.setattr(model_module, "_FRAME_BLOCK", block)
    blocked = robot.forward(q, opening)
    np.testing.assert_array_equal(blocked, whole)
    np.testing.assert_allclose(blocked, pinocchio_frames(robot, q, opening), rtol=0, atol=1e-12)


def test_zero_samples_give_empty_frames_and_capsules():
    robot = Robot.ur3e()
    n_frames, n_capsules = len(robot.frame_names), len(robot.capsule_names)
    assert robot.forward(np.zeros((0, robot.n))).shape == (0, n_frames, 4, 4)
    frames, p0, p1 = robot.forward_with_capsules(np.zeros((0, robot.n)), 0.05)
    assert frames.shape == (0, n_frames, 4, 4) and p0.shape == p1.shape == (0, n_capsules, 3)
