"""Hostile scenes: every bad input is a SceneError naming the field (or the file and the problem), never a
traceback, never a hang, never silently accepted."""

from __future__ import annotations

import json
import keyword
import math
import os
import tracemalloc

import pytest

from robocritics import Scene, SceneError, simulate
from robocritics.critic import critique
from robocritics.program import run_program
from robocritics.program.check import FORBIDDEN_NAMES, MODULE_ALIASES
from robocritics.program.language import SAFE_BUILTINS
from robocritics.program.skills import SKILLS
from robocritics.scene import (
    MAX_ENTITIES,
    MAX_FILE_BYTES,
    MAX_JSON_DEPTH,
    Container,
    SceneObject,
    Table,
    Workspace,
    parse_json,
    reserved_names,
)
from robocritics.pipeline import check_scene_ids

CUBE = {"id": "cube", "shape": "box", "size": [0.04, 0.04, 0.04], "position": [0.3, 0.0, 0.02]}
BOX = {"id": "bin_1", "size": [0.1, 0.1, 0.1], "position": [0.3, 0.2, 0.05]}


def refused(data) -> SceneError:
    with pytest.raises(SceneError) as info:
        Scene.model_validate(data)
    return info.value


# --- numbers: finite, in range, real numbers ------------------------------------------------------


@pytest.mark.parametrize(
    "data, path, words",
    [
        ({"objects": [{**CUBE, "position": [1e300, 0, 0.02]}]}, "objects[0].position[0]", "1e+300 is out of range (coordinates are within 10 m"),
        ({"objects": [{**CUBE, "position": [0.3, -10.01, 0.02]}]}, "objects[0].position[1]", "-10.01 is out of range"),
        ({"objects": [{**CUBE, "position": [0.3, 0, math.inf]}]}, "objects[0].position[2]", "inf is not a finite number"),
        ({"objects": [{**CUBE, "position": [10**5000, 0, 0]}]}, "objects[0].position[0]", "an integer of 16610 bits is out of range"),
        ({"objects": [{**CUBE, "position": [True, 0, 0]}]}, "objects[0].position[0]", "bool is not a number"),
        ({"objects": [{**CUBE, "position": ["0.3", 0, 0]}]}, "objects[0].position[0]", "'0.3' is not a number"),
        ({"objects": [{**CUBE, "size": [0.04, 0.04, 1e9]}]}, "objects[0].size[2]", "1e+09 is out of range (lengths are positive and at most 20 m)"),
        ({"objects": [{**CUBE, "size": [0.04, 0.0, 0.04]}]}, "objects[0].size[1]", "0 is not a positive length"),
        ({"objects": [{**CUBE, "size": [0.1] * 100_000}]}, "objects[0].size", "a box needs 3 numbers ([x, y, z]), got 100000"),
        ({"objects": [{**CUBE, "rpy": [0, 0, 7]}]}, "objects[0].rpy[2]", "7 is out of range (angles are within 6.283 rad"),
        ({"objects": [{**CUBE, "rpy": [math.nan, 0, 0]}]}, "objects[0].rpy[0]", "nan is not a finite number"),
        ({"objects": [{**CUBE, "graspable": 1}]}, "objects[0].graspable", "valid boolean"),
        ({"containers": [{**BOX, "yaw": math.nan}]}, "containers[0].yaw", "nan is not a finite number"),
        ({"containers": [{**BOX, "wall_m": math.inf}]}, "containers[0].wall_m", "inf is not a finite number"),
        ({"containers": [{**BOX, "size": [0.1, 0.1, -0.1]}]}, "containers[0].size[2]", "is not a positive length"),
        ({"table": {"top_z": math.nan}}, "table.top_z", "nan is not a finite number"),
        ({"table": {"size": [math.inf, 1.2]}}, "table.size[0]", "inf is not a finite number"),
        ({"table": {"center_xy": [0, 1e12]}}, "table.center_xy[1]", "1e+12 is out of range"),
        ({"table": {"thickness_m": 0}}, "table.thickness_m", "0 is not a positive length"),
        ({"workspace": {"center": [math.nan, 0, 0.15], "radius_m": 0.5}}, "workspace.center[0]", "nan is not a finite number"),
        ({"workspace": {"center": [0, 0, 0.15], "radius_m": math.inf}}, "workspace.radius_m", "inf is not a finite number"),
        ({"workspace": {"center": [0, 0, 0.15], "radius_m": 1e6}}, "workspace.radius_m", "1e+06 is out of range"),
    ],
)
def test_every_number_is_finite_and_in_range(data, path, words):
    error = refused(data)
    assert error.path == path
    assert words in str(error)


def test_a_nan_workspace_centre_can_no_longer_hide_an_error():
    # before: outside_distance was NaN everywhere, so the space-usage critic's Error became OK
    program = "move_to(0.3, 0.1, 0.2)\n"
    tiny = Scene.model_validate({"workspace": {"center": [0.0, 0.0, 0.15], "radius_m": 0.05}})
    assert critique(simulate(program, tiny), critics=["space_usage"]).verdicts[0].flag.name == "ERROR"
    assert refused({"workspace": {"center": [float("nan"), 0.0, 0.15], "radius_m": 0.05}}).path == "workspace.center[0]"


# --- ids -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "name, words",
    [
        ("print", "'print' is a builtin of robot programs"),
        ("for", "'for' is a Python keyword"),
        ("match", "'match' is a Python keyword"),
        ("None", "'None' is a Python keyword"),
        ("table", "'table' is the table's id"),
        ("__class__", "must be a Python identifier not starting with '_'"),
        ("_hidden", "must be a Python identifier not starting with '_'"),
        ("green apple", "must be a Python identifier"),
        ("", "an id cannot be empty"),
        ("a" * 65, "an id of 65 characters is longer than the limit of 64"),
        ("ﬁle", "is not in normal form: Python reads it as 'file' in a program"),
        (5, "an id is text, got int"),
    ],
)
def test_ids_are_identifiers_that_shadow_no_name_of_the_language(name, words):
    for data, path in (({"objects": [{**CUBE, "id": name}]}, "objects[0].id"), ({"containers": [{**BOX, "id": name}]}, "containers[0].id")):
        error = refused(data)
        assert error.path == path and words in str(error)


def test_the_reserved_names_come_from_their_sources():
    names = reserved_names()
    assert set(SAFE_BUILTINS) | set(keyword.kwlist) | set(keyword.softkwlist) | {"table"} == set(names)


@pytest.mark.parametrize(
    "name, words",
    [
        ("home", "'home' is a skill in robot programs; an object named so would hide it"),
        ("wait", "'wait' is a skill"),
        ("lib", "'lib' is the module 'lib' of robot programs"),
        ("skills", "'skills' is the module 'lib' of robot programs"),
        ("math", "'math' is the module 'math'"),
        ("objects", "'objects' is the list of the scene's objects in robot programs"),
        ("containers", "'containers' is the list of its containers"),
        ("open", "'open' is a name robot programs may not use, so they could not refer to this object"),
        ("type", "'type' is a name robot programs may not use"),
    ],
)
def test_ids_that_are_names_of_the_skill_api_are_refused_where_scenes_meet_programs(name, words):
    scene = Scene.model_validate({"objects": [CUBE, {**CUBE, "id": name, "position": [0.3, 0.1, 0.02]}]})
    with pytest.raises(SceneError) as info:
        check_scene_ids(scene)
    assert info.value.path == "objects[1].id" and words in str(info.value)
    assert f"choose another id (e.g. '{name}_1')" in str(info.value)
    with pytest.raises(SceneError, match="objects\\[1\\]\\.id"):
        simulate("move_to(0.3, 0.1, 0.2)\n", scene)


def test_every_refused_name_is_one_programs_use_and_every_skill_is_refused():
    # each name check_scene_ids refuses means something in a program (so refusing it loses nothing)
    program = "a = lib\nb = objects\nc = containers\nd = math\nimport robot_lib\nimport skills\nimport robocritics\nhome()\n"
    assert [c.skill for c in run_program(program, Scene()).calls] == ["home"]
    for name in [*SKILLS, *MODULE_ALIASES, "objects", "containers", *FORBIDDEN_NAMES]:
        with pytest.raises(SceneError):
            check_scene_ids(Scene.model_validate({"containers": [{**BOX, "id": name}]}))


def test_ordinary_ids_are_kept():
    # Python builtins that programs neither see nor forbid stay usable (a container called 'bin')
    scene = Scene.model_validate({"objects": [{**CUBE, "id": "hex"}], "containers": [{**BOX, "id": "bin"}]})
    check_scene_ids(scene)
    assert [c.describe() for c in run_program("move_above(bin, 0.1)\nmove_to(hex)\n", scene).calls] == [
        "move_above(bin, height=0.1)",
        "move_to(hex)",
    ]


# --- sizes, text, attributes ------------------------------------------------------------------


def test_a_scene_holds_at_most_max_entities():
    objects = [{**CUBE, "id": f"c{i}"} for i in range(MAX_ENTITIES // 2 + 1)]
    boxes = [{**BOX, "id": f"b{i}"} for i in range(MAX_ENTITIES // 2)]
    error = refused({"objects": objects, "containers": boxes})
    assert f"{MAX_ENTITIES + 1} objects and containers; a scene holds at most {MAX_ENTITIES}" in str(error)
    assert "at most 100" in str(refused({"objects": [{**CUBE, "id": f"c{i}"} for i in range(101)]}))


@pytest.mark.parametrize(
    "data, path, words",
    [
        ({"name": "x" * 201}, "name", "text of 201 characters is longer than the limit of 200"),
        ({"description": "x" * 10_001}, "description", "longer than the limit of 10,000"),
        ({"name": "a\ud800b"}, "name", "character 1 is an unpaired surrogate '\\ud800', not text"),
        ({"name": 5}, "name", "text expected, got int"),
        ({"objects": [{**CUBE, "attributes": {"tags": [[[[[[[["deep"]]]]]]]]}}]}, "objects[0].attributes.tags[0][0][0][0][0][0][0]", "attributes nest deeper than 8 levels"),
        ({"objects": [{**CUBE, "attributes": {f"a{i}": i for i in range(1001)}}]}, "objects[0].attributes.a499", "more than 1000 attribute values"),
        ({"objects": [{**CUBE, "attributes": {"ripeness": math.nan}}]}, "objects[0].attributes.ripeness", "nan is not a finite number"),
        ({"objects": [{**CUBE, "attributes": {"n": 10**30}}]}, "objects[0].attributes.n", "an integer of 100 bits; the limit is 64"),
        ({"objects": [{**CUBE, "attributes": {"s": {1, 2}}}]}, "objects[0].attributes.s", "a set is not JSON-like data"),
        ({"objects": [{**CUBE, "attributes": {"colour": "\udcff"}}]}, "objects[0].attributes.colour", "unpaired surrogate"),
        ({"objects": [{**CUBE, "attributes": {"k" * 65: 1}}]}, "objects[0].attributes", "a key of 65 characters"),
        ({"objects": [{**CUBE, "attributes": []}]}, "objects[0].attributes", "attributes are a JSON object"),
        ({"objects": [{**CUBE, "shape": "x" * 100_000}]}, "objects[0].shape", "... (100,002 characters); use one of box"),
        ({"objects": 5}, "objects", "valid list"),
        ([1, 2], "scene", "valid dictionary"),
    ],
)
def test_text_and_attributes_are_bounded(data, path, words):
    error = refused(data)
    assert error.path == path and words in str(error)
    assert len(str(error)) < 300


def test_a_cyclic_attribute_is_refused_not_recursed():
    loop: dict = {}
    loop["again"] = loop
    error = refused({"objects": [{**CUBE, "attributes": {"loop": loop}}]})
    assert "attributes nest deeper than 8 levels" in str(error) and error.path.startswith("objects[0].attributes.loop")


def test_attributes_stay_plain_json_and_built_in_scenes_are_unchanged():
    scene = Scene.model_validate({"objects": [{**CUBE, "attributes": {"tags": ("a", "b"), "fill": {"ml": 200}, "n": None}}]})
    assert scene.objects[0].attributes == {"tags": ["a", "b"], "fill": {"ml": 200}, "n": None}
    for name in Scene.builtin_names():
        scene = Scene.builtin(name)
        assert Scene.model_validate(json.loads(scene.to_json())) == scene
        check_scene_ids(scene)


@pytest.mark.parametrize(
    "make, path, words",
    [
        (lambda: SceneObject(**{**CUBE, "id": "for"}), "id", "'for' is a Python keyword"),
        (lambda: SceneObject.model_validate({**CUBE, "size": [1]}), "size", "a box needs 3 numbers"),
        (lambda: Container(id="bin", size=(0.2, 0.15, 0.1), position=(0.1, -0.2, 0.05), yaw=7.0), "yaw", "out of range"),
        (lambda: Table(top_z=float("nan")), "top_z", "nan is not a finite number"),
        (lambda: Workspace(center=(0.0, 0.0, 0.0), radius_m=-1), "radius_m", "is not a positive length"),
        (lambda: Scene(objects=[{**CUBE, "position": [0, 0, float("inf")]}]), "objects[0].position[2]", "inf is not a finite"),
    ],
)
def test_constructors_raise_scene_errors_too(make, path, words):
    with pytest.raises(SceneError) as info:
        make()
    assert info.value.path == path and words in str(info.value)


# --- files and JSON --------------------------------------------------------------------------------


def write(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    return path


def good_scene_text(**changes):
    """A one-cube scene file with fields changed; a value given as a str is written as raw JSON."""
    raw = {k: v for k, v in changes.items() if isinstance(v, str)}
    text = json.dumps({"objects": [{**CUBE, **{k: f"@{k}@" for k in raw}, **{k: v for k, v in changes.items() if k not in raw}}]})
    for k, v in raw.items():
        text = text.replace(f'"@{k}@"', v)
    return text


@pytest.mark.parametrize(
    "content, words",
    [
        (os.urandom(0) + bytes(range(256)) * 8, "is not UTF-8 text (invalid start byte at byte 128)"),
        ('{"name": "caf\xe9"}'.encode("latin-1"), "is not UTF-8 text (invalid continuation byte at byte 13)"),
        ("[" * 100_000 + "]" * 100_000, f"JSON nested 100000 deep (from line 1); the limit is {MAX_JSON_DEPTH}"),
        ('{"a": ' * 40 + "1" + "}" * 40, "JSON nested 40 deep"),
        ('"' + '\\"' * 300_000, "not valid JSON at line 1, column 1: Unterminated string"),
        ("{" + '"k": 1, ' * 10 + "}", "not valid JSON"),
        ("[1, 2]", "a scene is a JSON object, got list"),
        ("", "not valid JSON at line 1, column 1: Expecting value"),
        (good_scene_text(position="[" + "9" * 5000 + ", 0, 0.02]"), "objects[0].position[0]: a 5000-digit integer is out of range"),
        (good_scene_text(position=[1e300, 0, 0.02]), "objects[0].position[0]: 1e+300 is out of range"),
        (good_scene_text(position="[1e999, 0, 0.02]"), "objects[0].position[0]: inf is not a finite number"),
        ('{"workspace": {"center": [NaN, 0, 0.15], "radius_m": 0.5}}', "workspace.center[0]: nan is not a finite number"),
        ('{"table": {"top_z": -Infinity}}', "table.top_z: -inf is not a finite number"),
        (good_scene_text(attributes='{"n": ' + "1" * 30 + "}"), "objects[0].attributes.n: a 30-digit integer; the limit is 20 digits"),
    ],
)
def test_bad_scene_files_name_the_file_and_the_problem(tmp_path, content, words):
    path = write(tmp_path, "scene.json", content)
    tracemalloc.start()
    try:
        with pytest.raises(SceneError) as info:
            Scene.load(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert words in str(info.value)
    assert str(path) in str(info.value)
    assert peak < 80e6  # no 100k-deep recursion, no 5000-digit conversion


def test_deep_json_inside_strings_is_not_nesting(tmp_path):
    text = json.dumps({"description": "[" * 1000 + "\\\"{" * 100, "objects": [CUBE]})
    assert Scene.load(write(tmp_path, "s.json", text)).objects[0].id == "cube"
    assert Scene.load(write(tmp_path, "bom.json", b"\xef\xbb\xbf" + json.dumps({"name": "bom"}).encode())).name == "bom"


def test_files_that_are_not_scene_files(tmp_path):
    with pytest.raises(SceneError, match="is a directory, not a file"):
        Scene.load(tmp_path)
    with pytest.raises(SceneError, match="no such scene file"):
        Scene.load(tmp_path / "missing.json")
    with pytest.raises(SceneError, match="is not a regular file"):
        Scene.load("/dev/zero")  # an endless stream: refused without reading
    fifo = tmp_path / "pipe.json"
    os.mkfifo(fifo)
    with pytest.raises(SceneError, match="is not a regular file"):
        Scene.load(fifo)  # would block forever on open
    big = write(tmp_path, "big.json", '{"description": "' + "x" * MAX_FILE_BYTES + '"}')
    with pytest.raises(SceneError, match=f"is larger than the limit of {MAX_FILE_BYTES:,} bytes"):
        Scene.load(big)
    with pytest.raises(SceneError, match="cannot read scene file"):
        Scene.load("bad\x00name.json")
    with pytest.raises(SceneError, match="cannot read scene file"):
        Scene.load("x" * 5000 + ".json")
    unreadable = write(tmp_path, "locked.json", "{}")
    unreadable.chmod(0)
    try:
        if os.access(unreadable, os.R_OK):  # root reads anything
            pytest.skip("running as root")
        with pytest.raises(SceneError, match="cannot read scene file .*Permission denied"):
            Scene.load(unreadable)
    finally:
        unreadable.chmod(0o600)


def test_scene_names_and_json_text_are_bounded_too():
    error = pytest.raises(SceneError, Scene.builtin, "x" * 1000).value
    assert "no built-in scene 'xxxx" in str(error) and "(1,002 characters)" in str(error) and len(str(error)) < 200
    with pytest.raises(SceneError, match="JSON nested 50 deep"):
        Scene.model_validate_json("[" * 50 + "]" * 50)
    with pytest.raises(SceneError, match="not UTF-8 text"):
        Scene.model_validate_json(b"\xff")
    assert Scene.model_validate_json(Scene.builtin("sorting").to_json()) == Scene.builtin("sorting")
    assert parse_json('{"a": [1, 2.5, "x", null, true]}', "t") == {"a": [1, 2.5, "x", None, True]}
