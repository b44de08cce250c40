"""The studio's model flows in headless Chromium against the real `robocritics studio` process and a loopback
OpenAI-compatible server (tests/llm_server.py): Fix = the critics' repairs first, then the model for what is left;
chat streaming; the chat's order; an identical reply said, not a silent revision; "receiving…" only while the
model sends (issue 21, #6, #9, #10)."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from browser import chromium, click, studio_process, wait_for
from llm_server import LLMServer
from robocritics import Scene, critique, simulate
from test_studio_browser import chat, history, open_page, run

ROOT = Path(__file__).resolve().parent.parent
NAIVE_PATH = ROOT / "examples" / "programs" / "sorting_naive.py"
NAIVE = NAIVE_PATH.read_text()
CAREFUL = (ROOT / "examples" / "programs" / "sorting_careful.py").read_text()


def fenced(program: str) -> str:
    return "Here is the revised program.\n```python\n" + program + "```\n"


@pytest.fixture(scope="module")
def llm():
    with LLMServer() as server:
        yield server


@pytest.fixture(scope="module")
def studio(llm):
    with studio_process("--program", str(NAIVE_PATH), "--base-url", llm.url, "--model", "test-chat",
                        "--timeout", "60") as (url, _):
        yield url


@pytest.fixture(scope="module")
def driver():
    with chromium() as d:
        yield d


def approve_next(driver, previous_diff: str = "") -> str:
    wait_for(driver, "return !document.getElementById('approval').hidden && "
                     "document.getElementById('approval-diff').textContent !== arguments[0]", previous_diff,
             what="an approval")
    diff = driver.find_element("id", "approval-diff").get_attribute("textContent")
    click(driver, "approve")
    return diff


def test_fix_is_the_critics_repairs_then_the_model_with_history_numbers_in_order(driver, studio, llm):
    """#6 (with an LLM: repairs first, then the model), #9 (diff headers = history numbers, the request before its
    reply), #1 (Fix all enabled after Run)."""
    open_page(driver, studio)
    index = run(driver, NAIVE)
    wait_for(driver, "return !document.getElementById('fix-all').disabled", what="Fix all enabled")
    llm.reply(fenced(CAREFUL))
    click(driver, "fix-all")
    wait_for(driver, "return !document.getElementById('approval').hidden", what="the repairs' approval")
    status = driver.find_element("id", "chat-status").text
    assert "model" not in status and "approval" in status, status  # not "waiting for the model" during repairs
    repair = approve_next(driver)
    assert repair.startswith(f"--- #{index}+++ #{index + 1} (critic repairs)")
    model = approve_next(driver, repair)
    assert model.startswith(f"--- #{index + 1}+++ #{index + 2}"), model[:80]
    expected = critique(simulate(CAREFUL, Scene.builtin("sorting"))).score
    wait_for(driver, f"return document.querySelector('#history li.current[data-index=\"{index + 2}\"]')",
             what="the model's revision")
    assert float(driver.execute_script("return document.getElementById('score').dataset.score")) == \
        pytest.approx(expected)
    assert [h.split(" score")[0] for h in history(driver)[index - 1:]] == \
        [f"#{index} run", f"#{index + 1} repair", f"#{index + 2} fix"]
    log = chat(driver)
    at = max(i for i, (role, text) in enumerate(log) if role == "user" and text == "Fix all")
    roles = [role for role, _ in log[at:]]
    assert roles[:3] == ["user", "note", "assistant"], log[at:]  # the request, the repairs, then the reply
    assert "Here is the revised program" in log[at + 2][1]


def test_an_identical_reply_is_said_not_a_silent_revision(driver, studio, llm):
    """#9: a reply identical to the current program makes no new revision; the chat says so."""
    if not driver.current_url.startswith(studio):
        open_page(driver, studio)
    current = driver.execute_script("return document.getElementById('editor').value")
    count = len(history(driver))
    turns = int(driver.execute_script("return Number(document.body.dataset.turns || 0)"))
    llm.reply(fenced(current))
    driver.find_element("id", "chat-input").send_keys("make it nicer")
    click(driver, "chat-send")
    wait_for(driver, f"return Number(document.body.dataset.turns || 0) > {turns}", what="the turn to end")
    wait_for(driver, "return [...document.querySelectorAll('#chat-log .note')].some(n => "
                     "n.textContent.includes('unchanged: no new revision'))", what="the unchanged note")
    assert len(history(driver)) == count
    log = chat(driver)
    at = max(i for i, (role, text) in enumerate(log) if role == "user" and text == "make it nicer")
    assert [r for r, _ in log[at:at + 3]] == ["user", "assistant", "note"]


def test_chat_reply_streams_in_as_it_arrives(driver, studio, llm):
    reply = "I will pick the apple first and then place it gently in the white box. " * 8
    if not driver.current_url.startswith(studio):
        open_page(driver, studio)
    llm.token_interval_s = 0.05
    try:
        llm.reply(reply)
        driver.find_element("id", "chat-input").send_keys("put the apple in the box")
        click(driver, "chat-send")
        partial = wait_for(
            driver, "const m = document.querySelector('#chat-log .live[data-streaming=\"1\"]');"
                    "return m && m.textContent.length > 0 && m.textContent", what="a partial reply")
        assert len(partial) < len(reply.strip())
        wait_for(driver, "return document.getElementById('chat-status').textContent.includes('receiving')",
                 what="'receiving' while the reply streams")
        first = driver.current_window_handle
        driver.switch_to.new_window("tab")  # another page sees the reply come in, from the shared state
        open_page(driver, studio)
        elsewhere = wait_for(driver, "const m = document.querySelector('#chat-log .remote');"
                                     "return m && m.textContent.length > 0 && m.textContent", what="the reply in a 2nd tab")
        assert reply.strip().startswith(elsewhere.strip()[:60])
        driver.close()
        driver.switch_to.window(first)
        wait_for(driver, "return [...document.querySelectorAll('#chat-log .assistant')].some(m => "
                         "m.textContent.trim() === arguments[0])", reply.strip(), what="the whole reply")
    finally:
        llm.token_interval_s = 0.0


def test_receiving_is_not_shown_while_the_endpoint_refuses_connections(driver):
    """#10: "receiving…" only while the model sends; a refused connection is an error in the terminal."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # closed when the block ends: nothing listens there
    with studio_process("--base-url", f"http://127.0.0.1:{port}/v1", "--model", "test-chat",
                        "--timeout", "5") as (url, _):
        open_page(driver, url)
        driver.execute_script(
            "window.statuses = []; new MutationObserver(() => window.statuses.push("
            "document.getElementById('chat-status').textContent)).observe(document.getElementById('chat-status'),"
            "{childList: true, characterData: true, subtree: true});")
        driver.find_element("id", "chat-input").send_keys("pick up the apple")
        click(driver, "chat-send")
        wait_for(driver, "return Number(document.body.dataset.turns || 0) > 0", timeout_s=120, what="the turn to end")
        statuses = driver.execute_script("return window.statuses")
        assert not any("receiving" in s for s in statuses), statuses
        assert any("waiting for the model" in s for s in statuses), statuses
        terminal = driver.find_element("id", "terminal").get_attribute("textContent")
        assert "LLM" in terminal or "connect" in terminal.lower(), terminal
