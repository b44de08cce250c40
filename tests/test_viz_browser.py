"""The 3-D replay the way a person sees it: the offline HTML file and the notebook display in headless Chromium."""

from __future__ import annotations

import subprocess
import sys
from functools import lru_cache
from pathlib import Path

import pytest

import robocritics as rc
from browser import canvas_pixels, canvas_stats, chromium, save_screenshot, severe_console_errors, wait_for

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "programs" / "sorting_naive.py"
READY = "return document.querySelector('.rc-replay') && document.querySelector('.rc-replay').dataset.ready"


@lru_cache(maxsize=None)
def naive():
    execution = rc.simulate(EXAMPLE.read_text(), rc.Scene.builtin("sorting"))
    return execution, rc.critique(execution)


@pytest.fixture(scope="module")
def offline_file(tmp_path_factory) -> Path:
    """The file `robocritics check --html` writes, made by the real command."""
    out = tmp_path_factory.mktemp("replay") / "sorting_naive.html"
    proc = subprocess.run(
        [sys.executable, "-m", "robocritics", "check", str(EXAMPLE), "--scene", "sorting", "--html", str(out)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 1, proc.stderr  # the naive program has Errors
    assert out.stat().st_size > 100_000
    return out


@pytest.fixture(scope="module")
def driver():
    with chromium() as d:
        yield d


def test_offline_file_renders_the_scene_from_file_url_with_no_network(driver, offline_file):
    driver.get(offline_file.as_uri())
    wait_for(driver, READY, what="the first frame")
    canvas = driver.find_element("css selector", ".rc-canvas")
    stats = canvas_stats(driver, canvas)
    assert stats["width"] > 400 and stats["height"] > 250
    # a blank canvas has zero variance; the robot, the table and the boxes make hundreds
    assert min(stats["variance"]) > 200, stats
    # nothing was fetched: every byte came from the file
    assert driver.execute_script("return performance.getEntriesByType('resource').length") == 0
    assert severe_console_errors(driver) == []
    # the report table is below the replay
    assert "RoboCritics report" in driver.find_element("css selector", ".rc-page-report").text
    save_screenshot(driver, "replay.png")


def test_timeline_marks_every_flagged_window_in_its_flag_colour(driver, offline_file):
    _, report = naive()
    driver.get(offline_file.as_uri())
    wait_for(driver, READY, what="the first frame")
    marks = driver.execute_script(
        "return [...document.querySelectorAll('.rc-mark')].map(m => [m.dataset.critic, m.dataset.flag])"
    )
    for v in report.verdicts:
        shown = [m for m in marks if m[0] == v.critic]
        if v.flag is rc.Flag.OK:
            assert shown == []
        else:
            assert len(shown) == len(v.evidence.sample_ranges) and all(f == v.flag.value for _, f in shown)
    rows = driver.find_elements("css selector", ".rc-verdict")
    assert [r.get_attribute("data-critic") for r in rows if r.get_attribute("data-flag") == "ERROR"] == [
        v.critic for v in report.errors
    ]


def test_scrubbing_moves_the_robot(driver, offline_file):
    driver.get(offline_file.as_uri())
    wait_for(driver, READY, what="the first frame")
    canvas = driver.find_element("css selector", ".rc-canvas")
    caption = driver.find_element("css selector", ".rc-caption")
    before, caption_before = canvas_pixels(driver, canvas), caption.text
    scrub = driver.find_element("css selector", "input.rc-scrub")
    # drag the slider the way a person does: click at 60 % of its width
    from selenium.webdriver.common.action_chains import ActionChains

    width = scrub.size["width"]
    ActionChains(driver).move_to_element_with_offset(scrub, int(width * 0.1), 0).click().perform()
    replay = driver.find_element("css selector", ".rc-replay")
    t = float(wait_for(driver, "return arguments[0].dataset.time > 0 && arguments[0].dataset.time", replay))
    duration = naive()[0].duration_s
    assert 0.45 * duration < t < 0.75 * duration
    wait_for(driver, "return !document.querySelector('.rc-replay')._renderQueued")
    after = canvas_pixels(driver, canvas)
    assert after != before  # the arm moved
    assert caption.text != caption_before and caption.text.startswith("line ")


def test_clicking_a_verdict_jumps_to_its_worst_moment(driver, offline_file):
    _, report = naive()
    driver.get(offline_file.as_uri())
    wait_for(driver, READY, what="the first frame")
    replay = driver.find_element("css selector", ".rc-replay")
    for v in report.errors + report.warnings:
        driver.find_element("css selector", f'.rc-verdict[data-critic="{v.critic}"]').click()
        t = float(wait_for(driver, "return arguments[0].dataset.selected === arguments[1] && arguments[0].dataset.time",
                           replay, v.critic))  # fmt: skip
        assert t == pytest.approx(v.evidence.worst_time_s - naive()[0].trajectory.time[0], abs=1e-3), v.critic
    # a timeline mark selects its verdict too
    collision = report.verdict("collision")
    if collision.flag is not rc.Flag.OK:
        driver.find_element("css selector", '.rc-mark[data-critic="collision"]').click()
        wait_for(driver, "return arguments[0].dataset.selected === 'collision'", replay)


def test_play_advances_time_at_the_chosen_speed_and_stops_at_the_end(driver, offline_file):
    driver.get(offline_file.as_uri())
    wait_for(driver, READY, what="the first frame")
    replay = driver.find_element("css selector", ".rc-replay")
    from selenium.webdriver.support.ui import Select

    Select(driver.find_element("css selector", "select.rc-speed")).select_by_value("4")
    driver.execute_script("window.replay.seek(window.replay.duration - 1.0)")
    driver.find_element("css selector", ".rc-play").click()
    # at 4x the last second of motion takes 0.25 s of page time; then playback stops at the end (loop off)
    wait_for(driver, "return !arguments[0].dataset.playing", replay, what="playback to stop at the end")
    assert float(replay.get_attribute("data-time")) == pytest.approx(naive()[0].duration_s, abs=1e-3)
    # with loop on it wraps around and keeps playing
    driver.find_element("css selector", "input.rc-loop").click()
    driver.execute_script("window.replay.seek(window.replay.duration - 0.5)")
    driver.find_element("css selector", ".rc-play").click()
    wait_for(driver, "return arguments[0].dataset.playing && parseFloat(arguments[0].dataset.time) < 5", replay,
             what="the loop to wrap around")  # fmt: skip
    driver.find_element("css selector", ".rc-play").click()


def test_notebook_display_renders_inside_its_iframe(driver, tmp_path):
    execution, report = naive()
    notebook_like = tmp_path / "cell.html"
    notebook_like.write_text(f"<html><body><h3>cell output</h3>{execution.show(report)._repr_html_()}</body></html>")
    driver.get(notebook_like.as_uri())
    frame = driver.find_element("css selector", "iframe.robocritics-replay")
    driver.switch_to.frame(frame)
    try:
        wait_for(driver, READY, what="the replay inside the iframe")
        stats = canvas_stats(driver, driver.find_element("css selector", ".rc-canvas"))
        assert min(stats["variance"]) > 200, stats
        assert len(driver.find_elements("css selector", ".rc-verdict")) == len(report.verdicts)
    finally:
        driver.switch_to.default_content()


def test_a_long_program_replay_spreads_its_flagged_windows_over_the_whole_timeline(driver, tmp_path):
    # a palletising-like program of ~3 minutes: its report keeps at most 20 flagged windows spread over the run
    # (critic.verdict.kept_runs), and the replay's timeline shows them where they happen, not bunched at the start
    from long_program import repeated_sorting

    program = tmp_path / "long_sorting.py"
    program.write_text(repeated_sorting(12))
    out = tmp_path / "long_sorting.html"
    proc = subprocess.run(
        [sys.executable, "-m", "robocritics", "check", str(program), "--scene", "sorting", "--html", str(out)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode in (0, 1), proc.stderr
    assert out.stat().st_size < 8_000_000  # thinned frames: the file stays bounded whatever the length
    driver.get(out.as_uri())
    wait_for(driver, READY, what="the first frame")
    marks = driver.execute_script(
        "return [...document.querySelectorAll('.rc-mark')].map(m => {"
        " const r = m.getBoundingClientRect(), t = m.parentElement.getBoundingClientRect();"
        " return [m.dataset.critic, (r.left - t.left) / t.width]; })"
    )
    assert marks, "a long sorting run has flagged windows"
    for critic in {c for c, _ in marks}:
        lefts = sorted(x for c, x in marks if c == critic)
        assert len(lefts) <= 20
        if len(lefts) >= 5:  # spread: the first in the first fifth of the run, the last in its last fifth
            assert lefts[0] < 0.2 and lefts[-1] > 0.8, (critic, lefts)
    canvas = driver.find_element("css selector", ".rc-canvas")
    assert min(canvas_stats(driver, canvas)["variance"]) > 200
    assert severe_console_errors(driver) == []
    save_screenshot(driver, "replay_long_program.png")
