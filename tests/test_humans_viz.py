"""People in the replay: the body-region capsules in the replay data, and drawn in headless Chromium."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import robocritics as rc
from browser import canvas_pixels, chromium, save_screenshot, severe_console_errors, wait_for
from robocritics.humans import BODY_REGIONS
from robocritics.viz.replay import replay_data

ROOT = Path(__file__).resolve().parent.parent
NAIVE = ROOT / "examples" / "programs" / "workbench_naive.py"
READY = "return document.querySelector('.rc-replay') && document.querySelector('.rc-replay').dataset.ready"


@pytest.fixture(scope="module")
def naive():
    execution = rc.simulate(NAIVE.read_text(), rc.Scene.builtin("workbench"))
    return execution, rc.critique(execution)


def test_replay_data_holds_every_body_region_and_names_the_person_a_verdict_involves(naive):
    execution, report = naive
    data = replay_data(execution, report)
    (person,) = data["humans"]
    assert person["id"] == "operator"
    assert {c["region"] for c in person["capsules"]} == set(BODY_REGIONS)
    assert all(c["name"].startswith("operator.") and c["radius_m"] > 0 for c in person["capsules"])
    separation = next(v for v in data["verdicts"] if v["critic"] == "separation")
    assert separation["flag"] == "ERROR" and "operator" in separation["objects"]
    contact = next(v for v in data["verdicts"] if v["critic"] == "contact_speed")
    assert any(o.startswith("operator.") for o in contact["objects"])  # the body capsule closest to contact


def test_the_operator_is_drawn_in_the_offline_file(naive, tmp_path):
    out = tmp_path / "workbench_naive.html"
    proc = subprocess.run(
        [sys.executable, "-m", "robocritics", "check", str(NAIVE), "--scene", "workbench", "--html", str(out)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 1, proc.stderr  # the naive program fails separation
    execution, report = naive
    without = tmp_path / "no_people.html"
    empty = execution.scene.model_copy(update={"humans": []})
    from dataclasses import replace

    rc.viz.Replay(replace(execution, scene=empty), report).save(without)
    with chromium() as driver:
        driver.get(out.as_uri())
        wait_for(driver, READY, what="the first frame")
        replay = driver.find_element("css selector", ".rc-replay")
        assert replay.get_attribute("data-people") == "1"
        assert severe_console_errors(driver) == []
        with_people = canvas_pixels(driver, driver.find_element("css selector", ".rc-canvas"))
        save_screenshot(driver, "workbench.png")
        driver.get(without.as_uri())
        wait_for(driver, READY, what="the first frame")
        assert driver.find_element("css selector", ".rc-replay").get_attribute("data-people") == "0"
        assert canvas_pixels(driver, driver.find_element("css selector", ".rc-canvas")) != with_people


def test_the_studio_shows_the_operator_and_the_separation_error(naive):
    from robocritics.viz.studio import Studio

    _, report = naive
    with chromium() as driver, Studio("workbench", NAIVE.read_text()) as studio:
        driver.get(studio.url)
        wait_for(driver, "return document.body.dataset.ready === '1'", what="the studio page to start")
        driver.execute_script("document.getElementById('run').click()")
        wait_for(driver, "const r = document.querySelector('#critics .critic[data-critic=\"separation\"]'); "
                         "return r && ['ok', 'warning', 'error'].includes(r.dataset.flag)",
                 what="the separation critic's flag after Run")
        shown = driver.execute_script(
            "const o = {}; for (const r of document.querySelectorAll('#critics .critic')) o[r.dataset.critic] = "
            "r.dataset.flag; return o;")
        assert shown["separation"] == "error" == report.verdict("separation").flag.value.lower()
        wait_for(driver, "return document.getElementById('replay').dataset.ready === '1'", what="the replay")
        assert driver.execute_script("return document.getElementById('replay').dataset.people") == "1"
        driver.execute_script("document.querySelector('#critics .critic[data-critic=\"separation\"]').click()")
        wait_for(driver, "return document.getElementById('replay').dataset.selected === 'separation'")
        save_screenshot(driver, "studio_workbench.png")
        assert not [e for e in severe_console_errors(driver) if "favicon" not in e]
