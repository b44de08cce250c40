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
    assert request(studio, "POST", "/api/fix", {}, API)[0] == 409


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
