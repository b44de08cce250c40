"""Scene schema: built-in scenes load, bad input raises SceneError naming the field."""

import json
import math
from importlib import resources

import pytest

from robocritics import Scene, SceneError
from robocritics.robot.model import default_workspace

GOOD_OBJECT = {"id": "cube", "shape": "box", "size": [0.04, 0.04, 0.04], "position": [0.3, 0.0, 0.02]}


@pytest.mark.parametrize("name", ["recycling", "sorting", "breakfast"])
def test_builtin_scenes_are_within_reach(name):
    scene = Scene.builtin(name)
    assert scene.objects and scene.containers
    for item in (*scene.objects, *scene.containers):
        assert default_workspace().outside_distance([item.position[0], item.position[1], item.top]) < 0, item.id


def test_builtin_scene_files_load_by_path():
    # the package's JSON files are the only copy: by path they load to the same scenes as by name
    folder = resources.files("robocritics.scenes")
    assert Scene.builtin_names() == ["breakfast", "recycling", "sorting", "workbench"]
    for name in Scene.builtin_names():
        path = str(folder / f"{name}.json")
        assert Scene.load(path) == Scene.builtin(name) == Scene.resolve(path) == Scene.resolve(name)


@pytest.mark.parametrize(
    "patch, path, words",
    [
        ({"shape": "cone"}, "objects[0].shape", "unknown shape 'cone'"),
        ({"size": [0.04, -0.04, 0.04]}, "objects[0].size[1]", "-0.04 is not a positive length"),
        ({"position": [0.3, math.nan, 0.02]}, "objects[0].position[1]", "nan is not a finite number"),
        ({"size": [0.04, 0.04]}, "objects[0].size", "a box needs 3 numbers"),
        ({"id": "__class__"}, "objects[0].id", "identifier"),
        ({"colour": "red"}, "objects[0].colour", "Extra inputs"),
    ],
)
def test_invalid_objects_name_the_field(patch, path, words):
    with pytest.raises(SceneError) as info:
        Scene.model_validate({"objects": [{**GOOD_OBJECT, **patch}]})
    assert info.value.path == path
    assert words in str(info.value)


def test_duplicate_ids_are_refused():
    with pytest.raises(SceneError, match=r"objects\[1\]\.id: duplicate id 'cube'"):
        Scene.model_validate({"objects": [GOOD_OBJECT, GOOD_OBJECT]})


def test_load_reports_json_position(tmp_path):
    bad = tmp_path / "s.json"
    bad.write_text('{"objects": [}')
    with pytest.raises(SceneError, match="line 1, column 14"):
        Scene.load(bad)
    with pytest.raises(SceneError, match="no such scene file"):
        Scene.load(tmp_path / "missing.json")
    with pytest.raises(SceneError, match="did you mean 'sorting'"):
        Scene.builtin("sortin")


def test_container_inside_is_free_space():
    scene = Scene.builtin("sorting")
    box = scene.entity("white_box")
    assert box.contains_point((box.position[0], box.position[1], box.floor_top + 0.02))
    assert not box.contains_point((box.position[0], box.position[1], box.top + 0.02))
    shapes = [s for s in scene.shapes() if s.owner == "white_box"]
    assert len(shapes) == 5  # floor and four walls
    assert math.isclose(default_workspace().volume_m3, 4 / 3 * math.pi * 0.5**3)


def test_round_trip_json():
    scene = Scene.builtin("breakfast")
    assert Scene.model_validate(json.loads(scene.to_json())) == scene


def _contains_point_by_matrix(container, point, margin_m):
    """The obvious reference: the point in the container frame by the rotation matrix."""
    import numpy as np

    from robocritics.scene import rpy_matrix

    local = rpy_matrix((0, 0, container.yaw)).T @ (np.asarray(point, float) - np.asarray(container.position))
    hx, hy = container.size[0] / 2 - container.wall_m, container.size[1] / 2 - container.wall_m
    return bool(
        abs(local[0]) <= hx + margin_m
        and abs(local[1]) <= hy + margin_m
        and container.floor_top - margin_m <= point[2] <= container.top + margin_m
    )


def test_container_contains_point_agrees_with_the_rotation_matrix():
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from robocritics.scene import Container

    coord = st.floats(-0.5, 0.5)

    @settings(max_examples=500, deadline=None, derandomize=True)
    @given(coord, coord, st.floats(-3.2, 3.2), coord, coord, st.floats(0.0, 0.3), st.floats(0.0, 0.02))
    def check(x, y, yaw, px, py, pz, margin_m):
        container = Container(id="bin", position=(x, y, 0.05), size=(0.2, 0.15, 0.1), yaw=yaw)
        point = (px, py, pz)
        assert container.contains_point(point, margin_m) == _contains_point_by_matrix(container, point, margin_m)

    check()
