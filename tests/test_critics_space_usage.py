"""space_usage: convex hull of the swept link points against the allowed workspace."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import ConvexHull
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from critic_asserts import assert_matches_reference, assert_well_formed, critic, run, execution_of
from critic_reference import ref_space_usage
from robocritics.critic import Flag
from robocritics.critic.builtin.space_usage import hull_points, hull_volume, volume_error_bound
from robocritics.scene import Scene, Workspace
from robocritics.robot.model import default_workspace
from strategies import trajectories
from synth import make_trajectory, realistic_trajectory

CENTRE = np.array([0.0, 0.0, 0.15185])


def circle(radius, z=0.15185, samples=200, frames=1):
    """Frames moving on a horizontal circle around the shoulder."""
    a = np.linspace(0, 2 * math.pi, samples)
    pos = np.stack([radius * np.cos(a), radius * np.sin(a), np.full_like(a, z)], axis=-1)
    pos = np.repeat(pos[:, None, :], frames, axis=1)
    for f in range(1, frames):
        pos[:, f, 2] += 0.05 * f
    return make_trajectory(np.linspace(0, 4, samples), pos)


def test_point_leaving_the_sphere_errs_naming_link_and_sample():
    time = np.linspace(0, 1, 101)
    pos = np.zeros((101, 3, 3)) + CENTRE
    pos[:, 1, 0] = np.linspace(0.1, 0.55, 101)  # link_1 ends 5 cm outside the 0.5 m sphere
    traj = make_trajectory(time, pos, frame_names=("base_link", "forearm_link", "tcp"))
    v = run("space_usage", traj, Scene())
    assert v.flag is Flag.ERROR
    assert v.value == pytest.approx(0.05)
    assert v.unit == "m" and v.threshold == 0.0
    assert "forearm_link" in v.message and "sample 100" in v.message and "5.0 cm outside" in v.message
    first = int(np.argmax(pos[:, 1, 0] > 0.5))
    assert v.evidence.first_sample == first and v.evidence.last_sample == 100
    assert v.evidence.links == ["forearm_link"]
    assert_well_formed(v, "space_usage")


def test_large_sweep_warns_small_one_is_ok():
    scene = Scene()
    # a solid cylinder of radius 0.44 and height 0.44 inside the sphere: 0.268 m^3 = 51 % of 0.524 m^3
    z0 = 0.15185 - 0.22
    big = circle(0.44, z=z0, frames=2)
    frames = big.frames.copy()
    frames[:, 1, 2, 3] = z0 + 0.44
    big = make_trajectory(big.time, frames=frames, frame_names=("link_0", "tcp"))
    v = run("space_usage", big, scene)
    assert v.flag is Flag.WARNING, v.message
    assert v.value == pytest.approx(math.pi * 0.44**2 * 0.44, rel=0.01)
    assert v.threshold == pytest.approx(0.5 * (scene.workspace or default_workspace()).volume_m3)
    assert "%" in v.message and v.unit == "m³"
    assert_well_formed(v, "space_usage")
    small = circle(0.2, frames=2)
    v = run("space_usage", small, scene)
    assert v.flag is Flag.OK


def test_degenerate_point_sets_have_zero_volume():
    assert hull_volume(np.zeros((0, 3)))[0] == 0.0
    assert hull_volume(np.zeros((3, 3)))[0] == 0.0
    flat = np.random.default_rng(0).uniform(-1, 1, (50, 3))
    flat[:, 2] = 0.1
    assert hull_volume(flat)[0] == 0.0
    v = run("space_usage", circle(0.3))  # one frame on a circle: a flat disc
    assert v.flag is Flag.OK and v.value == 0.0


def test_decimated_hull_is_within_its_error_bound_of_the_exact_hull():
    traj = realistic_trajectory(duration_s=6.0, rate_hz=500.0, seed=3, n_waypoints=4)
    X = np.ascontiguousarray(traj.frames[:, :, :3, 3])
    exact, _, _ = hull_volume(hull_points(X, 0.0)[0])
    for tol in (1e-4, 5e-4, 2e-3):
        P, ti, li = hull_points(X, tol)
        assert len(P) < X.shape[0] * X.shape[1] / 2
        vol, area, _ = hull_volume(P)
        bound = volume_error_bound(P, area, tol)
        assert vol <= exact + 1e-12
        assert exact - vol <= bound
        np.testing.assert_array_equal(P, X[ti, li])
        # every point, dropped or not, lies within tol of the kept hull (facet distances)
        eq = ConvexHull(P).equations
        beyond = (X.reshape(-1, 3) @ eq[:, :3].T + eq[:, 3]).max(axis=1)
        assert beyond.max() <= tol + 1e-12


def test_workspace_outside_distance_matches_a_per_point_reference():
    """The component-wise formula against |p - c| - r evaluated point by point with math.dist."""
    ws = Workspace(center=(0.1, -0.2, 0.3), radius_m=0.4)
    X = np.random.default_rng(1).uniform(-1, 1, (50, 4, 3))
    X[0, 0] = ws.center  # the centre: -r
    X[0, 1] = np.array(ws.center) + [0.4, 0.0, 0.0]  # on the sphere: 0
    expected = np.array([[math.dist(p, ws.center) - ws.radius_m for p in row] for row in X.tolist()])
    got = ws.outside_distance(X)
    assert got.shape == (50, 4)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    assert got[0, 0] == pytest.approx(-0.4) and got[0, 1] == pytest.approx(0.0, abs=1e-12)
    assert float(ws.outside_distance([0.1, -0.2, 1.0])) == pytest.approx(0.3)  # a single point


def test_critic_uses_a_custom_workspace_method():
    class Box(Workspace):
        def outside_distance(self, points):
            return np.asarray(points)[..., 0] - 0.1  # everything beyond x = 0.1 is outside

    scene = Scene().model_copy(update={"workspace": Box(**default_workspace().model_dump())})
    v = run("space_usage", circle(0.3), scene)
    assert v.flag is Flag.ERROR and v.value == pytest.approx(0.2)


@st.composite
def params(draw):
    return {
        "warn_fraction": draw(st.sampled_from([0.0005, 0.005, 0.05, 0.5])),
        "outside_tolerance_m": draw(st.sampled_from([0.0, 0.1, 0.5])),
        "hull_tolerance_m": draw(st.sampled_from([0.0, 1e-4, 1e-3])),
    }


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(traj=trajectories(max_samples=80), overrides=params(), radius=st.sampled_from([0.3, 0.5, 0.8]))
def test_agrees_with_the_per_sample_reference(traj, overrides, radius):
    scene = Scene(workspace=default_workspace().model_copy(update={"radius_m": radius}))
    c = critic("space_usage")
    p = c.Params(**overrides)
    v = c.check(execution_of(traj, scene), p)
    ref = ref_space_usage(traj, scene, p)
    assert_well_formed(v, "space_usage")
    if ref["flag"] is Flag.ERROR:
        assert_matches_reference(v, ref)
        return
    # the volume may be under-estimated by at most the decimation bound
    bound = v.details["volume_error_bound_m3"] + 1e-12 * max(1.0, ref["volume"])
    assert ref["volume"] - bound <= v.value <= ref["volume"] + 1e-9 * max(1.0, ref["volume"])
    limit = p.warn_fraction * (scene.workspace or default_workspace()).volume_m3
    if abs(ref["volume"] - limit) > bound:
        assert v.flag is ref["flag"]


def hull_points_reference(X, tol):
    """The docstring's rule, one frame and one block at a time: the largest second-difference norm M of the
    block gives the stride s (the largest power of two <= 64 with M s^2 / 8 <= tol) and every s-th sample of
    the block is kept, frame after frame; then each frame's last sample, where its last block's stride skipped
    it, closes its last chord; last, a point equal to the one before it in that order goes."""
    from robocritics.critic.builtin.space_usage import BLOCK

    T, L, _ = X.shape
    kept, closing = [], []
    for frame in range(L):
        p = X[:, frame]
        second = np.zeros(T)
        second[1:-1] = [math.sqrt(float(((p[t + 1] - 2 * p[t] + p[t - 1]) ** 2).sum())) for t in range(1, T - 1)]
        for start in range(0, T, BLOCK):
            M = second[start : start + BLOCK].max()
            stride = 1
            while stride < BLOCK and M * (2 * stride) ** 2 / 8 <= tol:
                stride *= 2
            kept += [(t, frame) for t in range(start, min(start + BLOCK, T), stride)]
        if kept[-1] != (T - 1, frame):
            closing.append((T - 1, frame))
    out = []
    for t, frame in kept + closing:
        if not out or not np.array_equal(X[t, frame], X[out[-1]]):
            out.append((t, frame))
    return out


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 2**32 - 1),
    T=st.integers(3, 300),
    L=st.integers(1, 4),
    tol=st.sampled_from([1e-6, 5e-4, 1e-2]),
    still=st.booleans(),
)
def test_hull_points_follow_the_stride_rule(seed, T, L, tol, still):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, T)[:, None, None]
    X = 0.3 * np.sin(rng.uniform(0.5, 20, size=(1, L, 3)) * t + rng.uniform(0, 6, size=(1, L, 3)))
    X += rng.normal(scale=rng.choice([0.0, 1e-5, 1e-3]), size=X.shape)
    if still:  # a frame that does not move: its repeated points are kept once
        X[:, 0] = X[0, 0]
    X = np.ascontiguousarray(X)
    P, ti, li = hull_points(X, tol)
    np.testing.assert_array_equal(P, X[ti, li])
    assert list(zip(ti.tolist(), li.tolist())) == hull_points_reference(X, tol)
