"""A vendor arm's links measured as their own meshes near contact (issue 24, item 1).

``Robot.from_urdf`` fits capsules around each link mesh (the fast path); ``robocritics.geometry.link_meshes``
replaces every capsule value at most ``MESH_EXACT_WITHIN_M`` by the distance of the piece of mesh that capsule
encloses. Checked here against coal on the raw mesh (built in the test from the file's triangles, or by
Pinocchio from the raw vendor file) and against brute-force point-triangle distances, with hypothesis.
"""

from __future__ import annotations

import importlib.util
import math
import struct
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics import Robot
from robocritics.critic.builtin.collision import Params as CollisionParams
from robocritics.critic.builtin.pinch_point import Params as PinchParams
from robocritics.planning.trace import EXACT_WITHIN_M, MESH_EXACT_WITHIN_M, build_trajectory
from robocritics.robot import fit
from robocritics.scene import Scene

from mesh_reference import point_triangle

# --- a one-joint arm whose upper link is a mesh: a tube with a housing across its far end ------------------


def _box_corners(lo, hi) -> np.ndarray:
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]  # fmt: skip
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], float)
    return corners[np.array(faces)]


#: The upper link in its own frame (m): a 0.36 m tube along x and a housing at its end, 24 triangles.
LINK_BOXES = [(np.array((0.0, -0.03, -0.03)), np.array((0.36, 0.03, 0.03))), (np.array((0.30, -0.09, -0.07)), np.array((0.42, 0.09, 0.07)))]
LINK = np.concatenate([_box_corners(lo, hi) for lo, hi in LINK_BOXES])

_URDF = """<?xml version="1.0"?>
<robot name="mesh_arm">
  <link name="base"><collision><geometry><cylinder radius="0.05" length="0.1"/></geometry></collision></link>
  <link name="upper"><collision><geometry><mesh filename="upper.stl"/></geometry></collision></link>
  <link name="tool0"/>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="2"/></joint>
  <joint name="flange" type="fixed"><parent link="upper"/><child link="tool0"/><origin xyz="0.42 0 0"/></joint>
</robot>
"""


def write_stl(path: Path, corners: np.ndarray) -> Path:
    record = np.zeros(len(corners), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    record["v"] = corners
    path.write_bytes(b"link".ljust(80, b" ") + struct.pack("<I", len(corners)) + record.tobytes())
    return path


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    folder = tmp_path_factory.mktemp("arm")
    write_stl(folder / "upper.stl", LINK)
    (folder / "arm.urdf").write_text(_URDF)
    robot = Robot.from_urdf(folder / "arm.urdf", tool="none", home_q=[0.0], reach_m=0.5, fixed_links=("base",))
    return robot


def _link_triangles() -> np.ndarray:
    """The link's triangles as the STL stores them (float32 corners), link frame."""
    return LINK.astype(np.float32).astype(float)


def _coal_raw(pose: np.ndarray, shape) -> float:
    """coal on the raw link mesh (a BVH built here from the STL's triangles) at ``pose`` against ``shape``."""
    import coal

    tri = _link_triangles()
    model = coal.BVHModelOBBRSS()
    model.beginModel(len(tri), 3 * len(tri))
    model.addVertices(np.ascontiguousarray(tri.reshape(-1, 3)))
    model.addTriangles(np.arange(3 * len(tri)).reshape(-1, 3))
    model.endModel()
    geometry = {"box": lambda s: coal.Box(*s), "sphere": lambda s: coal.Sphere(s[0]), "cylinder": lambda s: coal.Cylinder(*s)}[shape.kind](shape.size)
    T = lambda P: coal.Transform3s(np.ascontiguousarray(P[:3, :3]), np.ascontiguousarray(P[:3, 3]))  # noqa: E731
    request = coal.DistanceRequest()
    request.gjk_tolerance = 1e-10
    return coal.distance(model, T(pose), geometry, T(np.asarray(shape.pose)), request, coal.DistanceResult())


def _values(robot, scene, q, entity: str) -> tuple[float, float]:
    """The least value over the upper link's capsules against ``entity`` with the meshes refined, and the
    same with the capsules alone."""
    capsules = robot.copy()
    capsules.capsule_meshes = (None,) * len(robot.capsules)
    out = []
    for r in (robot, capsules):
        tr = build_trajectory(r, scene, np.array([[q]]), np.zeros(1))
        cols = [k for k, p in enumerate(tr.pairs) if p.b_entity == entity and p.a.split("#")[0] == "upper"]
        out.append(float(tr.proximity[0, cols].min()))
    return out[0], out[1]


def test_the_mesh_link_has_several_capsules_each_with_its_piece(arm):
    names = [c.name for c in arm.capsules if c.frame == "upper"]
    assert len(names) >= 2  # a tube and a housing: one capsule would be loose
    pieces = [arm.capsule_meshes[arm.capsule_names.index(n)] for n in names]
    assert all(p is not None for p in pieces) and arm.capsule_meshes[arm.capsule_names.index("base")] is None
    area = lambda t: 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()  # noqa: E731
    assert sum(area(p.vertices[p.triangles]) for p in pieces) == pytest.approx(area(_link_triangles()), rel=1e-9)
    assert all(c.capsule_meshes == (None,) * len(c.capsules) for c in (Robot.ur3e(), Robot.panda()))


@settings(max_examples=50, deadline=None)
@given(
    q=st.floats(-3.0, 3.0),
    kind=st.sampled_from(["box", "sphere", "cylinder"]),
    where=st.tuples(st.floats(-0.45, 0.45), st.floats(-0.45, 0.45), st.floats(0.18, 0.42)),
    size=st.floats(0.02, 0.12),
)
def test_near_contact_the_link_reads_coal_on_its_raw_mesh_and_the_brute_force_distance(arm, q, kind, where, size):
    dims = {"box": [size, 0.8 * size, 0.6 * size], "sphere": [0.5 * size], "cylinder": [0.5 * size, size]}[kind]
    scene = Scene.model_validate({"objects": [{"id": "thing", "shape": kind, "size": dims, "position": list(where), "rpy": [0.3, 0.0, 0.4]}]})
    (shape,) = scene.objects[0].shapes()
    pose = arm.forward(np.array([q]))[arm.frame_names.index("upper")]
    exact = _coal_raw(pose, shape)
    centre = np.linalg.inv(pose)[:3] @ np.append(where, 1.0)  # the object's centre in the link frame
    if exact > 0 and any(np.all((lo < centre) & (centre < hi)) for lo, hi in LINK_BOXES):
        # wholly inside the closed link mesh, touching no triangle: coal reads the gap to the surface; the
        # link reads a penetration, -(gap + 2 rho) with rho the object's inscribed ball
        exact = -(exact + 2 * {"box": min(dims) / 2, "sphere": dims[0], "cylinder": min(dims[0], dims[1] / 2)}[kind])
    value, capsule = _values(arm, scene, q, "thing")
    assert capsule <= max(exact, 0.0) + 1e-9  # the capsules never miss a contact
    if exact <= 0:
        # crossing: both negative. coal's depth of a triangle mesh is the first touched triangle's its traversal
        # meets (not the deepest), so the two depths need not agree (the report says so)
        assert value < 0
    elif exact <= MESH_EXACT_WITHIN_M:
        assert value == pytest.approx(exact, abs=1e-9)  # the mesh's distance
    else:  # beyond: a lower bound, above the threshold (a threshold test there reads the mesh too)
        assert MESH_EXACT_WITHIN_M < value <= exact + 1e-9 and capsule - 1e-12 <= value
    if kind == "sphere" and exact > 0:  # outside: the brute-force distance to the surface
        placed = _link_triangles() @ pose[:3, :3].T + pose[:3, 3]
        assert exact == pytest.approx(point_triangle(np.array(where), placed).min() - dims[0], abs=1e-6)


def test_a_sphere_inside_the_closed_link_mesh_is_a_penetration_not_its_gap_to_the_surface(arm):
    # a 1 cm ball in the middle of the tube (0.03 m half-width): it touches no triangle, yet it is inside
    pose = arm.forward(np.array([0.0]))[arm.frame_names.index("upper")]
    centre = pose[:3, :3] @ np.array([0.15, 0.0, 0.0]) + pose[:3, 3]
    scene = Scene.model_validate({"objects": [{"id": "bead", "shape": "sphere", "size": [0.01], "position": centre.tolist()}]})
    (shape,) = scene.objects[0].shapes()
    gap = _coal_raw(pose, shape)
    assert gap == pytest.approx(0.02, abs=1e-9)  # coal sees a surface 2 cm from the ball
    value, capsule = _values(arm, scene, 0.0, "bead")
    assert capsule < 0
    assert value == pytest.approx(-(gap + 2 * 0.01), abs=1e-9)  # -(3 cm + 1 cm): the ball's centre depth + r


def test_the_mesh_threshold_covers_every_built_in_proximity_threshold():
    assert MESH_EXACT_WITHIN_M >= max(CollisionParams().d_warn_m, PinchParams().d_max_m, PinchParams().d_min_m)
    assert MESH_EXACT_WITHIN_M <= EXACT_WITHIN_M  # the kernel's values it refines are exact capsule values


# --- a vendor arm as shipped ----------------------------------------------------------------------------


def _airo_ur5e() -> Path | None:
    spec = importlib.util.find_spec("airo_models")
    path = Path(spec.origin).parent / "arms/ur5e/ur5e.urdf" if spec and spec.origin else None
    return path if path is not None and path.is_file() else None


def test_a_vendor_arm_whose_capsule_touches_the_table_reads_its_mesh_clear_as_pinocchio_and_coal_do():
    """airo-models' UR5e as shipped: configurations where the upper arm's fitted capsules reach into the table
    while the mesh stays clear now read the mesh's distance, equal to coal on the raw file's geometry (loaded by
    Pinocchio) and to the brute-force lowest vertex above the table's top."""
    path = _airo_ur5e()
    if path is None:
        pytest.skip("airo-models is not installed (pip install '.[test]')")
    import coal

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        robot = Robot.from_urdf(path, tool="robotiq_2f85")
    capsules = robot.copy()
    capsules.capsule_meshes = (None,) * len(robot.capsules)
    scene = Scene.model_validate({})
    q = np.random.default_rng(3).uniform(robot.lower, robot.upper, size=(200, robot.n))
    time = np.arange(len(q)) * 0.01
    meshed, plain = build_trajectory(robot, scene, q, time), build_trajectory(capsules, scene, q, time)
    cols = [k for k, p in enumerate(meshed.pairs) if p.b_entity == "table" and p.a.split("#")[0] == "upper_arm_link"]
    least, capsule = meshed.proximity[:, cols].min(axis=1), plain.proximity[:, cols].min(axis=1)
    flips = np.flatnonzero((capsule <= 0) & (least > 0))
    assert len(flips) >= 3, "some sampled configurations put the capsule, not the mesh, into the table"
    # the reference: the raw file's collision geometry, as Pinocchio loads it (coal meshes), at Pinocchio's FK
    model = pin.buildModelFromUrdf(str(path))
    geom = pin.buildGeomFromUrdf(model, str(path), pin.GeometryType.COLLISION, package_dirs=[str(path.parent)])
    (upper,) = [g for g in geom.geometryObjects if model.frames[g.parentFrame].name == "upper_arm_link"]
    data, geom_data = model.createData(), pin.GeometryData(geom)
    (table,) = scene.shapes()
    box = coal.Box(*table.size)
    at = coal.Transform3s(np.eye(3), np.asarray(table.pose)[:3, 3].copy())
    mesh = upper.geometry
    vertices = np.array(mesh.vertices())
    for t in flips.tolist():
        pin.updateGeometryPlacements(model, data, geom, geom_data, q[t])
        placement = geom_data.oMg[geom.getGeometryId(upper.name)]
        raw = coal.distance(mesh, coal.Transform3s(placement.rotation, placement.translation), box, at,
                            coal.DistanceRequest(), coal.DistanceResult())  # fmt: skip
        assert least[t] == pytest.approx(raw, abs=1e-9)
        placed = vertices @ placement.rotation.T + placement.translation
        if np.abs(placed[:, :2]).max() < 0.6:  # over the table top (z = 0): the lowest vertex is the distance
            assert least[t] == pytest.approx(placed[:, 2].min(), abs=1e-6)
        assert capsule[t] <= 0 < least[t]
    # far from the table nothing changed: values above the threshold stay the capsules' lower bounds
    far = capsule > MESH_EXACT_WITHIN_M
    assert np.array_equal(least[far], capsule[far]) or np.all(least[far] >= capsule[far])
    assert math.isfinite(float(least.min()))
