"""Your cell: scene fixtures from mesh files (issue 24, item 6).

A jig is written here as a binary STL (numpy), placed in a scene by a file path relative to the scene file,
and measured against the arm: the proximity kernel's values against coal directly and against a brute-force
segment-triangle reference; hostile mesh files end in a SceneError naming the field (CLI exit 2); the offline
--html file draws the jig in headless Chromium.
"""

from __future__ import annotations

import itertools
import json
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import robocritics as rc
from robocritics import cli
from robocritics.errors import SceneError
from robocritics.geometry.meshes import capsule_mesh
from robocritics.geometry.proximity import ProximityKernel
from robocritics.planning.trace import EXACT_WITHIN_M
import robocritics.scene as scene_module
from robocritics.llm.prompts import describe_scene
from robocritics.scene import Scene, rpy_matrix

from mesh_reference import point_segment, point_triangle

FACES = np.array([(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
                  (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)])  # fmt: skip


def box_corners(lo, hi) -> np.ndarray:
    """The 12 triangles ``(12, 3, 3)`` of the axis-aligned box ``lo``-``hi``."""
    v = np.array(list(itertools.product(*zip(lo, hi))), float)
    return v[FACES]


def jig_corners() -> np.ndarray:
    """An L-shaped jig in millimetres, origin at its corner on the table: a 120 x 80 x 20 plate and a
    20 x 80 x 90 fence at its back (not convex: a hull or a box would be loose)."""
    return np.concatenate([box_corners((0, 0, 0), (120, 80, 20)), box_corners((0, 0, 20), (20, 80, 90))])


def write_stl(path: Path, corners: np.ndarray) -> Path:
    """A binary STL: 80-byte header, the triangle count, then per triangle a normal, three corners, 2 bytes."""
    record = np.zeros(len(corners), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    record["v"] = corners
    path.write_bytes(b"robocritics test jig".ljust(80, b" ") + struct.pack("<I", len(corners)) + record.tobytes())
    return path


JIG = {"id": "jig", "shape": "mesh", "file": "parts/jig.stl", "scale": 0.001, "position": [0.22, -0.04, 0.0],
       "rpy": [0.0, 0.0, 0.3]}  # fmt: skip


@pytest.fixture()
def cell(tmp_path):
    (tmp_path / "parts").mkdir()
    write_stl(tmp_path / "parts" / "jig.stl", jig_corners())
    scene = {"name": "cell", "objects": [JIG]}
    path = tmp_path / "cell.json"
    path.write_text(json.dumps(scene))
    return path


# --- reference: the distance of a segment to a triangle, by its cases ----------------------------------


def segment_segment(p0, p1, q0, q1, steps=4001):
    """Distance of segment p0-p1 to each segment q (F, 3): the exact minimum over one segment's parameter of
    the other's point-segment distance is approached by a dense grid, then polished by golden section."""
    s = np.linspace(0, 1, steps)
    pts = p0 + s[:, None] * (p1 - p0)  # (S, 3)
    d = point_segment(pts[:, None, :], q0[None], q1[None])  # (S, F)
    best = d.argmin(0)
    lo, hi = s[np.maximum(best - 1, 0)], s[np.minimum(best + 1, steps - 1)]
    g = (np.sqrt(5) - 1) / 2
    f = lambda t: point_segment(p0 + t[:, None] * (p1 - p0), q0, q1)  # noqa: E731  (distance is convex in t)
    for _ in range(80):
        m1, m2 = hi - g * (hi - lo), lo + g * (hi - lo)
        left = f(m1) < f(m2)
        hi, lo = np.where(left, m2, hi), np.where(left, lo, m1)
    return f((lo + hi) / 2)


def segment_crosses(p0, p1, tri):
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(b - a, c - a)
    h0, h1 = ((p0 - a) * n).sum(1), ((p1 - a) * n).sum(1)
    crosses = h0 * h1 <= 0
    t = np.where(h0 != h1, h0 / np.where(h0 != h1, h0 - h1, 1), 0)
    x = p0 + t[:, None] * (p1 - p0)
    for u, v in ((a, b), (b, c), (c, a)):
        crosses &= (np.cross(v - u, x - u) * n).sum(1) >= -1e-15
    return crosses


def reference_distance(p0, p1, radius, tri):
    """min over triangles of the segment-triangle distance (0 if it crosses one; else an endpoint to the face or
    the segment to an edge), minus the radius: the capsule's distance to the surface."""
    if segment_crosses(p0, p1, tri).any():
        return -radius
    ends = np.minimum(point_triangle(p0, tri), point_triangle(p1, tri))
    edges = np.min([segment_segment(p0, p1, tri[:, i], tri[:, (i + 1) % 3]) for i in range(3)], axis=0)
    return float(np.minimum(ends, edges).min()) - radius


def coal_distance(p0, p1, radius, shape):
    import coal

    from robocritics.geometry.meshes import mesh_model
    from robocritics.geometry.pairs import capsule_pose

    pose, length = capsule_pose(p0, p1)
    T = lambda P: coal.Transform3s(P[:3, :3].copy(), P[:3, 3].copy())  # noqa: E731
    return coal.distance(coal.Capsule(radius, length), T(pose), mesh_model(shape), T(np.asarray(shape.pose)),
                         coal.DistanceRequest(), coal.DistanceResult())  # fmt: skip


def placed_triangles(shape) -> np.ndarray:
    v, f = shape.mesh
    v = v @ shape.pose[:3, :3].T + shape.pose[:3, 3]
    return v[f]


# --- the scene ---------------------------------------------------------------------------------------


def test_a_mesh_fixture_loads_relative_to_its_scene_file_and_round_trips(cell, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path / "parts")  # the path is the scene file's, not the working directory's
    scene = Scene.load(cell)
    (jig,) = scene.objects
    assert Path(jig.file) == (cell.parent / "parts" / "jig.stl").resolve()
    assert jig.graspable is False and jig.shape == "mesh"
    assert jig.size == pytest.approx((0.12, 0.08, 0.09))  # the scaled bounding box, in the mesh frame
    assert (jig.bottom, jig.top) == pytest.approx((0.0, 0.09))
    (shape,) = jig.shapes()
    corners = placed_triangles(shape)
    assert corners.shape == (24, 3, 3)
    expected = jig_corners() * 0.001 @ rpy_matrix(JIG["rpy"]).T + JIG["position"]
    assert np.allclose(np.sort(corners.reshape(-1, 3), axis=0), np.sort(expected.reshape(-1, 3), axis=0), atol=1e-7)
    assert Scene.model_validate_json(scene.to_json()) == scene  # a dumped scene (derived size and all) reloads
    assert "fixture (CAD mesh, not graspable)" in describe_scene(scene)


def test_a_mesh_fixture_takes_the_issues_yaw_key_as_a_turn_about_z(tmp_path):
    write_stl(tmp_path / "jig.stl", jig_corners())
    yaw = 0.7
    (_, jig) = Scene.load(_scene_with(tmp_path, yaw=yaw)).objects
    c, s = np.cos(yaw), np.sin(yaw)  # the turn written out, not through rpy_matrix
    corners = jig_corners().reshape(-1, 3) * 0.001
    expected = corners @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + [0.3, 0.0, 0.0]
    assert jig.rpy == (0.0, 0.0, yaw)
    gaps = np.linalg.norm(jig.placed_vertices()[:, None] - expected[None], axis=-1)
    assert gaps.min(axis=1).max() < 1e-7 and gaps.min(axis=0).max() < 1e-7  # the same corners, both ways
    assert Scene.model_validate_json(Scene.load(_scene_with(tmp_path, yaw=yaw)).to_json()).objects[1] == jig


def test_the_arm_near_and_through_the_jig_is_measured_exactly_and_flagged(cell):
    scene = Scene.load(cell)
    program = "move_to(0.27, 0.0, 0.15)\nmove_to(0.27, 0.0, 0.07)\nmove_down(0.06)\nhome()\n"
    execution = rc.simulate(program, scene)
    tr, robot = execution.trajectory, execution.robot
    (shape,) = scene.shapes()[:1]
    cols = [k for k, p in enumerate(tr.pairs) if (p.b_entity or p.b) == "jig" and p.a in robot.capsule_names]
    assert cols, "the arm's capsules are measured against the jig"
    p0, p1 = robot.capsule_segments(tr.frames)
    tri = placed_triangles(shape)
    checked = 0
    for k in cols:
        i = robot.capsule_names.index(tr.pairs[k].a)
        r = float(robot.capsule_radii[i])
        values = tr.proximity[:, k]
        for t in np.unique(np.linspace(0, len(values) - 1, 25).astype(int).tolist() + [int(values.argmin())]):
            if values[t] > EXACT_WITHIN_M:  # a far value may be a lower bound: it must still be one
                assert values[t] <= coal_distance(p0[t, i], p1[t, i], r, shape) + 1e-9
                continue
            exact = coal_distance(p0[t, i], p1[t, i], r, shape)
            assert values[t] == pytest.approx(exact, abs=1e-9)
            ref = reference_distance(p0[t, i], p1[t, i], r, tri)
            if ref > 0:
                assert values[t] == pytest.approx(ref, abs=1e-6)
            else:
                assert values[t] <= 1e-9
            checked += 1
    assert checked > 10
    least = tr.proximity[:, cols].min()
    assert least < 0  # move_down(0.06) from 7 cm: the fingertips 1 cm deep in the 2-cm plate
    verdict = next(v for v in rc.critique(execution).verdicts if v.critic == "collision")
    assert verdict.flag is rc.Flag.ERROR and "jig" in verdict.message
    assert verdict.value == pytest.approx(least, abs=1e-9)
    near = rc.simulate("move_to(0.27, 0.0, 0.15)\nmove_to(0.27, 0.0, 0.085)\nhome()\n", scene)
    nv = next(v for v in rc.critique(near).verdicts if v.critic == "collision")
    assert nv.flag is rc.Flag.WARNING and "jig" in nv.message and 0 < nv.value < 0.05


@settings(max_examples=12, deadline=None)
@given(
    st.tuples(*[st.floats(0.15, 0.40)] * 2, st.floats(-0.05, 0.20)),
    st.tuples(*[st.floats(-0.15, 0.15)] * 3),
    st.floats(0.005, 0.05),
)
def test_capsule_to_mesh_matches_coal_and_the_brute_force_reference(tmp_path_factory, start, step, radius):
    folder = tmp_path_factory.mktemp("jig")
    write_stl(folder / "jig.stl", jig_corners())
    scene = Scene.model_validate({"objects": [dict(JIG, file=str(folder / "jig.stl"))]})
    shape = scene.objects[0].shapes()[0]
    a = np.array(start) + np.array([0.0, -0.1, 0.0])
    b = a + np.array(step)
    kernel = ProximityKernel([("link", radius)], [shape], [("link", "jig")])
    value = float(kernel.distances(a[None, None], b[None, None])[0, 0])
    assert value == pytest.approx(coal_distance(a, b, radius, shape), abs=1e-12)
    ref = reference_distance(a, b, radius, placed_triangles(shape))
    if ref > 1e-6:
        assert value == pytest.approx(ref, abs=1e-6)
    else:
        assert value <= 1e-6
    # with a cutoff, a far sample gets a lower bound above it, never a value below the true one
    cut = np.array([0.01])
    bounded = capsule_mesh(a[None], b[None], radius, shape, cut=cut)[0]
    assert bounded == pytest.approx(value, abs=1e-12) if value <= 0.01 else (0.01 < bounded <= value + 1e-12)


# --- hostile mesh files -----------------------------------------------------------------------------------


def _scene_with(tmp_path, **fields) -> Path:
    obj = {"id": "jig", "shape": "mesh", "file": "jig.stl", "scale": 0.001, "position": [0.3, 0.0, 0.0]}
    obj.update(fields)
    path = tmp_path / "hostile.json"
    path.write_text(json.dumps({"objects": [{"id": "cup", "shape": "sphere", "size": [0.03], "position": [0.2, 0.2, 0.03]}, obj]}))
    return path


def _nan_stl(path: Path) -> None:
    corners = jig_corners()
    corners[3, 1, 2] = np.nan
    write_stl(path, corners)


def _dae_with_doctype(path: Path) -> None:
    path.write_text('<?xml version="1.0"?>\n<!DOCTYPE lolz [<!ENTITY lol "lol">]>\n'
                    '<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">&lol;</COLLADA>\n')  # fmt: skip


HOSTILE = {
    "missing": ({"file": "nowhere.stl"}, None, "objects[1].file", "No such file"),
    "junk bytes": ({}, lambda p: p.write_bytes(b"\x13\x88 not a mesh \x00" * 64), "objects[1].file", "cannot be read"),
    "not a mesh format": ({"file": "jig.txt"}, lambda p: p.write_text("solid nothing\n"), "objects[1].file", "reads STL, DAE and OBJ"),
    "NaN vertices": ({}, _nan_stl, "objects[1].file", "non-finite"),
    "DOCTYPE in a DAE": ({"file": "jig.dae"}, _dae_with_doctype, "objects[1].file", "DOCTYPE"),
    "a directory": ({"file": "."}, None, "objects[1].file", "not a regular file"),
    "zero scale": ({"scale": 0}, None, "objects[1].scale", "not a positive finite"),
    "negative scale": ({"scale": -0.001}, None, "objects[1].scale", "not a positive finite"),
    "huge scale": ({"scale": 1e9}, None, "objects[1].scale", "not a positive finite"),
    "scale as text": ({"scale": "0.001"}, None, "objects[1].scale", "not a number"),
    "metres given as mm": ({"scale": 1.0}, None, "objects[1].file", "is scale right"),
    "placed past the bound": ({"position": [9.95, 0.0, 0.0]}, None, "objects[1].file", "reaches"),
    "graspable": ({"graspable": True}, None, "objects[1].graspable", "fixture"),
    "a size of its own": ({"size": [1, 1, 1]}, None, "objects[1].size", "comes from its file"),
    "a file on a box": ({"shape": "box", "size": [0.1, 0.1, 0.1]}, None, "objects[1].file", "only a shape 'mesh'"),
    "yaw and rpy": ({"yaw": 0.3, "rpy": [0, 0, 0.3]}, None, "objects[1].yaw", "not both"),
    "yaw as text": ({"yaw": "0.3"}, None, "objects[1].yaw", "not a number"),
    "yaw of NaN": ({"yaw": float("nan")}, None, "objects[1].yaw", "not a finite number"),
    "yaw past a turn": ({"yaw": 7.0}, None, "objects[1].yaw", "out of range"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_a_hostile_mesh_is_a_scene_error_naming_the_field(tmp_path, case):
    fields, make, where, words = HOSTILE[case]
    write_stl(tmp_path / "jig.stl", jig_corners() * (1000 if case == "metres given as mm" else 1))
    target = tmp_path / fields.get("file", "jig.stl")
    if make is not None:
        make(target)
    path = _scene_with(tmp_path, **fields)
    with pytest.raises(SceneError) as caught:
        Scene.load(path)
    assert caught.value.path == where and words in str(caught.value), str(caught.value)


def test_mesh_files_are_bounded_in_bytes_and_triangles(tmp_path, monkeypatch):
    with open(tmp_path / "jig.stl", "wb") as f:  # sparse: no disk is spent on the test
        f.truncate(scene_module.MAX_MESH_FILE_BYTES + 1)
    with pytest.raises(SceneError, match="bytes; a scene mesh has at most") as caught:
        Scene.load(_scene_with(tmp_path))
    assert caught.value.path == "objects[1].file"
    write_stl(tmp_path / "many.stl", np.concatenate([jig_corners() + 200 * i for i in range(5)]))
    monkeypatch.setattr(scene_module, "MAX_MESH_TRIANGLES", 100)
    with pytest.raises(SceneError, match="120 triangles; robocritics reads at most 100") as caught:
        Scene.load(_scene_with(tmp_path, file="many.stl", scale=0.0001))
    assert caught.value.path == "objects[1].file"


def test_the_cli_exits_2_naming_the_mesh_field(tmp_path, capsys):
    program = tmp_path / "p.py"
    program.write_text("home()\n")
    scene = _scene_with(tmp_path, file="absent.stl")
    assert cli.main(["check", str(program), "--scene", str(scene)]) == 2
    err = capsys.readouterr().err
    assert "objects[1].file" in err and "absent.stl" in err


# --- shown ------------------------------------------------------------------------------------------------


def test_replay_data_sends_the_triangles_decimated_to_a_bound():
    from robocritics.viz.replay import shown_triangles

    corners = jig_corners() * 0.001
    v, f = np.unique(corners.reshape(-1, 3), axis=0, return_inverse=True)
    f = f.reshape(-1, 3)
    assert np.array_equal(shown_triangles(v, f), v[f])  # few: all of them
    # a finely tessellated sphere: clustering keeps its outline within the bound
    n = 120
    th, ph = np.meshgrid(np.linspace(0, np.pi, n), np.linspace(0, 2 * np.pi, n), indexing="ij")
    grid = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).reshape(-1, 3)
    idx = np.arange(n * n).reshape(n, n)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 4)
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    shown = shown_triangles(grid, tris, limit=2000)
    assert 200 < len(shown) <= 2000
    assert np.allclose(np.linalg.norm(shown.reshape(-1, 3), axis=1), 1.0, atol=0.1)


def test_the_offline_file_draws_the_jig(cell, tmp_path):
    from browser import canvas_pixels, chromium, save_screenshot, severe_console_errors, wait_for

    program = tmp_path / "near.py"
    program.write_text("move_to(0.27, 0.0, 0.15)\nmove_to(0.27, 0.0, 0.085)\nhome()\n")
    out, bare = tmp_path / "cell.html", tmp_path / "bare.html"
    proc = subprocess.run([sys.executable, "-m", "robocritics", "check", str(program), "--scene", str(cell), "--html", str(out)],
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    assert proc.returncode in (0, 1), proc.stderr
    html = out.read_text()
    assert '"shape": "mesh"' in html or '"shape":"mesh"' in html
    empty = tmp_path / "empty.json"
    empty.write_text(json.dumps({"name": "cell"}))
    subprocess.run([sys.executable, "-m", "robocritics", "check", str(program), "--scene", str(empty), "--html", str(bare)],
                   capture_output=True, text=True, timeout=300, check=False)  # fmt: skip
    ready = "return document.querySelector('.rc-replay') && document.querySelector('.rc-replay').dataset.ready"
    with chromium() as driver:
        driver.get(out.as_uri())
        wait_for(driver, ready, what="the first frame")
        assert severe_console_errors(driver) == []
        assert driver.find_element("css selector", ".rc-replay").get_attribute("data-meshes") == "1"
        with_jig = canvas_pixels(driver, driver.find_element("css selector", ".rc-canvas"))
        save_screenshot(driver, "mesh_jig.png")
        driver.get(bare.as_uri())
        wait_for(driver, ready, what="the first frame")
        assert canvas_pixels(driver, driver.find_element("css selector", ".rc-canvas")) != with_jig


def test_a_carried_object_against_the_jig_matches_coal(cell):
    """A box the gripper carries (its pose per sample) against the mesh: coal per run of equal poses."""
    from robocritics.geometry.pairs import closest_points
    from robocritics.scene import SceneObject

    scene = Scene.load(cell)
    jig = scene.shapes()[0]
    box = SceneObject(id="part", shape="box", size=(0.04, 0.03, 0.05), position=(0.3, 0.1, 0.2)).shapes()[0]
    T = 40
    poses = np.broadcast_to(np.eye(4), (T, 4, 4)).copy()
    poses[: T // 2, :3, 3] = np.linspace((0.35, 0.2, 0.25), (0.27, 0.0, 0.03), T // 2)
    poses[T // 2 :] = poses[T // 2 - 1]  # resting: one run
    kernel = ProximityKernel([], [box, jig], [("part", "jig"), ("jig", "part")], moving=["part"])
    values = kernel.distances(np.zeros((T, 0, 3)), np.zeros((T, 0, 3)), poses={"part": poses})
    expected = [closest_points("box", box.size, poses[t], "mesh", jig.mesh, jig.pose)[2] for t in range(T)]
    assert np.allclose(values[:, 0], expected, atol=1e-12) and np.array_equal(values[:, 0], values[:, 1])
    assert values[0, 0] > 0.05 and values[-1, 0] < 0  # from above the jig down into its plate


def test_programs_see_the_jig_centre_and_avoid_collision_routes_over_it(cell):
    scene = Scene.load(cell)
    (jig,) = scene.objects
    corners = placed_triangles(jig.shapes()[0]).reshape(-1, 3)
    assert jig.centre == pytest.approx(tuple((corners.max(0) + corners.min(0)) / 2))  # not the file's origin

    def least(program):
        tr = rc.simulate(program, scene).trajectory
        return tr.proximity[:, [k for k, p in enumerate(tr.pairs) if (p.b_entity or p.b) == "jig"]].min()

    across = "move_to(0.35, 0.12, 0.06)\nmove_to(0.17, -0.12, 0.06)\n"
    assert least("avoid_collision(jig)\n" + across) > max(least(across), 0.03)
    above = least("move_to(jig.x, jig.y, jig.top + 0.05)\n")  # the fingertips 5 cm over its highest point
    assert 0.045 < above < 0.06


def test_the_studio_draws_the_jig_and_flags_the_plunge(cell):
    from browser import chromium, save_screenshot, severe_console_errors, wait_for
    from robocritics.viz.studio import Studio

    program = "move_to(0.27, 0.0, 0.15)\nmove_to(0.27, 0.0, 0.07)\nmove_down(0.06)\nhome()\n"
    with chromium() as driver, Studio(str(cell), program) as studio:
        driver.get(studio.url)
        wait_for(driver, "return document.body.dataset.ready === '1'", what="the studio page to start")
        driver.execute_script("document.getElementById('run').click()")
        wait_for(driver, "const r = document.querySelector('#critics .critic[data-critic=\"collision\"]'); "
                         "return r && ['ok', 'warning', 'error'].includes(r.dataset.flag)", what="the collision flag")  # fmt: skip
        flag = driver.execute_script("return document.querySelector('#critics .critic[data-critic=\"collision\"]').dataset.flag")
        assert flag == "error"
        wait_for(driver, "return document.getElementById('replay').dataset.ready === '1'", what="the replay")
        assert driver.execute_script("return document.getElementById('replay').dataset.meshes") == "1"
        save_screenshot(driver, "studio_mesh_jig.png")
        assert not [e for e in severe_console_errors(driver) if "favicon" not in e]


# --- inside a closed mesh -------------------------------------------------------------------------------------

PLATE, FENCE = ((0, 0, 0), (120, 80, 20)), ((0, 0, 20), (20, 80, 90))  # the jig's two boxes, mm (jig_corners)


def _box_of(p_mm) -> int:
    """Which of the jig's boxes holds the point (mm, jig frame) strictly inside: 0, 1, or -1 for none."""
    for i, (lo, hi) in enumerate((PLATE, FENCE)):
        if all(lo[k] < p_mm[k] < hi[k] for k in range(3)):
            return i
    return -1


def _jig_shape(folder: Path, corners=None):
    write_stl(folder / "jig.stl", jig_corners() if corners is None else corners)
    scene = Scene.model_validate({"objects": [dict(JIG, file=str(folder / "jig.stl"))]})
    return scene.objects[0].shapes()[0]


_MM_POINT = st.one_of(
    st.tuples(st.floats(2, 118), st.floats(2, 78), st.floats(2, 18)),  # in the plate
    st.tuples(st.floats(2, 18), st.floats(2, 78), st.floats(22, 88)),  # in the fence
    st.tuples(st.floats(-10, 130), st.floats(-10, 90), st.floats(-10, 100)),  # anywhere about it
)


def test_the_jig_is_closed_and_its_winding_number_is_its_inside(tmp_path):
    from robocritics.geometry.meshes import is_closed, winding_numbers

    shape = _jig_shape(tmp_path)
    vertices, triangles = shape.mesh
    assert is_closed(vertices, triangles)
    assert not is_closed(vertices, triangles[2:])  # two triangles off the plate's bottom: an open shell
    points = np.random.default_rng(5).uniform((-10, -10, -10), (130, 90, 100), size=(400, 3))
    w = winding_numbers(points * 0.001, vertices[triangles])
    inside = np.array([_box_of(p) >= 0 for p in points])
    assert np.allclose(w, inside.astype(float), atol=1e-9)  # 1 inside a shell, 0 outside: integers, off the surface


@settings(max_examples=25, deadline=None)
@given(_MM_POINT, st.tuples(*[st.floats(-25, 25)] * 3), st.floats(0.5, 6.0))
def test_a_capsule_inside_the_closed_jig_reads_a_penetration_like_a_box_does(tmp_path_factory, start_mm, step_mm, radius_mm):
    """Wholly inside (both ends in one of the jig's boxes, clear of its faces): -(distance of the segment to the
    surface + r), the brute-force reference; a ball in a box reads the same in the closed-form kernels."""
    shape = _jig_shape(tmp_path_factory.mktemp("jig"))
    a_mm = np.array(start_mm)
    b_mm = a_mm + np.array(step_mm)
    pose = np.asarray(shape.pose)
    a, b = (pose[:3, :3] @ (x * 0.001) + pose[:3, 3] for x in (a_mm, b_mm))
    r = radius_mm * 0.001
    value = float(capsule_mesh(a[None], b[None], r, shape)[0])
    kernel = ProximityKernel([("link", r)], [shape], [("link", "jig")])
    assert float(kernel.distances(a[None, None], b[None, None])[0, 0]) == value
    surface = reference_distance(a, b, 0.0, placed_triangles(shape))  # segment to surface (0: crosses it)
    where = _box_of(a_mm), _box_of(b_mm)
    if where[0] == where[1] >= 0 and surface > r + 1e-6:
        assert value == pytest.approx(-(surface + r), abs=1e-6)
        if not a_mm.tolist() == b_mm.tolist():
            return
        # a ball: the box kernel on the same box, placed as the jig places it
        lo, hi = (np.array(x) * 0.001 for x in (PLATE, FENCE)[where[0]])
        box_pose = pose.copy()
        box_pose[:3, 3] = pose[:3, :3] @ ((lo + hi) / 2) + pose[:3, 3]
        box = scene_module.Shape("b", "b", "box", tuple(hi - lo), box_pose)
        assert value == pytest.approx(float(ProximityKernel([("link", r)], [box], [("link", "b")]).distances(a[None, None], b[None, None])[0, 0]), abs=1e-9)
    elif where == (-1, -1) and surface > r + 1e-6:
        assert value == pytest.approx(surface - r, abs=1e-6)
    else:
        assert value <= 1e-6  # crossing the surface


def test_an_open_mesh_has_no_inside_a_capsule_behind_it_reads_its_gap(tmp_path):
    corners = jig_corners()[2:]  # the plate's bottom gone: not closed
    shape = _jig_shape(tmp_path, corners)
    pose = np.asarray(shape.pose)
    a = pose[:3, :3] @ np.array([0.06, 0.04, 0.01]) + pose[:3, 3]  # mid-plate, 1 cm over where its floor was
    value = float(capsule_mesh(a[None], a[None], 0.002, shape)[0])
    assert value == pytest.approx(reference_distance(a, a, 0.002, placed_triangles(shape)), abs=1e-6) and value > 0


def test_a_carried_ball_inside_the_closed_jig_reads_its_depth(tmp_path):
    from robocritics.geometry.meshes import shape_mesh

    shape = _jig_shape(tmp_path)
    pose = np.asarray(shape.pose)
    ball = scene_module.Shape("ball", "ball", "sphere", (0.004,), np.eye(4))
    at = np.broadcast_to(np.eye(4), (2, 4, 4)).copy()
    at[0, :3, 3] = pose[:3, :3] @ np.array([0.06, 0.04, 0.012]) + pose[:3, 3]  # 8 mm under the plate's top
    at[1, :3, 3] = pose[:3, :3] @ np.array([0.06, 0.04, 0.030]) + pose[:3, 3]  # 10 mm over it
    values = shape_mesh(ball, shape, at, pose[None])
    assert values[0] == pytest.approx(-(0.008 + 0.004), abs=1e-9)
    assert values[1] == pytest.approx(0.010 - 0.004, abs=1e-9)
