"""The studio as a person sees it, in headless Chromium: Run, critics, timeline, replay, Fix with approval, chat
streaming, Deploy. Real parts only: the Evaluator's worker process, the loopback LLM server, the loopback UR
controller."""

from __future__ import annotations

import json

import time
from pathlib import Path

import pytest

from browser import canvas_stats, chromium, save_screenshot, severe_console_errors, wait_for
from llm_server import LLMServer
from robocritics import Scene, critique, simulate
from robocritics.llm.client import OpenAICompatible
from robocritics.viz.studio import Studio

ROOT = Path(__file__).resolve().parent.parent
NAIVE = (ROOT / "examples" / "programs" / "sorting_naive.py").read_text()
CAREFUL = (ROOT / "examples" / "programs" / "sorting_careful.py").read_text()


@pytest.fixture(scope="module")
def driver():
    with chromium() as d:
        yield d


def open_studio(driver, studio):
    driver.get(studio.url)
    wait_for(driver, "return document.body.dataset.ready === '1'", what="the studio page to start")


def press_run(driver):
    started = time.monotonic()
    driver.execute_script("document.getElementById('run').click()")
    wait_for(driver, "return document.querySelectorAll('#critics .critic[data-flag=\"error\"],"
                     "#critics .critic[data-flag=\"ok\"],#critics .critic[data-flag=\"warning\"]').length >= 5",
             what="the critics' flags after Run")
    return time.monotonic() - started


def press_run_again(driver) -> float:
    """Seconds from pressing Run until a NEW revision's flags are shown."""
    count = driver.execute_script("return document.querySelectorAll('#history li').length")
    started = time.monotonic()
    driver.execute_script("document.getElementById('run').click()")
    wait_for(driver, f"return document.querySelectorAll('#history li').length > {count} && "
                     "!document.body.dataset.running", what="the second Run")
    return time.monotonic() - started


def flags(driver) -> dict[str, str]:
    return driver.execute_script(
        "const o = {}; for (const r of document.querySelectorAll('#critics .critic')) o[r.dataset.critic] = "
        "r.dataset.flag; return o;")


def test_run_on_sorting_naive_shows_the_critics_timeline_and_robot(driver):
    expected = critique(simulate(NAIVE, Scene.builtin("sorting")))
    with Studio("sorting", NAIVE) as studio:
        open_studio(driver, studio)
        elapsed = press_run(driver)
        print(f"studio: Run to flags shown took {elapsed:.2f} s (first Run, worker warming up)")
        print(f"studio: Run to flags shown took {press_run_again(driver):.2f} s (second Run)")
        shown = flags(driver)
        for v in expected.verdicts:
            assert shown[v.critic] == v.flag.value.lower(), v.critic
        score = float(driver.execute_script("return document.getElementById('score').dataset.score"))
        assert score == pytest.approx(expected.score)
        # the timeline marks the Error windows
        error_marks = driver.execute_script(
            "return [...document.querySelectorAll('.rc-timeline .rc-mark')]"
            ".filter(m => m.dataset.flag.toLowerCase() === 'error').map(m => m.dataset.critic)")
        assert set(error_marks) == {v.critic for v in expected.errors}
        # flagged program lines are marked in the editor's gutter
        marked = driver.execute_script(
            "return [...document.querySelectorAll('#gutter .ln.flagged')].map(e => Number(e.dataset.line))")
        lines = {n for v in expected.verdicts if not v.ok for n in v.evidence.lines}
        assert set(marked) == lines
        wait_for(driver, "return document.getElementById('replay').dataset.ready === '1'", what="the replay")
        stats = canvas_stats(driver, driver.find_element("css selector", "#replay .rc-canvas"))
        assert max(stats["variance"]) > 50, stats
        # the terminal has the feedback text
        terminal = driver.find_element("id", "terminal").get_attribute("textContent")
        assert set(expected.feedback().strip().splitlines()) <= set(terminal.splitlines())
        # Deploy is disabled: the report has an Error (and no controller is configured)
        assert driver.find_element("id", "deploy").get_attribute("disabled") is not None
        # a verdict click moves the time cursor to its worst moment
        worst = next(v for v in expected.errors if v.evidence.worst_time_s)
        driver.execute_script("document.getElementById('replay').dataset.time = '-1'")
        driver.execute_script(f"document.querySelector('#critics .critic[data-critic=\"{worst.critic}\"]').click()")
        t = float(wait_for(driver, "const t = document.getElementById('replay').dataset.time; "
                                   "return t !== '-1' && t", what="the time cursor to move"))
        assert t == pytest.approx(worst.evidence.worst_time_s, abs=0.1)
        driver.set_window_size(1400, 900)
        driver.execute_script(f"document.querySelector('#critics .critic[data-critic=\"{worst.critic}\"]').click()")
        time.sleep(0.5)  # let the highlight render before the screenshot (not an assertion)
        save_screenshot(driver, "studio.png")
        assert not [e for e in severe_console_errors(driver) if "favicon" not in e]


def test_chat_is_disabled_with_a_message_without_an_endpoint(driver):
    with Studio("sorting", NAIVE) as studio:
        open_studio(driver, studio)
        assert driver.find_element("id", "chat-input").get_attribute("disabled") is not None
        assert "LLM endpoint" in driver.find_element("id", "chat-status").text


def fenced(program: str) -> str:
    return "Here is the revised program.\n```python\n" + program + "```\n"


def test_fix_all_shows_the_diff_for_approval_then_the_new_score(driver):
    with LLMServer() as llm:
        llm.reply(fenced(CAREFUL))
        model = OpenAICompatible(base_url=llm.url, model="test-chat")
        with Studio("sorting", NAIVE, model=model) as studio:
            open_studio(driver, studio)
            press_run(driver)
            driver.execute_script("document.getElementById('fix-all').click()")
            # first the critics' own repairs (run in the studio's worker), then the model's revision: each approved
            wait_for(driver, "return !document.getElementById('approval').hidden", what="the repair's approval")
            repair_diff = driver.execute_script("return document.getElementById('approval-diff').textContent")
            shown = driver.find_element("id", "approval-diff").text
            assert "(critic repairs)" in shown and any(line.startswith("+") for line in shown.splitlines()[2:])
            driver.find_element("id", "approve").click()
            wait_for(driver, "return !document.getElementById('approval').hidden && "
                             f"document.getElementById('approval-diff').textContent !== {json.dumps(repair_diff)}",
                     what="the model revision's approval")
            diff = driver.find_element("id", "approval-diff").text
            assert any(line.startswith("+") for line in diff.splitlines()) and "(critic repairs)" not in diff
            driver.find_element("id", "approve").click()
            expected = critique(simulate(CAREFUL, Scene.builtin("sorting"))).score
            wait_for(driver, f"return Math.abs(Number(document.getElementById('score').dataset.score) - {expected})"
                             " < 1e-9", what="the revision's score")
            assert driver.execute_script("return document.getElementById('editor').value") == studio.program
            assert len(driver.find_elements("css selector", "#history li")) == 3  # run, repair, the model's fix
            # going back to the first attempt restores it
            driver.find_element("css selector", "#history li[data-index='1']").click()
            wait_for(driver, "return document.getElementById('editor').value.includes('')"
                             " && document.querySelector('#history li.current[data-index=\"1\"]')", what="history")
            assert driver.execute_script("return document.getElementById('editor').value") == NAIVE


def test_chat_reply_streams_in_as_it_arrives(driver):
    reply = "I will pick the apple first and then place it gently in the white box. " * 3
    with LLMServer() as llm:
        llm.token_interval_s = 0.05
        llm.reply(reply)
        model = OpenAICompatible(base_url=llm.url, model="test-chat")
        with Studio("sorting", NAIVE, model=model) as studio:
            open_studio(driver, studio)
            driver.find_element("id", "chat-input").send_keys("put the apple in the box")
            driver.find_element("id", "chat-send").click()
            partial = wait_for(
                driver, "const m = document.querySelector('#chat-log .assistant[data-streaming=\"1\"]');"
                        "return m && m.textContent.length > 0 && m.textContent", what="a partial reply")
            assert len(partial) < len(reply.strip())
            wait_for(driver, "return document.querySelector('#chat-log .assistant[data-done=\"1\"]')", what="done")
            final = driver.find_element("css selector", "#chat-log .assistant").text
            assert final.strip() == reply.strip()


def test_deploy_a_passing_program_to_the_loopback_controller_after_confirming(driver):
    from robocritics.testing.ursim import URSim
    from ur_support import stepped

    with URSim(**stepped(idle_after_s=0.05)) as sim:
        target = {"host": "127.0.0.1", "rtde_port": sim.rtde_port, "dashboard_port": sim.dashboard_port,
                  "secondary_port": sim.secondary_port}
        with Studio("sorting", CAREFUL, deploy=target) as studio:
            open_studio(driver, studio)
            press_run(driver)
            wait_for(driver, "return !document.getElementById('deploy').disabled", what="Deploy enabled")
            driver.find_element("id", "deploy").click()
            assert not driver.execute_script("return document.getElementById('deploy-dialog').hidden")
            driver.find_element("id", "deploy-confirm").click()
            wait_for(driver, "return document.body.dataset.deployed", timeout_s=180, what="the deploy result")
            assert driver.execute_script("return document.body.dataset.deployed") == "1", \
                driver.find_element("id", "terminal").text


def test_the_page_works_with_its_token_and_not_without(driver):
    with Studio("sorting", NAIVE, token="t0ken-for-test") as studio:
        driver.get(studio.url.split("?")[0])
        assert "needs its token" in driver.find_element("tag name", "body").text
        open_studio(driver, studio)
        press_run(driver)  # every API call carried the token header
        assert len(driver.find_elements("css selector", "#history li")) == 1
