"""Replay data (robocritics.viz.replay_data) cross-checked against the trajectory, the robot and the critics."""

from __future__ import annotations

import base64
import json
import re
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

import robocritics as rc
from robocritics.geometry.pairs import closest_points
from robocritics.viz import MAX_FRAME_RATE_HZ, REPLAY_FORMAT, Replay, replay_data, replay_html
from robocritics.viz.html import script_json

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "programs"


@lru_cache(maxsize=None)
def run(name: str):
    scene = rc.Scene.builtin(name.split("_")[0])
    execution = rc.simulate((EXAMPLES / f"{name}.py").read_text(), scene)
    return execution, rc.critique(execution)


def f32(blob) -> np.ndarray:
    assert blob["dtype"] == "float32"
    return np.frombuffer(base64.b64decode(blob["data"]), dtype="<f4").reshape(blob["shape"])


def frame_samples(execution, data) -> np.ndarray:
    """Map each frame back to its trajectory sample by its time."""
    t = np.asarray(execution.trajectory.time) - execution.trajectory.time[0]
    times = f32(data["time_s"])
    idx = np.searchsorted(t, times - 1e-6)
    assert np.allclose(t[idx], times, atol=1e-5)
    return idx


def test_capsule_ends_are_the_robot_capsules_at_the_drawn_samples():
    execution, report = run("sorting_naive")
    data = replay_data(execution, report)
    assert data["format"] == REPLAY_FORMAT
    idx = frame_samples(execution, data)
    p0, p1 = execution.robot.capsule_segments(execution.trajectory.frames[idx])
    ends = f32(data["capsule_ends"])
    assert ends.shape == (len(idx), len(execution.robot.capsules), 6)
    np.testing.assert_allclose(ends[..., :3], p0, atol=1e-6)
    np.testing.assert_allclose(ends[..., 3:], p1, atol=1e-6)
    assert [c["name"] for c in data["capsules"]] == list(execution.robot.capsule_names)
    np.testing.assert_allclose([c["radius_m"] for c in data["capsules"]], execution.robot.capsule_radii)


def test_frames_are_thinned_but_keep_every_verdicts_worst_sample_and_window_bounds():
    execution, report = run("sorting_naive")
    data = replay_data(execution, report)
    idx = frame_samples(execution, data)
    assert idx[0] == 0 and idx[-1] == len(execution.trajectory) - 1
    assert np.all(np.diff(idx) > 0)
    # thinned: the regular frames are at most MAX_FRAME_RATE_HZ (the kept samples come on top)
    kept = set()
    for v in report.verdicts:
        ev = v.evidence
        kept |= {s for s in (ev.worst_sample, ev.first_sample, ev.last_sample) if s is not None}
        kept |= {s for r in ev.sample_ranges for s in r}
    assert kept <= set(idx.tolist())
    regular = len(set(idx.tolist()) - kept)
    assert regular <= execution.duration_s * MAX_FRAME_RATE_HZ + 2
    assert len(idx) < len(execution.trajectory) / 2


def test_verdicts_carry_flags_windows_and_worst_times_of_the_report():
    execution, report = run("sorting_naive")
    data = replay_data(execution, report)
    t0 = execution.trajectory.time[0]
    assert [v["critic"] for v in data["verdicts"]] == report.critics
    for shown, v in zip(data["verdicts"], report.verdicts):
        assert shown["flag"] == v.flag.value
        assert shown["message"] == v.message and shown["hint"] == v.hint
        if v.flag is rc.Flag.OK:
            assert shown["windows_s"] == []
            continue
        assert shown["windows_s"], v.critic
        expected = [[execution.trajectory.time[a] - t0, execution.trajectory.time[b] - t0] for a, b in v.evidence.sample_ranges]
        np.testing.assert_allclose(shown["windows_s"], expected, atol=1e-9)
        assert shown["worst_time_s"] == pytest.approx(v.evidence.worst_time_s)
        assert shown["links"] == v.evidence.links and shown["objects"] == v.evidence.objects
    assert data["score_text"] == report.score_text


@pytest.mark.parametrize("name", ["sorting_naive", "recycling_naive", "breakfast_naive"])
def test_closest_points_segment_has_the_length_the_critic_measured(name):
    # coal's closest points (viz) against the critic's own distance (geometry.proximity): two implementations
    execution, report = run(name)
    data = replay_data(execution, report)
    checked = 0
    for shown, v in zip(data["verdicts"], report.verdicts):
        if "closest_pair" not in v.details:
            assert shown["segment"] is None
            continue
        a, b = np.array(shown["segment"])
        distance = v.details["closest_distance_m"]
        if distance > 0:
            assert np.linalg.norm(b - a) == pytest.approx(distance, abs=2e-4), v.critic
        checked += 1
    assert checked >= 1


def test_closest_points_of_two_known_shapes():
    pose_a, pose_b = np.eye(4), np.eye(4)
    pose_b[:3, 3] = (0.5, 0.0, 0.0)
    pa, pb, d = closest_points("sphere", (0.1,), pose_a, "box", (0.2, 0.2, 0.2), pose_b)
    assert d == pytest.approx(0.5 - 0.1 - 0.1, abs=1e-9)
    np.testing.assert_allclose(pa, (0.1, 0, 0), atol=1e-9)
    np.testing.assert_allclose(pb, (0.4, 0, 0), atol=1e-9)
    # a capsule along z (length 0.4 m, radius 0.05 m) beside a sphere at the height of its end
    pose_b[:3, 3] = (0.3, 0.0, 0.2)
    pa, pb, d = closest_points("capsule", (0.05, 0.4), pose_a, "sphere", (0.05,), pose_b)
    assert d == pytest.approx(0.3 - 0.05 - 0.05, abs=1e-9)


def test_a_carried_object_moves_with_the_tcp_and_rests_where_it_was_released():
    execution, report = run("sorting_naive")
    data = replay_data(execution, report)
    idx = frame_samples(execution, data)
    tcp = execution.trajectory.tcp[idx] if execution.trajectory.tcp.ndim == 3 else None
    attached = np.array(data["attached"])
    moved = [o for o in data["objects"] if "poses" in o]
    assert {o["id"] for o in moved} == set(execution.object_poses)
    for o in moved:
        poses = f32(o["poses"]).reshape(-1, 3, 4)
        carried = attached == data["attached_ids"].index(o["id"])
        assert carried.sum() > 2
        # while carried, the object's pose relative to the TCP is constant
        rel = [np.linalg.inv(tcp[i]) @ np.vstack([poses[i], [0, 0, 0, 1]]) for i in np.flatnonzero(carried)[:1]]
        for i in np.flatnonzero(carried):
            np.testing.assert_allclose(np.linalg.inv(tcp[i]) @ np.vstack([poses[i], [0, 0, 0, 1]]), rel[0], atol=1e-4)
        # after the last carry it no longer moves
        last = np.flatnonzero(carried)[-1]
        np.testing.assert_allclose(poses[last + 1 :], np.broadcast_to(poses[-1], poses[last + 1 :].shape), atol=1e-6)
        # and it starts where the scene put it
        np.testing.assert_allclose(poses[0].reshape(-1), o["pose"], atol=1e-5)


def test_scene_boxes_are_the_containers_and_the_table():
    execution, _ = run("recycling_naive")
    data = replay_data(execution)
    owners = [b["owner"] for b in data["boxes"]]
    for c in execution.scene.containers:
        assert owners.count(c.id) == len(c.shapes()) == 5
    assert owners.count("table") == 1
    assert data["verdicts"] == [] and data["score_text"] is None
    json.dumps(data, allow_nan=False)  # plain JSON, no NaN


def test_replay_data_refuses_what_is_not_an_execution():
    execution, _ = run("sorting_naive")
    with pytest.raises(TypeError, match="Execution"):
        replay_data(execution.trajectory)


@pytest.mark.parametrize("hostile", ["</script><script>alert(1)</script>", "<!-- x", "a & b", "\u2028"])
def test_script_json_cannot_close_its_script_element(hostile):
    text = script_json({"message": hostile})
    assert "</" not in text and "<!--" not in text and "<" not in text
    assert json.loads(text) == {"message": hostile}


def test_offline_page_references_nothing_outside_itself():
    execution, report = run("sorting_naive")
    page = replay_html(execution, report)
    # no element loads anything: no src/href attributes, no CSS url(), no module import
    assert not re.search(r"""<(script|link|img|iframe)[^>]*\s(src|href)\s*=""", page, re.I)
    assert "url(" not in page.split("<script>")[0]
    assert "Content-Security-Policy" in page and "default-src 'none'" in page
    assert page.count("<script") == 4  # data, three.js, replay.js, mount


def test_hostile_scene_text_is_escaped_in_the_page():
    execution, report = run("sorting_naive")
    page = replay_html(execution, report, title="</title><script>alert(1)</script>")
    assert "<script>alert(1)" not in page


def test_notebook_display_is_an_iframe_holding_the_whole_page():
    execution, report = run("sorting_naive")
    shown = execution.show(report)
    assert isinstance(shown, Replay)
    html = shown._repr_html_()
    assert html.startswith("<iframe") and 'sandbox="allow-scripts"' in html
    assert "<script" not in html  # all of it is inside the escaped srcdoc attribute
    import html as html_module

    srcdoc = html_module.unescape(re.search(r'srcdoc="([^"]*)"', html).group(1))
    assert srcdoc == shown.html and "RoboReplay.mount" in srcdoc


def test_a_plugin_verdict_with_odd_numbers_still_renders():
    # a third-party critic may report NaN, infinity or sample ranges beyond the trajectory
    execution, report = run("sorting_naive")
    odd = rc.Verdict(
        critic="odd_plugin", flag=rc.Flag.WARNING, message="<b>odd</b>", value=float("nan"), threshold=float("inf"),
        evidence={"sample_ranges": [(5, 3), (10**9, 10**9 + 1), (2, 4)], "worst_time_s": float("nan")},
    )  # fmt: skip
    data = replay_data(execution, report.model_copy(update={"verdicts": [*report.verdicts, odd]}))
    shown = data["verdicts"][-1]
    assert shown["value"] is None and shown["threshold"] is None and shown["worst_time_s"] is None
    t = execution.trajectory.time
    assert shown["windows_s"] == [[t[2] - t[0], t[4] - t[0]]]
    page = script_json(data)
    assert "<b>" not in page and json.loads(page)["verdicts"][-1]["message"] == "<b>odd</b>"


def test_the_replay_draws_any_arm_its_capsules_and_its_reach():
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from test_robots import scaled_sorting

    from robocritics.robot.model import Robot

    robot = Robot.panda()
    execution = rc.simulate((EXAMPLES / "sorting_careful.py").read_text(), scaled_sorting(robot), robot=robot)
    data = replay_data(execution, rc.critique(execution))
    assert [c["name"] for c in data["capsules"]] == list(robot.capsule_names)
    assert f32(data["capsule_ends"]).shape[1] == len(robot.capsules)
    assert data["robot"] == "panda"
    assert data["workspace"]["radius_m"] == pytest.approx(robot.workspace.radius_m)


def test_a_long_motion_is_thinned_to_a_bounded_replay_with_its_flagged_windows_whole(monkeypatch):
    # a long program's replay stays bounded: the sorting run drawn in at most 120 frames keeps its flagged windows
    # at the full frame rate (every stride-th sample in them) and thins the rest
    import robocritics.viz.replay as replay

    execution, report = run("sorting_naive")
    full = frame_samples(execution, replay_data(execution, report))
    monkeypatch.setattr(replay, "MAX_REPLAY_FRAMES", 120)
    idx = frame_samples(execution, replay_data(execution, report))
    windows = [r for v in report.verdicts if v.flag != rc.Flag.OK for r in v.evidence.sample_ranges]
    in_windows = {s for s in full.tolist() if any(a <= s <= b for a, b in windows)}
    assert len(in_windows) <= 60 and in_windows <= set(idx.tolist())  # every frame inside a window kept
    kept = {s for v in report.verdicts for s in (v.evidence.worst_sample, v.evidence.first_sample,
                                                  v.evidence.last_sample) if s is not None}
    kept |= {s for v in report.verdicts for r in v.evidence.sample_ranges for s in r}
    assert kept <= set(idx.tolist())
    assert len(set(idx.tolist()) - kept) <= 120 + 1 and len(idx) < len(full)  # the regular frames: the budget
    # an hour at 500 Hz: a bounded number of frames, a flagged minute at the full frame rate
    monkeypatch.undo()
    time_s = np.arange(1_800_000) / 500.0
    frames = replay._frame_samples(time_s, [5, 1_000_000], [(900_000, 930_000)])
    assert len(frames) <= replay.MAX_REPLAY_FRAMES + 4
    window = frames[(frames >= 900_000) & (frames <= 930_000)]
    assert len(window) >= 60 * replay.MAX_FRAME_RATE_HZ and np.diff(window).max() <= 500 / replay.MAX_FRAME_RATE_HZ + 1
