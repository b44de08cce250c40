"""The studio's flows as a person goes through them, in headless Chromium, against the real `robocritics studio`
process (no LLM: Fix applies the critics' own repairs) deploying to a real `robocritics ursim` process.

One studio and one controller serve the whole module (the tests run in file order and each starts from a Run of
its own program). Issue 21's numbered findings are named in each test's docstring; LLM flows are in
test_studio_llm_browser.py."""

from __future__ import annotations

import json
import time
import urllib.request
from pathlib import Path

import pytest

from browser import (canvas_stats, chromium, click, save_screenshot, set_editor, severe_console_errors, studio_process,
                     ursim_process, wait_for)
from robocritics import Scene, critique, simulate

ROOT = Path(__file__).resolve().parent.parent
NAIVE_PATH = ROOT / "examples" / "programs" / "sorting_naive.py"
NAIVE = NAIVE_PATH.read_text()
CAREFUL = (ROOT / "examples" / "programs" / "sorting_careful.py").read_text()  # no Error, 59 s of motion
SHORT = "move_above(green_apple)\nhome()\n"  # no Error (a Warning), 1.2 s of motion


@pytest.fixture(scope="module")
def ursim():
    with ursim_process() as controller:
        yield controller


@pytest.fixture(scope="module")
def studio(ursim):
    ports, _ = ursim
    with studio_process("--program", str(NAIVE_PATH), "--deploy-host", "127.0.0.1",
                        "--deploy-rtde-port", str(ports["rtde"]), "--deploy-dashboard-port", str(ports["dashboard"]),
                        "--deploy-secondary-port", str(ports["secondary"])) as (url, _):
        yield url


@pytest.fixture(scope="module")
def driver():
    with chromium() as d:
        yield d


def open_page(driver, url):
    driver.get(url)
    wait_for(driver, "return document.body.dataset.ready === '1'", what="the studio page to start")


def server_state(url: str) -> dict:
    request = urllib.request.Request(url.split("?")[0] + "api/state", headers={"X-Studio": "1"})
    with urllib.request.urlopen(request, timeout=60) as response:
        return json.loads(response.read())


def history(driver) -> list[str]:
    return driver.execute_script("return [...document.querySelectorAll('#history li')].map(li => li.textContent)")


def run(driver, program: str) -> int:
    """Put ``program`` in the editor, press Run, wait for its revision; return its number."""
    wait_for(driver, "return !document.getElementById('run').disabled", what="Run enabled")
    set_editor(driver, program)
    driver.execute_script("delete document.body.dataset.lastRun")
    click(driver, "run")
    index = int(wait_for(driver, "return !document.body.dataset.running && document.body.dataset.lastRun",
                         what="the Run's revision"))
    assert driver.execute_script("return document.querySelector('#history li.current').dataset.index") == str(index)
    return index


def flags(driver) -> dict[str, str]:
    return driver.execute_script(
        "const o = {}; for (const r of document.querySelectorAll('#critics .critic')) o[r.dataset.critic] = "
        "r.dataset.flag; return o;")


def chat(driver) -> list[tuple[str, str]]:
    return [tuple(x) for x in driver.execute_script(
        "return [...document.querySelectorAll('#chat-log .msg')].map(m => [m.className.split(' ')[1], m.textContent])")]


def test_first_view_is_the_program_run_at_start_and_a_reload_shows_the_latest(driver, studio):
    """#7 (--program run at start, reload shows the latest revision), #10 (history numbered once)."""
    expected = critique(simulate(NAIVE, Scene.builtin("sorting")))
    open_page(driver, studio)
    wait_for(driver, "return document.querySelectorAll('#critics .critic[data-flag=\"error\"]').length >= 1",
             what="the start Run's flags, without pressing Run")
    shown = flags(driver)
    for v in expected.verdicts:
        assert shown[v.critic] == v.flag.value.lower(), v.critic
    assert history(driver)[0].startswith("#1 run")
    style = driver.execute_script("return getComputedStyle(document.getElementById('history')).listStyleType")
    assert style == "none"  # "#1 run", not "1. #1 run"
    assert "token" not in driver.current_url
    driver.refresh()
    wait_for(driver, "return document.body.dataset.ready === '1' && "
                     "document.querySelector('#history li.current[data-index=\"1\"]') && "
                     "document.getElementById('replay').dataset.ready === '1'", what="the latest revision after reload")
    assert flags(driver) == shown
    stats = canvas_stats(driver, driver.find_element("css selector", "#replay .rc-canvas"))
    assert max(stats["variance"]) > 50, stats
    # #10: the terminal shows the first Error, not the last Warning
    top = driver.execute_script("const t = document.getElementById('terminal'); const e = t.querySelector('.err');"
                                "return e && (e.offsetTop - t.offsetTop >= t.scrollTop - 8) && "
                                "(e.offsetTop - t.offsetTop < t.scrollTop + t.clientHeight)")
    assert top


@pytest.mark.parametrize("program, line, words", [
    ("home()\nimport os\n", 2, "import of 'os'"),
    ("home()\nmove_to(2.0, 0, 0.3)\n", 2, "reaches 0.601 m."),
    ("for i in range(3000):\n    move_to(0.3, 0.1, 0.3)\n    move_to(0.3, -0.1, 0.3)\n", 2, "skill calls"),
    ("home(\n", 1, "syntax error"),
])
def test_a_program_that_does_not_run_has_a_runtime_row_with_its_line_and_no_stale_replay(driver, studio, program,
                                                                                          line, words):
    """#5: runtime row (syntax, forbidden name, unreachable target, budget), line marked, old replay cleared;
    #10: the message and its hint do not run on ("…0.601 m. Hint: change the motion…")."""
    if not driver.current_url.startswith(studio.split("?")[0]):
        open_page(driver, studio)
    run(driver, NAIVE)  # a replay with marks on screen
    wait_for(driver, "return document.querySelectorAll('.rc-timeline .rc-mark').length > 0", what="timeline marks")
    run(driver, program)
    shown = flags(driver)
    assert shown["runtime"] == "error"
    assert all(flag == "none" for name, flag in shown.items() if name != "runtime")
    assert "did not run" in driver.find_element("css selector", "#critics .critic[data-critic='collision'] .msg").text
    marked = driver.execute_script(
        "return [...document.querySelectorAll('#gutter .ln.flagged')].map(e => Number(e.dataset.line))")
    assert marked == [line]
    assert driver.execute_script("return document.querySelectorAll('.rc-timeline .rc-mark').length") == 0
    assert "did not run" in driver.find_element("id", "replay-note").text
    assert driver.execute_script("return document.getElementById('replay').dataset.ready") is None
    terminal = driver.find_element("id", "terminal").get_attribute("textContent")
    assert words in terminal and "Hint: " in terminal
    assert driver.find_element("id", "deploy").get_attribute("disabled") is not None


def fix_all_until_approval(driver) -> dict:
    click(driver, "fix-all")
    wait_for(driver, "return !document.getElementById('approval').hidden", what="the repair's approval")
    return {"id": driver.execute_script("return document.getElementById('approval').dataset.id"),
            "title": driver.find_element("id", "approval-title").text,
            "diff": driver.find_element("id", "approval-diff").text}


def test_fix_after_run_applies_the_critics_repairs_with_approval_without_an_llm(driver, studio):
    """#1 (Fix enabled after Run for every flagged critic), #6 (no LLM: the critics' repairs, approval dialog, no
    "waiting for the model"), #9 (diff headers use the history's numbers; the request comes before its reply)."""
    index = run(driver, NAIVE)
    wait_for(driver, "return !document.body.dataset.job", what="no job running")
    rows = driver.execute_script(
        "return [...document.querySelectorAll('#critics .critic')].map(r => [r.dataset.flag, "
        "r.querySelector('.fix').disabled, r.querySelector('.fix').title])")
    flagged = [r for r in rows if r[0] in ("error", "warning")]
    assert flagged and all(not disabled for _, disabled, _ in flagged), rows
    assert all("repairs" in title for _, _, title in flagged)
    assert all(disabled for flag, disabled, _ in rows if flag == "ok")
    before = float(driver.execute_script("return document.getElementById('score').dataset.score"))
    asked = fix_all_until_approval(driver)
    assert asked["title"] == f"#{index + 1} (critic repairs) from #{index}"
    head = asked["diff"].splitlines()[:2]
    assert head == [f"--- #{index}", f"+++ #{index + 1} (critic repairs)"], head
    status = driver.find_element("id", "chat-status").text
    assert "model" not in status and "approval" in status
    click(driver, "approve")
    wait_for(driver, f"return document.querySelector('#history li.current[data-index=\"{index + 1}\"]')",
             what="the repaired revision")
    assert history(driver)[index].startswith(f"#{index + 1} repair")
    after = float(driver.execute_script("return document.getElementById('score').dataset.score"))
    assert after > before
    log = chat(driver)
    fix_at = max(i for i, (role, text) in enumerate(log) if role == "user" and text == "Fix all")
    assert log[fix_at + 1][0] == "note" and f"#{index + 1}" in log[fix_at + 1][1]


def test_reload_mid_approval_shows_it_again_and_reject_leaves_a_trace(driver, studio):
    """#2 (a pending approval survives a reload), #9 (Reject leaves a trace in the chat)."""
    run(driver, NAIVE)
    asked = fix_all_until_approval(driver)
    count = len(history(driver))
    driver.refresh()
    wait_for(driver, "return document.body.dataset.ready === '1' && !document.getElementById('approval').hidden",
             what="the approval again after the reload")
    assert driver.execute_script("return document.getElementById('approval').dataset.id") == asked["id"]
    assert driver.find_element("id", "approval-diff").text == asked["diff"]
    assert "counts as rejected in" in driver.find_element("id", "approval-left").text
    assert server_state(studio)["job"]["approval"]["id"] == int(asked["id"])
    save_screenshot(driver, "studio-approval.png")
    click(driver, "reject")
    wait_for(driver, "return [...document.querySelectorAll('#chat-log .note')].some(n => "
                     "n.textContent.includes('rejected by you'))", what="the rejection in the chat")
    wait_for(driver, "return !document.body.dataset.job", what="the turn to end")
    assert len(history(driver)) == count


def test_a_run_while_an_approval_waits_cancels_that_turn(driver, studio):
    """#2: waiting for an approval never holds what Run needs (after a reload, too)."""
    run(driver, NAIVE)
    fix_all_until_approval(driver)
    driver.refresh()
    wait_for(driver, "return document.body.dataset.ready === '1' && !document.getElementById('approval').hidden",
             what="the approval after the reload")
    assert not driver.find_element("id", "run").get_attribute("disabled")
    started = time.monotonic()
    index = run(driver, SHORT)
    print(f"studio: Run while an approval waited took {time.monotonic() - started:.2f} s")
    assert driver.execute_script("return document.getElementById('editor').value") == SHORT
    wait_for(driver, "return [...document.querySelectorAll('#chat-log .note')].some(n => "
                     "n.textContent.includes('cancelled by a Run'))", what="the cancelled turn in the chat")
    wait_for(driver, "return document.getElementById('approval').hidden", what="the dialog gone")
    assert server_state(studio)["revisions"][-1]["index"] == index


def test_deploy_is_off_while_the_editor_differs_or_any_critic_ticked_or_not_reports_an_error(driver, studio):
    """#4: Deploy disabled (saying why) while any critic reports an Error, ticked or not, and while the editor
    differs from the last Run."""
    run(driver, NAIVE)
    errors = sorted(n for n, f in flags(driver).items() if f == "error")
    wait_for(driver, "return !document.body.dataset.job", what="no job")
    assert driver.find_element("id", "deploy").get_attribute("disabled") is not None
    why = driver.find_element("id", "status-text").text
    assert all(name in why for name in errors), why
    for name in errors:  # untick the critics that report Errors: their Errors still keep Deploy off
        driver.execute_script(f"document.querySelector('#critics .critic[data-critic=\"{name}\"] .toggle').click()")
    run(driver, NAIVE)
    assert driver.find_element("id", "deploy").get_attribute("disabled") is not None
    assert all(name in driver.find_element("id", "deploy").get_attribute("title") for name in errors)
    for name in errors:
        driver.execute_script(f"document.querySelector('#critics .critic[data-critic=\"{name}\"] .toggle').click()")
    run(driver, SHORT)
    wait_for(driver, "return !document.getElementById('deploy').disabled", what="Deploy enabled")
    set_editor(driver, SHORT + "home()\n")
    assert driver.find_element("id", "deploy").get_attribute("disabled") is not None
    assert "editor differs" in driver.find_element("id", "deploy").get_attribute("title")
    set_editor(driver, SHORT)
    assert driver.find_element("id", "deploy").get_attribute("disabled") is None


def deploy_progress(driver) -> dict:
    return driver.execute_script("return {text: document.getElementById('status-text').textContent, "
                                 "stop: !document.getElementById('stop').hidden, job: document.body.dataset.job}")


def test_deploy_sends_the_trajectory_shown_streams_progress_to_every_page_and_stop_stops_the_arm(driver, studio, ursim):
    """#3: progress on every page (also after a reload), one deploy across tabs (a second refused visibly), Stop
    through the fault stop path within 1 s; #4: it deploys exactly the trajectory shown; #10 wording."""
    _, controller_log = ursim
    open_page(driver, studio)
    index = run(driver, SHORT)
    shown_hash = server_state(studio)["revisions"] and \
        json.loads(urllib.request.urlopen(urllib.request.Request(
            studio.split("?")[0] + f"api/revision/{index}", headers={"X-Studio": "1"}), timeout=60).read())["trajectory_hash"]
    wait_for(driver, "return !document.getElementById('deploy').disabled", what="Deploy enabled")
    click(driver, "deploy")
    click(driver, "deploy-confirm")
    wait_for(driver, "return document.body.dataset.deployed", timeout_s=120, what="the deploy result")
    terminal = driver.find_element("id", "terminal").get_attribute("textContent")
    assert driver.execute_script("return document.body.dataset.deployed") == "1", terminal
    assert "deployed: deployed" not in terminal
    last = server_state(studio)["last_deploy"]
    assert last["ok"] and last["deployed_hash"] == last["trajectory_hash"] == shown_hash

    # a 59-s program: deploy it, watch it from a second tab and after a reload, stop it from the second tab
    index = run(driver, CAREFUL)
    wait_for(driver, "return !document.getElementById('deploy').disabled", what="Deploy enabled")
    driver.execute_script("delete document.body.dataset.deployed")
    click(driver, "deploy")
    click(driver, "deploy-confirm")
    first = driver.current_window_handle
    wait_for(driver, "return document.getElementById('status-text').textContent.includes('setpoints')",
             timeout_s=120, what="deploy progress in the first tab")
    driver.switch_to.new_window("tab")
    open_page(driver, studio)
    seen = wait_for(driver, "const t = document.getElementById('status-text').textContent;"
                            "return t.includes('setpoints') && !document.getElementById('stop').hidden && t",
                    what="deploy progress in the second tab")
    assert f"revision {index}" in seen and "tracking" in seen and " s · " in seen
    assert driver.find_element("id", "deploy").get_attribute("hidden") is not None  # Stop in its place
    # a second deploy (from this tab's dialog) is refused, and the page says so
    driver.execute_script("document.getElementById('deploy-confirm').click()")
    refused = wait_for(driver, "return document.body.dataset.refused", what="the second deploy refused")
    assert "deploy of revision" in refused and "running" in refused
    assert "deploy refused" in driver.find_element("id", "terminal").get_attribute("textContent")
    # a Run meanwhile does not wait behind the deploy: it is off, and the server refuses it at once, saying why
    assert driver.find_element("id", "run").get_attribute("disabled") is not None
    assert "deploy is running" in driver.find_element("id", "run").get_attribute("title")
    answer = driver.execute_async_script(
        "const done = arguments[0]; fetch('/api/run', {method: 'POST', headers: {'Content-Type': 'application/json',"
        "'X-Studio': '1'}, body: JSON.stringify({program: 'home()\\n'})}).then(r => r.json().then(j => "
        "done([r.status, j.error])));")
    assert answer[0] == 409 and "deploy of revision" in answer[1], answer
    # a reload of the first tab mid-deploy shows the moving arm's progress again
    driver.switch_to.window(first)
    driver.refresh()
    wait_for(driver, "return document.body.dataset.ready === '1' && "
                     "document.getElementById('status-text').textContent.includes('setpoints')",
             what="deploy progress after a reload")
    sent = [int(driver.find_element("id", "status-text").text.split(": ")[1].split(" /")[0])]
    wait_for(driver, f"return Number(document.getElementById('status-text').textContent.split(': ')[1]"
                     f".split(' /')[0]) > {sent[0]}", what="progress advancing")
    save_screenshot(driver, "studio-deploy.png")
    driver.switch_to.window(driver.window_handles[-1])
    click(driver, "stop")
    for handle in (driver.window_handles[-1], first):
        driver.switch_to.window(handle)
        wait_for(driver, "return document.getElementById('terminal').textContent.includes('stopped by Stop')",
                 what="the stop on every page")
        assert driver.execute_script("return document.body.dataset.deployed") == "0"
    last = server_state(studio)["last_deploy"]
    assert last["cause"] == "stop_requested" and last["stopped"] is True
    assert last["stop_latency_s"] < 1.0, last
    print(f"studio: the arm stopped {last['stop_latency_s']:.3f} s after Stop")
    from ur_support import ControllerProcess

    ports, _ = ursim
    state = ControllerProcess(None, ports["rtde"], ports["dashboard"], ports["secondary"]).state()
    assert max(abs(v) for v in state["actual_qd"]) < 1e-3, state
    started = controller_log.read_text().count("program_started")
    assert started == 2, controller_log.read_text()[-3000:]  # SHORT and CAREFUL, never a second CAREFUL
    driver.switch_to.window(driver.window_handles[-1])
    driver.close()
    driver.switch_to.window(first)
    assert not [e for e in severe_console_errors(driver) if "favicon" not in e and "409" not in e]


@pytest.mark.parametrize("width, height", [(1024, 700), (1280, 800), (1920, 1080)])
def test_controls_and_history_are_reachable_from_1024x700_to_1920x1080(driver, studio, width, height):
    """#8: the replay's play, scrub and speed controls are on screen and clickable; the history is visible beside
    the critics without scrolling them away."""
    driver.set_window_size(width, height)
    open_page(driver, studio)
    wait_for(driver, "return document.getElementById('replay').dataset.ready === '1' || "
                     "document.querySelector('#history li.current')", what="a revision shown")
    run(driver, NAIVE)
    wait_for(driver, "return document.getElementById('replay').dataset.ready === '1'", what="the replay")
    for selector in (".rc-play", ".rc-scrub", ".rc-controls select", ".rc-controls input[type=checkbox]"):
        hit = driver.execute_script(
            "const e = document.querySelector(arguments[0]); if (!e) return 'missing'; const r = e.getBoundingClientRect();"
            "const x = r.left + r.width / 2, y = r.top + r.height / 2;"
            "if (y > innerHeight || x > innerWidth || r.height === 0) return 'off screen ' + y;"
            "const at = document.elementFromPoint(x, y); return at === e || e.contains(at) || at.contains(e) ? 'ok' : "
            "'covered by ' + at.className;", selector)
        assert hit in ("ok", "missing"), (selector, hit)
    assert driver.execute_script("return document.querySelector('.rc-play') !== null")
    driver.execute_script("document.querySelector('.rc-play').click()")
    wait_for(driver, "return document.getElementById('replay').dataset.playing === '1'", what="playing")
    driver.execute_script("document.querySelector('.rc-play').click()")
    visible = driver.execute_script(
        "const panel = document.querySelector('.st-critics-panel').getBoundingClientRect();"
        "const last = [...document.querySelectorAll('#history li')].pop().getBoundingClientRect();"
        "const first = document.querySelector('#critics .critic').getBoundingClientRect();"
        "const h = document.getElementById('history').getBoundingClientRect();"
        "return {history: h.top >= panel.top && h.bottom <= panel.bottom + 1 && h.height > 20 && last.bottom <= h.bottom + 1"
        " && last.top >= h.top - 1, critics: first.top >= panel.top && first.bottom <= innerHeight,"
        "numbers: [panel.top, panel.bottom, h.top, h.bottom, h.height, last.top, last.bottom, innerHeight]}")
    name = "studio.png" if (width, height) == (1920, 1080) else f"studio-{width}x{height}.png"
    save_screenshot(driver, name)
    numbers = visible.pop("numbers")
    assert visible == {"history": True, "critics": True}, numbers
    buttons = driver.execute_script(
        "return ['run', 'fix-all', 'deploy'].map(id => { const r = document.getElementById(id).getBoundingClientRect();"
        "return r.right <= innerWidth && r.bottom <= innerHeight && r.width > 0; })")
    assert all(buttons), buttons
    driver.set_window_size(1400, 900)


def test_wildcard_host_prints_reachable_addresses_and_the_token_moves_to_a_cookie(driver):
    """#10: `--host 0.0.0.0` prints this machine's addresses; after the first visit the token is an HttpOnly
    SameSite cookie, not in the address bar."""
    from browser import command_process
    from robocritics.viz.studio.addresses import local_addresses

    with command_process(["studio", "--host", "0.0.0.0", "--token", "t0ken-for-test", "--port", "0",
                          "--no-browser"], "robocritics studio: http") as (proc, lines, _):
        port = lines[0].split()[2].rsplit(":", 1)[1].split("/")[0]
        expected = local_addresses()
        for _ in expected[1:]:
            lines.append(proc.stdout.readline())
        printed = [line.split()[-1] if "also" in line else line.split()[2] for line in lines]
        assert printed == [f"http://{a}:{port}/?token=t0ken-for-test" for a in expected]
        assert not any("0.0.0.0" in line for line in lines)
        local = f"http://127.0.0.1:{port}/"
        driver.get(local)
        assert "needs its token" in driver.find_element("tag name", "body").text
        open_page(driver, local + "?token=t0ken-for-test")
        assert driver.current_url == local
        assert "t0ken" not in driver.execute_script("return document.cookie")
        cookie = driver.get_cookie(f"robocritics_studio_{port}")
        assert cookie["httpOnly"] and cookie["sameSite"] == "Strict" and cookie["value"] == "t0ken-for-test"
        driver.refresh()  # no token in the address any more: the cookie carries it
        wait_for(driver, "return document.body.dataset.ready === '1'", what="the page after a reload")
        run(driver, SHORT)
        assert len(history(driver)) == 1
