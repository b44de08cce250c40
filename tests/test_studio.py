"""The studio's HTTP surface: security (token, cross-origin, Host, content type, body size), Run, the CLI's refusal
to bind off loopback without a token. The browser-level tests are in test_studio_browser.py."""

from __future__ import annotations

import http.client
import json
from pathlib import Path

import pytest

from robocritics import critique, simulate, Scene
from robocritics.cli import main
from robocritics.viz.studio import Studio, StudioError, is_loopback
from robocritics.viz.studio.server import MAX_BODY_BYTES

ROOT = Path(__file__).resolve().parent.parent
NAIVE = (ROOT / "examples" / "programs" / "sorting_naive.py").read_text()


def request(studio, method, path, body=None, headers=None):
    conn = http.client.HTTPConnection("127.0.0.1", studio.port, timeout=120)
    data = None if body is None else (body if isinstance(body, bytes) else json.dumps(body).encode())
    conn.request(method, path, body=data, headers=headers or {})
    response = conn.getresponse()
    payload = response.read()
    conn.close()
    return response.status, payload


API = {"Content-Type": "application/json", "X-Studio": "1"}


@pytest.fixture(scope="module")
def studio():
    with Studio("sorting", NAIVE) as s:
        yield s


def test_loopback_names():
    assert is_loopback("127.0.0.1") and is_loopback("127.5.6.7") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.10") and not is_loopback("example.org")


def test_non_loopback_bind_without_token_is_refused(capsys):
    assert main(["studio", "--host", "0.0.0.0", "--no-browser"]) == 2
    assert "--token" in capsys.readouterr().err
    with pytest.raises(StudioError, match="token"):
        Studio("sorting", host="0.0.0.0")


def test_page_is_one_response_with_no_external_urls(studio):
    status, page = request(studio, "GET", "/")
    assert status == 200
    text = page.decode()
    assert "RoboReplay" in text and "THREE" in text and 'id="critics"' in text
    assert "<script src" not in text and "<link" not in text


def test_run_gives_the_in_process_report(studio):
    status, body = request(studio, "POST", "/api/run", {"program": NAIVE}, API)
    assert status == 200, body
    revision = json.loads(body)
    expected = critique(simulate(NAIVE, Scene.builtin("sorting")))
    assert revision["score"] == pytest.approx(expected.score)
    assert {v["critic"]: v["flag"] for v in revision["verdicts"]} == {
        v.critic: v.flag.value.lower() for v in expected.verdicts
    }
    assert revision["has_errors"] and revision["replay"] is not None
    status, body = request(studio, "GET", f"/api/revision/{revision['index']}", headers=API)
    assert status == 200 and json.loads(body)["program"] == NAIVE


def test_a_program_that_does_not_run_is_reported_with_its_line(studio):
    status, body = request(studio, "POST", "/api/run", {"program": "home()\nimport os\n"}, API)
    revision = json.loads(body)
    assert status == 200 and "line 2" in revision["error"]
    # the runtime critic's Error verdict, scored like any failing report and marking the line in the editor
    assert revision["score"] == 0 and revision["has_errors"]
    (verdict,) = revision["verdicts"]
    assert verdict["critic"] == "runtime" and verdict["flag"] == "error" and verdict["lines"] == [2]


def test_goals_are_checked_on_every_run(tmp_path):
    wrong = (  # the task says white_box
        "open_gripper()\nmove_above(green_apple, 0.1)\nmove_linear(green_apple.x, green_apple.y, green_apple.z)\n"
        "close_gripper()\nmove_up(0.15)\nmove_to(brown_box.x, brown_box.y, brown_box.top + 0.1)\n"
        "open_gripper()\nhome()\n"
    )
    right = wrong.replace("brown_box", "white_box")
    with Studio("sorting", wrong, goals=["green_apple in white_box"]) as studio:
        status, body = request(studio, "GET", "/api/state", headers=API)
        assert status == 200 and json.loads(body)["goals"] == ["green_apple in white_box"]
        verdicts = {}
        for program in (wrong, right):
            status, body = request(studio, "POST", "/api/run", {"program": program}, API)
            assert status == 200, body
            verdicts[program] = {v["critic"]: v for v in json.loads(body)["verdicts"]}
    assert verdicts[wrong]["task_outcome"]["flag"] == "error"
    assert "green_apple" in verdicts[wrong]["task_outcome"]["message"] and "brown_box" in verdicts[wrong]["task_outcome"]["message"]
    assert verdicts[right]["task_outcome"]["flag"] == "ok"


def test_a_goal_naming_no_object_of_the_scene_is_refused_before_serving(capsys):
    assert main(["studio", "--goal", "purple_pear in white_box", "--no-browser", "--port", "0"]) == 2
    assert "purple_pear" in capsys.readouterr().err


def test_cross_origin_post_is_refused(studio):
    status, _ = request(studio, "POST", "/api/run", {"program": NAIVE}, {**API, "Origin": "http://evil.example"})
    assert status == 403


def test_api_post_without_json_type_or_custom_header_is_refused(studio):
    assert request(studio, "POST", "/api/run", {"program": NAIVE}, {"Content-Type": "text/plain"})[0] == 403
    assert request(studio, "POST", "/api/run", {"program": NAIVE}, {"Content-Type": "application/json"})[0] == 403


def test_foreign_host_header_is_refused(studio):
    assert request(studio, "GET", "/", headers={"Host": f"attacker.example:{studio.port}"})[0] == 403


def test_oversized_body_is_refused(studio):
    big = b'{"program": "' + b"x" * (MAX_BODY_BYTES + 10) + b'"}'
    assert request(studio, "POST", "/api/run", big, API)[0] == 413


def test_token_is_required_on_page_and_api():
    with Studio("sorting", NAIVE, token="s3cret") as s:
        assert s.url.endswith("?token=s3cret")
        assert request(s, "GET", "/")[0] == 401
        assert request(s, "GET", "/?token=wrong")[0] == 401
        assert request(s, "GET", "/api/state", headers=API)[0] == 401
        assert request(s, "GET", "/?token=s3cret")[0] == 200
        status, body = request(s, "GET", "/api/state", headers={**API, "X-Studio-Token": "s3cret"})
        assert status == 200 and json.loads(body)["program"] == NAIVE


def test_chat_and_deploy_are_disabled_with_reasons_when_not_configured(studio):
    state = json.loads(request(studio, "GET", "/api/state", headers=API)[1])
    assert "LLM endpoint" in state["chat"] and "controller" in state["deploy"]
    assert len(state["critics"]) >= 5
    assert request(studio, "POST", "/api/chat", {"text": "hello"}, API)[0] == 409


def test_other_requests_are_answered_while_a_run_is_going(studio):
    import threading

    done = threading.Event()
    answered_during_run = []

    def run():
        request(studio, "POST", "/api/run", {"program": NAIVE}, API)
        done.set()

    thread = threading.Thread(target=run)
    thread.start()
    while not done.is_set():
        status, _ = request(studio, "GET", "/api/state", headers=API)
        answered_during_run.append((status, done.is_set()))
    thread.join()
    assert any(status == 200 and not finished for status, finished in answered_during_run)


def test_the_command_serves_until_ctrl_c_and_exits_0(tmp_path):
    import os
    import signal
    import subprocess
    import sys
    import urllib.request

    proc = subprocess.Popen(
        [sys.executable, "-m", "robocritics", "studio", "--program", str(ROOT / "examples/programs/sorting_naive.py"),
         "--port", "0", "--no-browser"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env={**os.environ, "ROBOCRITICS_BASE_URL": ""},
        # a suite started from a background shell ignores SIGINT, and children inherit that: give Ctrl-C back
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        line = proc.stdout.readline()
        assert line.startswith("robocritics studio: http://127.0.0.1:"), line
        url = line.split()[2]
        assert b"RoboReplay" in urllib.request.urlopen(url, timeout=60).read()
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=60) == 0
    finally:
        if proc.poll() is None:
            proc.kill()


def test_a_connection_reset_mid_request_is_not_a_traceback(studio, capfd):
    import socket
    import struct
    import time

    for _ in range(3):  # a browser dropping keep-alive connections
        sock = socket.create_connection(("127.0.0.1", studio.port), timeout=5)
        sock.sendall(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n")  # no blank line: the server is still reading
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))  # close with RST
        sock.close()
    time.sleep(0.5)
    status, _ = request(studio, "GET", "/")  # still serving
    assert status == 200
    assert "Traceback" not in capfd.readouterr().err


# --- issue 22: bad requests are 400s with a JSON error, never a dropped connection or a traceback ----------------


@pytest.mark.parametrize("path, body", [
    ("/api/approve", {"id": "1", "ok": True}),
    ("/api/approve", {"id": 1.5, "ok": True}),
    ("/api/approve", {"id": True, "ok": True}),
    ("/api/approve", {"id": 1, "ok": "yes"}),
    ("/api/deploy", {"index": "1"}),
    ("/api/deploy", {"index": None}),
    ("/api/deploy", {"index": [1]}),
    ("/api/run", {"program": "home()\n", "critics": [1, 2]}),
    ("/api/run", {"program": "home()\n", "critics": ["no_such_critic"]}),
    ("/api/run", {"program": "home()\n", "critics": "collision"}),
    ("/api/fix", {"critics": [{"name": "collision"}]}),
    ("/api/fix", {"index": "2"}),
    ("/api/run", {"program": 12}),
])
def test_malformed_ids_and_critic_names_are_a_400_with_a_json_error(studio, capfd, path, body):
    status, payload = request(studio, "POST", path, body, API)
    assert status == 400, payload
    assert json.loads(payload)["error"]
    assert "Traceback" not in capfd.readouterr().err


def test_a_deeply_nested_body_is_a_400_not_a_dropped_connection(studio, capfd):
    deep = b'{"program": ' + b"[" * 200_000 + b"]" * 200_000 + b"}"
    status, payload = request(studio, "POST", "/api/run", deep, API)
    assert status == 400 and "nested" in json.loads(payload)["error"]
    assert "Traceback" not in capfd.readouterr().err
    assert request(studio, "GET", "/api/state", headers=API)[0] == 200


def test_only_the_last_revisions_keep_their_run_the_rest_are_compact(studio):
    """issue 22: a long session does not keep every revision's trajectory; old ones keep program and verdicts."""
    from robocritics.viz.studio.revisions import FULL_REVISIONS

    programs = [f"move_to(0.3, {0.01 * i:.2f}, 0.3)\nhome()\n" for i in range(FULL_REVISIONS + 3)]
    for program in programs:
        assert request(studio, "POST", "/api/run", {"program": program}, API)[0] == 200
    kept = [r for r in studio.revisions if r.execution is not None]
    assert len(kept) == FULL_REVISIONS and kept == studio.revisions[-FULL_REVISIONS:]
    assert all(r.report is None and r.deploy_report is None for r in studio.revisions[:-FULL_REVISIONS])
    old = studio.revisions[-FULL_REVISIONS - 1]
    status, body = request(studio, "GET", f"/api/revision/{old.index}", headers=API)
    shown = json.loads(body)
    assert status == 200 and shown["compact"] and shown["replay"] is None and not shown["deployable"]
    assert shown["program"] == programs[-FULL_REVISIONS - 1] and {v["critic"] for v in shown["verdicts"]} >= {
        "collision", "joint_speed"}
    status, body = request(studio, "POST", "/api/fix", {"index": old.index}, API)
    assert status == 409 and "no longer kept" in json.loads(body)["error"]


def test_an_approval_counts_as_rejected_at_its_deadline():
    """#2: an approval has a deadline (injected clock); after it, the answer is False and says why."""
    import threading

    from robocritics.viz.studio.jobs import JobBoard

    now = [0.0]
    board = JobBoard(approval_timeout_s=30.0, clock=lambda: now[0])
    job = board.begin("fix")
    answers = []
    thread = threading.Thread(target=lambda: answers.append(board.ask(job, "home()\n", "diff", "#2 from #1")))
    thread.start()
    while board.snapshot()["approval"] is None:
        threading.Event().wait(0.01)
    assert board.snapshot()["approval"]["seconds_left"] == 30.0
    now[0] = 31.0
    thread.join(5)
    assert answers == [False] and "no answer within 30 s" in job.approval.reason
    board.end(job)


def test_a_run_while_an_approval_waits_cancels_the_turn_and_other_jobs_are_refused():
    """#2, #3: one job at a time; Run cancels a turn waiting for approval; anything else is refused."""
    import threading

    from robocritics.viz.studio.jobs import Busy, Cancelled, JobBoard

    board = JobBoard(approval_timeout_s=600.0)
    job = board.begin("deploy", "revision 2")
    with pytest.raises(Busy, match="deploy of revision 2 is running"):
        board.begin("run")
    board.end(job)
    turn = board.begin("fix")
    outcome = []

    def wait():
        try:
            outcome.append(board.ask(turn, "home()\n", "diff", "#2"))
        except Cancelled as exc:
            outcome.append(str(exc))

    thread = threading.Thread(target=wait)
    thread.start()
    with pytest.raises(Busy):
        board.begin("chat")
    while board.snapshot()["approval"] is None:
        threading.Event().wait(0.01)
    run = board.begin("run")  # not held by the approval
    thread.join(5)
    assert outcome == ["cancelled by a Run while it waited for your approval"]
    assert board.job is run


def test_state_sends_the_chat_only_when_something_was_said_since(studio):
    """Every page polls the state: the chat log (up to CHAT_LOG_ENTRIES entries) is sent only when it changed."""
    from robocritics.viz.studio.common import CHAT_LOG_ENTRIES

    state = json.loads(request(studio, "GET", "/api/state", headers=API)[1])
    version = state["chat_version"]
    assert state["chat_log"] is not None
    assert json.loads(request(studio, "GET", f"/api/state?chat={version}", headers=API)[1])["chat_log"] is None
    for n in range(CHAT_LOG_ENTRIES + 5):
        studio._say("note", f"note {n}")
    state = json.loads(request(studio, "GET", f"/api/state?chat={version}", headers=API)[1])
    assert state["chat_version"] == version + CHAT_LOG_ENTRIES + 5
    assert len(state["chat_log"]) == CHAT_LOG_ENTRIES and state["chat_log"][-1]["text"] == f"note {CHAT_LOG_ENTRIES + 4}"
    assert json.loads(request(studio, "GET", "/api/state?chat=x" + "9" * 50, headers=API)[1])["chat_log"] is not None


def test_fix_all_of_a_program_that_does_not_run_asks_the_model_with_its_runtime_error():
    """#5/#6 with an LLM: the runtime row is fixable; the model is told what did not run, and its revision runs."""
    from llm_server import LLMServer
    from robocritics.llm.providers.openai_compatible import OpenAICompatible

    fixed = "move_above(green_apple)\nhome()\n"
    with LLMServer() as llm:
        llm.reply("Here it is.\n```python\n" + fixed + "```\n")
        with Studio("sorting", "", model=OpenAICompatible(base_url=llm.url, model="t")) as s:
            status, body = request(s, "POST", "/api/run", {"program": "home()\nmove_to(2.0, 0, 0.3)\n"}, API)
            assert status == 200 and json.loads(body)["verdicts"][0]["critic"] == "runtime"
            status, body = request(s, "POST", "/api/fix", {"automation": "auto",
                                                           "selected": s.installed_critics()}, API)
            events = [json.loads(line) for line in body.decode().splitlines()]
            assert status == 200 and events[-1] == {"type": "done"}, events[-1]
            assert "move_to(x=2" in llm.requests[-1].text and "0.601 m" in llm.requests[-1].text
            revision = [e for e in events if e["type"] == "revision"][-1]["revision"]
            assert revision["program"] == fixed and revision["error"] is None and revision["replay"] is not None
