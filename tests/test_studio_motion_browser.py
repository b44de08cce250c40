"""Motion from other tools in the studio (issue 25), as a person sees it in headless Chromium against the real
`robocritics studio --program FILE` process: a URScript file (its lines flagged in the editor, editable, Run
again) and a ur_rtde recording (a read-only summary whose findings name times); both replayed with the critics'
windows on the timelines; Fix, chat and Deploy off with the reason."""

from __future__ import annotations

import json
import urllib.error
import urllib.request
import contextlib
from pathlib import Path

import pytest

from browser import canvas_stats, chromium, click, save_screenshot, set_editor, severe_console_errors, studio_process, \
    wait_for
from robocritics import Scene, critique, simulate
from robocritics.formats import load_motion

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "tests" / "data" / "urscript" / "handwritten_timed_moves.script"
NAIVE = (ROOT / "examples" / "programs" / "sorting_naive.py").read_text()


@pytest.fixture(scope="module")
def driver():
    with chromium() as d:
        yield d


def post(url: str, path: str, body: dict) -> tuple[int, dict]:
    request = urllib.request.Request(url.split("?")[0] + path, data=json.dumps(body).encode(), method="POST",
                                     headers={"X-Studio": "1", "Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(request, timeout=60) as response:
            return response.status, json.loads(response.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


@contextlib.contextmanager
def studio_page(driver, *args: str):
    """``robocritics studio ARGS`` with the page open on it; the page is closed before the studio stops (so its
    polling does not log the stopped server's refusals into the next test)."""
    with studio_process(*args) as (url, _):
        try:
            first_revision(driver, url)
            yield url
        finally:
            driver.get("about:blank")


def first_revision(driver, url: str) -> None:
    driver.get(url)
    wait_for(driver, "return document.body.dataset.ready === '1' && "
                     "document.querySelector('#history li.current[data-index=\"1\"]') && "
                     "document.getElementById('replay').dataset.ready === '1'", what="the file judged and replayed")


def flags(driver) -> dict[str, str]:
    """The critics rows that show a verdict (installed critics that are not run by default show none)."""
    return driver.execute_script(
        "const o = {}; for (const r of document.querySelectorAll('#critics .critic')) if (r.dataset.flag !== 'none') "
        "o[r.dataset.critic] = r.dataset.flag; return o;")


def timeline_marks(driver) -> dict[str, str]:
    return driver.execute_script(
        "const o = {}; for (const m of document.querySelectorAll('#replay .rc-mark')) o[m.dataset.critic] = "
        "m.dataset.flag.toLowerCase(); return o;")


def assert_replayed(driver) -> None:
    stats = canvas_stats(driver, driver.find_element("css selector", "#replay .rc-canvas"))
    assert max(stats["variance"]) > 50, stats  # the arm and the scene drawn, not a blank canvas


def assert_imported_controls(driver, url: str, why: str) -> None:
    """Fix, Fix all and chat disabled saying ``why``; Deploy disabled, and refused by the API too."""
    controls = driver.execute_script(
        "const fix = [...document.querySelectorAll('#critics .fix')];"
        "return {fix: fix.length && fix.every(b => b.disabled), titles: fix.map(b => b.title),"
        "all: document.getElementById('fix-all').disabled, allTitle: document.getElementById('fix-all').title,"
        "chat: document.getElementById('chat-input').disabled, chatStatus: document.getElementById('chat-status').textContent,"
        "deploy: document.getElementById('deploy').disabled, deployTitle: document.getElementById('deploy').title}")
    assert controls["fix"] and controls["all"] and controls["chat"] and controls["deploy"], controls
    assert all(why in t for t in controls["titles"]) and why in controls["allTitle"], controls
    assert why in controls["chatStatus"], controls
    assert "not deployed" in controls["deployTitle"], controls
    status, answer = post(url, "api/deploy", {"index": 1})
    assert status == 409 and "not deployed" in answer["error"], answer
    status, answer = post(url, "api/fix", {})
    assert status == 409 and why in answer["error"], answer


def test_a_urscript_file_is_judged_with_its_lines_marked_and_can_be_edited_and_run_again(driver):
    expected = critique(load_motion(SCRIPT, scene=Scene()))
    flagged = {v.critic: v for v in expected.verdicts if v.flag.value.lower() != "ok"}
    assert flagged, "the test script should give a finding to show"
    with studio_page(driver, "--program", str(SCRIPT)) as url:
        assert driver.execute_script("return document.getElementById('editor').value") == SCRIPT.read_text()
        assert not driver.execute_script("return document.getElementById('editor').readOnly")
        assert "URScript" in driver.execute_script("return document.getElementById('editor-status').textContent")
        assert flags(driver) == {v.critic: v.flag.value.lower() for v in expected.verdicts}
        for name, verdict in flagged.items():  # the critic's URScript lines marked in the gutter, its window drawn
            for line in verdict.evidence.lines:
                mark = driver.execute_script(
                    "const d = document.querySelector(`#gutter .ln[data-line=\"${arguments[0]}\"]`);"
                    "return d && d.classList.contains('flagged') && d.dataset.flag", line)
                assert mark == verdict.flag.value.lower(), (name, line)
            assert timeline_marks(driver).get(name) == verdict.flag.value.lower(), name
        source = driver.execute_script("return document.getElementById('replay-note').textContent")
        assert SCRIPT.name in source
        assert_replayed(driver)
        assert_imported_controls(driver, url, "skill API")
        save_screenshot(driver, "studio-urscript.png")

        # the edited script is what Run judges: a construct outside the subset is the runtime Error at its line
        edited = SCRIPT.read_text().replace("movel(", "movez(", 1)
        line = next(i for i, text in enumerate(edited.splitlines(), 1) if "movez(" in text)
        wait_for(driver, "return !document.getElementById('run').disabled", what="Run enabled")
        set_editor(driver, edited)
        driver.execute_script("delete document.body.dataset.lastRun")
        click(driver, "run")
        wait_for(driver, "return document.body.dataset.lastRun === '2'", what="the edited script's revision")
        assert flags(driver)["runtime"] == "error"
        marked = driver.execute_script("return [...document.querySelectorAll('#gutter .ln.flagged')].map(d => +d.dataset.line)")
        assert marked == [line]
        terminal = driver.execute_script("return document.getElementById('terminal').textContent")
        assert "movez" in terminal and f"line {line}" in terminal, terminal
        assert not [e for e in severe_console_errors(driver) if "favicon" not in e]


def test_a_ur_rtde_recording_is_judged_with_times_replayed_and_read_only(driver, tmp_path):
    run = simulate(NAIVE, Scene.builtin("sorting"))
    csv = tmp_path / "cell_recording.csv"
    rows = ["timestamp," + ",".join(f"actual_q_{i}" for i in range(6)) + ",actual_TCP_pose_0"]
    for t, q in zip(run.trajectory.time, run.trajectory.q):  # a controller clock that does not start at 0
        rows.append(f"{1712.5 + t:.6f}," + ",".join(f"{v:.9f}" for v in q) + ",0.1")
    csv.write_text("\n".join(rows) + "\n")
    expected = critique(load_motion(csv, scene=Scene.builtin("sorting")))
    findings = [v for v in expected.verdicts if v.flag.value.lower() != "ok"]
    assert any(v.flag.value.lower() == "error" for v in findings), "the naive program's motion has Errors"
    with studio_page(driver, "--program", str(csv), "--scene", "sorting") as url:
        assert flags(driver) == {v.critic: v.flag.value.lower() for v in expected.verdicts}
        editor = driver.execute_script("const e = document.getElementById('editor'); return [e.readOnly, e.value]")
        assert editor[0] is True
        assert "ur_rtde recording cell_recording.csv" in editor[1]
        terminal = driver.execute_script("return document.getElementById('terminal').textContent")
        for v in findings:  # each finding named by its times, in the summary and in the terminal
            start, end = v.evidence.time_window_s
            assert f"{start:.2f}-{end:.2f} s  {v.flag.value.capitalize()} [{v.critic}]" in editor[1], v.critic
            assert f"[{v.critic}] (at {start:.2f}-{end:.2f} s)" in terminal, (v.critic, terminal)
            assert timeline_marks(driver).get(v.critic) == v.flag.value.lower(), v.critic
        assert driver.execute_script("return document.querySelectorAll('#gutter .ln.flagged').length") == 0
        assert_replayed(driver)
        assert_imported_controls(driver, url, "recording")
        save_screenshot(driver, "studio-recording.png")
        assert not [e for e in severe_console_errors(driver) if "favicon" not in e]
