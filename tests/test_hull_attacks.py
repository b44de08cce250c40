"""robot.hull under hostile point sets: never a crash, never a wrong volume.

coal's Qhull segfaults on any input that makes Qhull print (an error such as "initial simplex is flat" or a
precision warning), so every candidate here runs in a child interpreter: a regression fails the test with the
candidate's name instead of killing pytest. The reference is scipy's Qhull on the points moved by one of them
(exact for a set far from the origin: the subtraction is Sterbenz-exact), which is how scipy stays accurate
there; without the move scipy, like coal, loses the digits to the offset.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial import ConvexHull, QhullError

from robocritics.geometry.hull import _EPS, convex_hull, quickhull

#: The child: for each line "path" on stdin, the hull of np.load(path) by both implementations, as one JSON line.
WORKER = r"""
import json, sys
import numpy as np
from robocritics.geometry.hull import convex_hull, quickhull
print("ready", flush=True)
for line in sys.stdin:
    P = np.load(line.strip())
    out = {}
    for f in (convex_hull, quickhull):
        h = f(P)
        out[f.__name__] = [h.volume_m3, h.area_m2, h.vertices.tolist()]
    print(json.dumps(out), flush=True)
"""


class Child:
    """A long-lived interpreter computing hulls, restarted after it dies (one import for many candidates)."""

    def __init__(self) -> None:
        self.dir = Path(tempfile.mkdtemp(prefix="hull-attacks-"))
        self.n = 0
        self.proc: subprocess.Popen | None = None

    def _start(self) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-c", WORKER], stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        assert self.proc.stdout.readline().strip() == "ready", self.proc.stderr.read()

    def hull(self, P: np.ndarray) -> dict:
        if self.proc is None or self.proc.poll() is not None:
            self._start()
        self.n += 1
        path = self.dir / f"{self.n}.npy"
        np.save(path, P)
        self.proc.stdin.write(f"{path}\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            code = self.proc.wait()
            self.proc = None
            pytest.fail(f"the hull process died (exit code {code}) on {len(P)} points saved in {path}")
        return json.loads(line)

    def close(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.stdin.close()
            self.proc.wait(timeout=30)


@pytest.fixture(scope="module")
def child():
    c = Child()
    yield c
    c.close()


def reference(P: np.ndarray) -> tuple[float, float] | None:
    """scipy's (volume, area) of the points moved by ``P[0]``; None where scipy finds the set flat."""
    try:
        h = ConvexHull(P - P[0])
    except QhullError:
        return None
    return h.volume, h.area


def tolerance(P: np.ndarray, volume: float, area: float) -> float:
    """How far, m^3, a volume may be from scipy's: rounding relative to the volume, points within _EPS (of the
    extent) of a facet's plane that quickhull treats as on it (at most that distance times the area), and
    slivers' rounding (1e-12 of the bounding cube)."""
    extent = float(np.max(P.max(axis=0) - P.min(axis=0)))
    return 1e-9 * volume + 4 * _EPS * extent * area + 1e-12 * extent**3


def agree(P: np.ndarray, got: dict) -> None:
    ref = reference(P)
    if ref is None:  # flat to scipy: no volume to speak of
        extent = float(np.max(P.max(axis=0) - P.min(axis=0)))
        for name, (volume, _, _) in got.items():
            assert 0 <= volume <= 1e-12 * extent**3, name
        return
    extent = float(np.max(P.max(axis=0) - P.min(axis=0)))
    for name, (volume, area, _) in got.items():
        assert volume == pytest.approx(ref[0], abs=tolerance(P, *ref)), name
        if volume == 0:  # thinner than _EPS: the empty hull, though scipy counts both sides of the sheet
            continue
        # the area of a needle (slivers whose planes decide nothing) is only good to ~1e-8 of the bounding square
        assert area == pytest.approx(ref[1], rel=1e-6, abs=1e-7 * extent**2), name


rng = np.random.default_rng(5)


def slab(n: int, thickness: float) -> np.ndarray:
    return np.c_[rng.uniform(-1, 1, size=(n, 2)), thickness * rng.uniform(-1, 1, size=n)]


def grid(m: int) -> np.ndarray:
    g = np.linspace(-1, 1, m)
    return np.stack(np.meshgrid(g, g, g), axis=-1).reshape(-1, 3)


def box_faces(n: int, jitter: float) -> np.ndarray:
    P = rng.uniform(-1, 1, size=(n, 3))
    P[np.arange(n), rng.integers(0, 3, n)] = rng.choice([-1.0, 1.0], n)
    return P + jitter * rng.normal(size=P.shape)


def fan(n: int) -> np.ndarray:
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.r_[np.c_[np.cos(a), np.sin(a), np.zeros(n)], [[0, 0, 1.0], [0, 0, -0.5]]]


def sphere(n: int) -> np.ndarray:
    P = rng.normal(size=(n, 3))
    return P / np.linalg.norm(P, axis=1, keepdims=True)


def clusters(r: np.random.Generator, k: int, m: int, spread: float) -> np.ndarray:
    return np.repeat(r.normal(size=(k, 3)), m, axis=0) + spread * r.normal(size=(k * m, 3))


#: Each of these crashed the process, raised, or gave a volume off by orders of magnitude (or negative) before.
CANDIDATES = {
    # crashed coal (segfault): thick enough relative to the extent, flat to Qhull's offset-sized rounding
    "1e-4 slab of 1 nm at 1 km": slab(200, 1e-4) * 1e-9 + 1e3,
    "1e-4 slab of 1 um at 1000 km": slab(200, 1e-4) * 1e-6 + 1e6,
    # wrong (coal 2.4e-4 for 6.8e-5, quickhull 0; negative volumes at other offsets)
    "1e-5 slab of 1 m at 1000 km": slab(200, 1.1e-5) + 1e6,
    "1e-4 slab of 1 mm at 1000 km": slab(200, 1e-4) * 1e-3 + 1e6,
    "unit cube of 1 mm at 1000 km": grid(5) * 1e-3 + 1e6,
    # crashed coal before the flatness filter; thin ones are now measured by quickhull, not rounded to 0
    "planar": np.c_[rng.normal(size=(50, 2)), np.zeros(50)],
    "1e-9 thin": slab(50, 1e-9),
    "1e-6 thin at 1 km": slab(300, 1e-6) + 1e3,
    "collinear": np.outer(np.linspace(-1, 1, 30), [0.3, -0.2, 0.9]),
    "collinear and one point": np.r_[np.outer(np.linspace(-1, 1, 1000), [1, 2, 3.0]), [[0.1, 0, 0]]],
    "a plane and one point 1e-6 above": np.r_[np.c_[rng.uniform(-1, 1, (5000, 2)), np.zeros(5000)], [[0, 0, 1e-6]]],
    "one point repeated": np.ones((10, 3)),
    "points a few ulps apart": 0.3 + np.spacing(0.3) * rng.integers(-3, 4, size=(200, 3)),
    # coal's fan over a merged, jittered face folded back: +4e-4 relative volume
    "box faces jittered 1e-12": box_faces(3000, 1e-12),
    "box faces jittered 1e-15": box_faces(2000, 1e-15),
    "grid (coplanar hull faces)": grid(12),
    "rotated grid": grid(8) @ np.linalg.qr(rng.normal(size=(3, 3)))[0],
    "a vertex with 2000 neighbours": fan(2000),
    "tiny clusters at cube corners": np.repeat(grid(2), 100, axis=0) + 1e-13 * rng.normal(size=(800, 3)),
    "sphere": sphere(3000),
    "sphere jittered 1e-14": sphere(2000) * (1 + 1e-14 * rng.normal(size=(2000, 1))),
    "four points": rng.normal(size=(4, 3)),
    "many duplicates": np.repeat(rng.normal(size=(20, 3)), 200, axis=0),
    # quickhull raised KeyError: a 1e-8 cloud and a far point (a needle: its initial tetrahedron was misoriented)
    "needle": np.r_[1e-8 * rng.normal(size=(800, 3)), rng.normal(size=(1, 3))],
    "subnormal": 1e-310 * rng.normal(size=(100, 3)),
    # crashed coal (segfault): Qhull merged nearly coincident points into a twisted facet and printed a warning
    "21 clusters of 125 points 1e-13 apart": clusters(np.random.default_rng(6), 21, 125, 1e-13),
}


@pytest.mark.parametrize("name", list(CANDIDATES))
def test_hostile_point_sets_do_not_crash_and_agree_with_scipy(child, name):
    P = CANDIDATES[name]
    agree(P, child.hull(P))


def test_non_finite_and_huge_coordinates(child):
    P = rng.normal(size=(20, 3))
    for bad in (np.nan, np.inf, -np.inf):
        Q = P.copy()
        Q[3, 1] = bad
        got = child.hull(Q)
        assert all(v == [0.0, 0.0, []] for v in got.values())
    # 1e300 m: the volume overflows to inf (it is 1e900 m^3), the process survives
    got = child.hull(1e300 * P)
    assert all(v[0] == float("inf") for v in got.values())


def test_vertices_are_the_first_of_equal_points_far_from_the_origin(child):
    P = np.r_[grid(3), grid(3)] * 1e-3 + np.array([1e6, -2e5, 3e4])  # corners and duplicates, 1 mm cube
    got = child.hull(P)
    corners = [i for i in range(27) if (np.abs(grid(3)[i]) == 1).all()]
    for name, (volume, _, vertices) in got.items():
        assert vertices == corners, name
        assert volume == pytest.approx(8e-9, rel=1e-9), name


@st.composite
def hostile(draw):
    """Thin, offset, jittered, coplanar-faced or fanned point sets at scales from 1 nm to 1 km."""
    seed = draw(st.integers(0, 2**32 - 1))
    r = np.random.default_rng(seed)
    n = draw(st.integers(4, 600))
    kind = draw(st.sampled_from(["slab", "planes", "box", "fan", "curves", "needle"]))
    if kind == "slab":
        P = np.c_[r.uniform(-1, 1, (n, 2)), 10.0 ** draw(st.integers(-8, -2)) * r.uniform(-1, 1, n)]
        P = P @ np.linalg.qr(r.normal(size=(3, 3)))[0]
    elif kind == "planes":  # points near a few planes
        k = draw(st.integers(2, 6))
        P = np.concatenate([
            np.c_[r.uniform(-1, 1, (n // k + 1, 2)), 10.0 ** r.uniform(-16, -8) * r.normal(size=n // k + 1)]
            @ np.linalg.qr(r.normal(size=(3, 3)))[0] + r.normal(size=3)
            for _ in range(k)
        ])  # fmt: skip
    elif kind == "box":
        P = r.uniform(-1, 1, (n, 3))
        P[np.arange(n), r.integers(0, 3, n)] = r.choice([-1.0, 1.0], n)
        P += 10.0 ** r.uniform(-17, -10) * r.normal(size=P.shape)
    elif kind == "fan":
        a = np.linspace(0, 2 * np.pi, n, endpoint=False)
        rim = np.c_[np.cos(a), np.sin(a), 10.0 ** r.uniform(-16, -3) * r.normal(size=n)]
        P = np.r_[rim, [[0, 0, 1.0]], [[0, 0, -0.3]]]
    elif kind == "curves":  # arcs and helices, like frames of a robot turning its base
        parts = []
        for _ in range(draw(st.integers(1, 4))):
            t = np.linspace(0, r.uniform(0.1, 6.3), n // 2 + 4)
            radius, pitch = r.uniform(0.05, 0.5), 10.0 ** r.uniform(-9, -1) * r.choice([0, 1])
            parts.append(np.c_[radius * np.cos(t), radius * np.sin(t), pitch * t + r.uniform(0, 0.3)])
        P = np.concatenate(parts)
    else:  # a small cloud and a few far points
        P = np.r_[10.0 ** r.uniform(-10, -4) * r.normal(size=(n, 3)), r.normal(size=(draw(st.integers(1, 4)), 3))]
    scale = 10.0 ** draw(st.integers(-9, 3))
    offset = 10.0 ** draw(st.integers(0, 6)) * r.normal(size=3) * draw(st.sampled_from([0, 1]))
    return P * scale + offset


@settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(P=hostile())
def test_property_coal_quickhull_and_scipy_agree_and_nothing_crashes(child, P):
    agree(P, child.hull(P))


PROGRAMS = {
    "a straight line": "lib.move_linear(0.3, 0.1, 0.3)\nlib.move_linear(0.3, -0.1, 0.3)",
    "1 mm up and down": "lib.move_up(0.001)\nlib.move_down(0.001)",
    "waiting": "lib.wait(0.5)",
    "a base sweep": "lib.set_speed(0.2)\nlib.move_to(0.2, 0.2, 0.25)\nlib.move_to(-0.2, 0.2, 0.25)",
}


@pytest.mark.parametrize("name", list(PROGRAMS))
def test_point_sets_of_real_motions(child, name):
    """What space_usage hulls for motions that barely move or move along a line, simulated for real: the whole
    robot (default decimation and the exact hull) and the TCP alone (a straight path is thin: it was rounded to
    0; the exact sweep has vertices with hundreds of neighbours, which coal refuses)."""
    from robocritics import Scene, simulate
    from robocritics.critic.builtin.space_usage import hull_points

    X = simulate(PROGRAMS[name], Scene.builtin("sorting")).trajectory.positions
    for frames in (slice(None), slice(-1, None)):
        for tolerance_m in (0.0005, 0.0):
            P, _, _ = hull_points(np.ascontiguousarray(X[:, frames]), tolerance_m)
            if len(P) >= 4:
                agree(P, child.hull(P))


@pytest.mark.parametrize("hull_of", [convex_hull, quickhull])
@pytest.mark.parametrize("shape", [(12, 2), (4, 4), ()])
def test_points_of_the_wrong_shape_are_refused(hull_of, shape):
    # (12, 2) used to be read as 8 points of 3 coordinates; it fails before coal is called
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        hull_of(np.ones(shape) if shape else np.float64(1.0))


def test_points_of_shape_t_l_3_are_read_as_n_3():
    P = np.random.default_rng(3).normal(size=(10, 4, 3))
    assert quickhull(P).volume_m3 == pytest.approx(ConvexHull(P.reshape(-1, 3)).volume, rel=1e-9)
