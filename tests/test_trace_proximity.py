"""Trajectory proximities agree with coal.distance on the same shapes (random configurations)."""

import coal
import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from robocritics import Robot, Scene
from robocritics.planning.trace import EXACT_WITHIN_M


@pytest.fixture(scope="module")
def robot():
    return Robot.ur3e()


def coal_shape(shape):
    if shape.kind == "box":
        return coal.Box(*shape.size)
    if shape.kind == "cylinder":
        return coal.Cylinder(shape.size[0], shape.size[1])
    return coal.Sphere(shape.size[0])


def tf(M):
    t = coal.Transform3s()
    t.setRotation(np.ascontiguousarray(M[:3, :3]))
    t.setTranslation(np.ascontiguousarray(M[:3, 3]))
    return t


def capsule_geometry(robot, name, frames):
    c = robot.capsules[robot.capsule_names.index(name)]
    F = frames[robot.frame_names.index(c.frame)]
    p0 = F[:3, :3] @ np.array(c.p0) + F[:3, 3]
    p1 = F[:3, :3] @ np.array(c.p1) + F[:3, 3]
    axis = p1 - p0
    z = axis / np.linalg.norm(axis)
    x = np.cross(z, [1.0, 0, 0]) if abs(z[0]) < 0.9 else np.cross(z, [0, 1.0, 0])
    x /= np.linalg.norm(x)
    M = np.eye(4)
    M[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    M[:3, 3] = (p0 + p1) / 2
    return coal.Capsule(c.radius_m, float(np.linalg.norm(axis))), tf(M)


def coal_distance(ga, ta, gb, tb):
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    req.gjk_tolerance = 1e-10
    return coal.distance(ga, ta, gb, tb, req, res)


@settings(max_examples=25, deadline=None)
@given(q=arrays(np.float64, (3, 6), elements=st.floats(-3.2, 3.2, allow_nan=False)), scene_name=st.sampled_from(["sorting", "breakfast", "recycling"]))
def test_every_pair_matches_coal(robot, q, scene_name):
    scene = Scene.builtin(scene_name)
    q = robot.home_q + 0.6 * q / 3.2  # around the working posture, where objects are near
    traj = robot.trajectory(q, np.arange(3) * 0.008, scene)
    shapes = scene.shapes()
    arm = [k for k, p in enumerate(traj.pairs) if p.kind == "environment" and p.group_a == "arm"]
    for t in range(3):
        refs = []
        for k, pair in enumerate(traj.pairs):
            ga, ta = capsule_geometry(robot, pair.a, traj.frames[t])
            if pair.kind == "self":
                gb, tb = capsule_geometry(robot, pair.b, traj.frames[t])
                refs.append(coal_distance(ga, ta, gb, tb))
            else:
                refs.append(min(coal_distance(ga, ta, coal_shape(s), tf(s.pose)) for s in shapes if s.owner == pair.b_entity))
        # exact within EXACT_WITHIN_M and within the arm's closest distance (a self pair: the closest self
        # distance); beyond, a lower bound beyond both
        own = [k for k, p in enumerate(traj.pairs) if p.kind == "self"]
        env_within = max(EXACT_WITHIN_M, min(refs[k] for k in arm))
        self_within = max(EXACT_WITHIN_M, min(refs[k] for k in own))
        for k, (pair, ref) in enumerate(zip(traj.pairs, refs)):
            ours = traj.proximity[t, k]
            exact_within = self_within if pair.kind == "self" else env_within
            if ref > exact_within:
                assert exact_within - 1e-6 < ours <= ref + 1e-9, (pair.name, t, ours, ref)
            elif ref > 1e-9:
                assert ours == pytest.approx(ref, abs=1e-6), (pair.name, t)
            else:
                assert ours <= 1e-9, (pair.name, t, ours, ref)  # touching or penetrating: never positive
        # so the closest environment distance of the arm (and of any set of pairs holding it) is exact, and so is
        # the closest self distance (the pinch-point critic's)
        assert traj.proximity[t, arm].min() == pytest.approx(min(refs[k] for k in arm), abs=1e-6)
        assert traj.proximity[t, own].min() == pytest.approx(min(refs[k] for k in own), abs=1e-6)


def test_carried_object_pairs_are_exact_near_and_bounded_far(robot):
    """A carried cup's distances are exact within EXACT_WITHIN_M and the arm's closest distance, lower bounds beyond."""
    from robocritics import simulate

    execution = simulate(
        "move_above(coffee_cup, 0.05)\nmove_linear(coffee_cup.x, coffee_cup.y, coffee_cup.top - 0.03)\n"
        "close_gripper()\nmove_up(0.12)\n",
        Scene.builtin("recycling"),
    )
    traj = execution.trajectory
    cols = [k for k, p in enumerate(traj.pairs) if p.group_a == "attached"]
    assert cols, "carrying the cup adds cup-vs-scene pairs"
    cup = next(s for s in execution.scene.shapes() if s.owner == "coffee_cup")
    tcp = traj.tcp
    held = np.flatnonzero(traj.attached == "coffee_cup")
    offset = np.linalg.inv(tcp[held[0]]) @ cup.pose
    arm = [k for k, p in enumerate(traj.pairs) if p.kind == "environment" and p.group_a == "arm"]
    checked = {"exact": 0, "bound": 0}
    for t in held[:: max(1, len(held) // 6)]:
        # the arm's own distances at t are exact up to its closest one (test_every_pair_matches_coal)
        exact_within = max(EXACT_WITHIN_M, traj.proximity[t, arm].min())
        pose = tcp[t] @ offset
        for k in cols:
            ref = min(
                coal_distance(coal_shape(cup), tf(pose), coal_shape(s), tf(s.pose))
                for s in execution.scene.shapes()
                if s.owner == traj.pairs[k].b_entity
            )
            if ref <= exact_within:
                assert traj.proximity[t, k] == pytest.approx(ref, abs=1e-6)
                checked["exact"] += 1
            else:
                assert exact_within < traj.proximity[t, k] <= ref + 1e-9
                checked["bound"] += 1
    assert checked["exact"] and checked["bound"]


def test_long_trajectory_frames_match_pinocchio(robot):
    """The batched FK (element-wise column products, no BLAS) of a trajectory past OpenBLAS's threading
    threshold gives Pinocchio's frames, every frame at samples spread over it, fingers slid by the opening."""
    rng = np.random.default_rng(5)
    T = 20_000
    q = rng.uniform(robot.lower, robot.upper, size=(T, robot.n))
    frames = robot.forward(q)
    assert frames.shape == (T, len(robot.frame_names), 4, 4)
    for t in np.linspace(0, T - 1, 9).astype(int):
        pin.forwardKinematics(robot.model, robot.data, q[t])
        pin.updateFramePlacements(robot.model, robot.data)
        for i, name in enumerate(robot.frame_names):
            ref = robot.data.oMf[robot.model.getFrameId(name)].homogeneous
            np.testing.assert_allclose(frames[t, i], ref, rtol=0, atol=1e-12)
    opening = rng.uniform(0.0, robot.max_opening_m, size=T)
    slid = robot.forward(q, opening)
    moved = [robot.frame_names.index(f) for f in robot.finger_links]
    still = [i for i in range(len(robot.frame_names)) if i not in moved]
    np.testing.assert_array_equal(slid[:, still], frames[:, still])
    gap = np.linalg.norm(slid[:, moved[0], :3, 3] - slid[:, moved[1], :3, 3], axis=1)
    full = np.linalg.norm(frames[:, moved[0], :3, 3] - frames[:, moved[1], :3, 3], axis=1)
    np.testing.assert_allclose(full - gap, robot.max_opening_m - opening, atol=1e-12)


def _forward_4x4(robot, q):
    """The plain reference: per sample, per joint, parent @ placement @ joint motion as 4x4 products."""
    T = len(q)
    frames = np.empty((T, len(robot.frame_names), 4, 4))
    for t in range(T):
        oMi = [np.eye(4)]
        for j in range(1, robot.model.njoints):
            kind, axis = robot._joint_motion[j]
            X = np.eye(4)
            if kind == "revolute":
                k = axis / np.linalg.norm(axis)
                K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
                X[:3, :3] = np.eye(3) + np.sin(q[t, j - 1]) * K + (1 - np.cos(q[t, j - 1])) * (K @ K)
            else:
                X[:3, 3] = q[t, j - 1] * axis
            oMi.append(oMi[robot._joint_parents[j]] @ robot._joint_placements[j] @ X)
        for f, (parent, placement) in enumerate(zip(robot._frame_parent, robot._frame_placement)):
            frames[t, f] = oMi[parent] @ placement
    return frames


@pytest.mark.parametrize(
    "motions",
    [
        {},  # the UR3e as it is: every joint about +z
        {2: ("revolute", np.array([1.0, 0.0, 0.0])), 4: ("revolute", np.array([0.0, -1.0, 0.0]))},
        {3: ("revolute", np.array([0.3, -0.4, 0.866])), 5: ("revolute", np.array([0.0, 0.0, -1.0]))},
        {1: ("prismatic", np.array([0.0, 0.0, 1.0])), 6: ("prismatic", np.array([0.6, 0.0, -0.8]))},
    ],
)
def test_batched_fk_matches_the_plain_4x4_products_for_any_joint_axis(motions):
    """The batched FK's branches (z rotations as column mixes, other axes by Rodrigues, prismatic joints)
    against the plain per-sample 4x4 product chain."""
    robot = Robot.ur3e()
    robot._joint_motion = [motions.get(j, m) for j, m in enumerate(robot._joint_motion)]
    q = np.random.default_rng(len(motions)).uniform(-3, 3, size=(25, robot.n))
    np.testing.assert_allclose(robot.forward(q), _forward_4x4(robot, q), rtol=0, atol=1e-13)
