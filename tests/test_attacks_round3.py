"""Issue 22, attacked again after its fixes (round three): the neighbours of each class, end to end.

Each test drives the real command (a ``robocritics`` subprocess, or ``main`` in-process where only the argument
checks run) or the studio over HTTP, and asserts the clean outcome: a typed one-line error naming what and where,
exit 2 (bad input) or 1, no traceback, no escape byte on stdout or stderr, bounded memory measured in a child.

Classes covered here: 2 (links: benchmarks/ablation.py's outputs), 5 (a long-lived studio: revisions bounded),
6 (escape sequences from an LLM's program, a ``fix`` diff, a ``--host``), 7 (studio routes with huge ids and
revisions that do not exist), 8 (silent acceptance: ``true`` or ``"0.5"`` as a threshold, empty file options).
"""

from __future__ import annotations

import http.client
import importlib.util
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from llm_fixtures import llm_server  # noqa: F401  (fixture)

from robocritics.cli import main

ROOT = Path(__file__).resolve().parent.parent
PROGRAMS = ROOT / "examples" / "programs"

#: Escape sequences an attacker would send: set the window title, clear the screen, colour a forged line, an 8-bit
#: CSI, a right-to-left override.
ESCAPES = "\x1b]0;pwned\x07\x1b[2J\x1b[32mDEPLOYED OK\x9b2J\u202e"
TERMINAL_BYTES = ("\x1b", "\x07", "\x9b", "\u202e")


def robocritics(*argv: str, timeout: float = 120) -> subprocess.CompletedProcess:
    """The real command in a child process (text decoded as UTF-8, whatever it printed)."""
    return subprocess.run([sys.executable, "-m", "robocritics", *argv], capture_output=True, timeout=timeout,
                          encoding="utf-8", errors="surrogateescape", cwd=ROOT)  # fmt: skip


def assert_clean(done: subprocess.CompletedProcess) -> None:
    for name, text in (("stdout", done.stdout), ("stderr", done.stderr)):
        assert "Traceback" not in text, f"{name}: {text[-2000:]}"
        found = [repr(ch) for ch in TERMINAL_BYTES if ch in text]
        assert not found, f"{name} carries {found}: {text[-2000:]!r}"


# --- class 6: outside text printed to a terminal ----------------------------------------------------------


def test_run_prints_the_models_escape_sequences_escaped(llm_server):  # noqa: F811
    """`robocritics run` printed the model's program, its error and its reply raw: a reply could clear the screen
    and forge a line. Now every one is shown with visible escapes (and the program still runs)."""
    llm_server.reply(f"{ESCAPES}\n```python\nmove_above(green_apple)  # {ESCAPES}\nx = '{ESCAPES}'\n"
                     f"move_to('{ESCAPES}')\n```")  # fmt: skip
    done = robocritics("run", "put the apple away", "--scene", "sorting", "--base-url", llm_server.url, "--model",
                       "m", "--max-attempts", "1", "--critics", "joint_speed")  # fmt: skip
    assert done.returncode == 1, done.stderr  # the program does not run: move_to an unknown object
    assert_clean(done)
    assert "# \\x1b]0;pwned\\x07\\x1b[2J\\x1b[32mDEPLOYED OK\\x9b2J\\u202e" in done.stdout  # shown, not acted on
    assert "--- did not run ---" in done.stdout and "unknown object" in done.stdout


def test_fix_prints_the_diff_of_a_program_with_escape_sequences_escaped(tmp_path):
    """`robocritics fix` printed its diff raw: the program's own comment line reached the terminal."""
    naive = (PROGRAMS / "sorting_naive.py").read_text()
    program = tmp_path / "sorting_escapes.py"
    program.write_text(f"# {ESCAPES}\n" + naive.replace("open_gripper()\n", f"open_gripper()  # {ESCAPES}\n", 1))
    out = tmp_path / "fixed.py"
    done = robocritics("fix", str(program), "-o", str(out))
    assert done.returncode in (0, 1), done.stderr
    assert_clean(done)
    assert "+++ repaired" in done.stdout and "open_gripper()  # \\x1b]0;pwned" in done.stdout
    assert out.read_text().count("\x1b") == naive.count("\x1b") + 6  # the file keeps the program as written


@pytest.mark.parametrize("host", ["a\x1b[2Jb", "robot\u202eexe", "arm\x07"])
def test_a_host_with_control_characters_is_not_a_host_name(host, capsys):
    assert main(["deploy", str(PROGRAMS / "sorting_careful.py"), "--host", host]) == 2
    err = capsys.readouterr().err
    assert "argument --host" in err and "is not a host name" in err
    assert not any(ch in err for ch in TERMINAL_BYTES)


# --- class 8: silent acceptance ------------------------------------------------------------------------------


@pytest.mark.parametrize("value", ["true", "false", '"0.5"', '"fast"'])
def test_a_threshold_that_is_not_a_number_is_refused_not_converted(value, tmp_path):
    """pydantic's lax mode read `true` as 1 m/s and "0.5" as 0.5 without a word."""
    params = tmp_path / "params.json"
    params.write_text('{"joint_speed": {"warn_speed_m_s": %s}}' % value)
    done = robocritics("check", str(PROGRAMS / "sorting_careful.py"), "--params", str(params))
    assert done.returncode == 2 and done.stdout == ""
    assert_clean(done)
    assert done.stderr.startswith("robocritics: error: invalid params for critic 'joint_speed': warn_speed_m_s: ")
    assert "valid number" in done.stderr


def test_the_same_threshold_as_a_number_still_counts():
    from robocritics.critic import get_critics, resolve_params

    critic = get_critics()["joint_speed"]
    assert resolve_params(critic, {"warn_speed_m_s": 1}).warn_speed_m_s == 1.0
    assert resolve_params(critic, {"warn_speed_m_s": 0.5, "frames": ["tool0"]}).frames == ("tool0",)


@pytest.mark.parametrize(
    "argv, option",
    [(["check", "P", "--html="], "--html"), (["check", "P", "--params="], "--params"),
     (["check", "P", "--critics="], "--critics"), (["fix", "P", "-o="], "-o/--output"),
     (["batch", "in.jsonl", "-o="], "-o/--output"), (["run", "task", "--memory="], "--memory"),
     (["studio", "--program=", "--no-browser", "--host", "0.0.0.0"], "--program")],  # refused, never served
)  # fmt: skip
def test_an_empty_file_option_is_a_usage_error_not_an_absent_one(argv, option, capsys):
    """`check --html=` wrote nothing and exited 0; `--params=` ran with the defaults; `batch -o=` blamed '.'."""
    argv = [str(PROGRAMS / "sorting_careful.py") if a == "P" else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"argument {option}:" in err and ("file name is empty" in err or "no critic named" in err)


# --- class 2: every file the project writes, benchmarks included ---------------------------------------------


@pytest.fixture
def ablation():
    path = ROOT / "benchmarks" / "ablation.py"
    spec = importlib.util.spec_from_file_location("robocritics_ablation_attacks", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    yield module
    sys.modules.pop(spec.name, None)


@pytest.mark.parametrize("option", ["--json", "--results"])
def test_ablation_refuses_a_link_at_its_outputs_before_any_run(ablation, option, tmp_path, capsys):
    target = tmp_path / "precious.txt"
    target.write_text("keep me")
    link = tmp_path / "out.json"
    link.symlink_to(target)
    assert ablation.main(["--selftest", "--tasks", "sorting", option, str(link)]) == 2
    err = capsys.readouterr().err
    assert "symbolic link" in err and option in err
    assert target.read_text() == "keep me" and link.is_symlink()


def test_ablation_appends_results_without_following_a_link_put_there_later(ablation, tmp_path):
    target = tmp_path / "precious.txt"
    target.write_text("keep me")
    results = tmp_path / "results.jsonl"
    result = ablation.Result(task="sorting", condition="external", repeat=0, attempts=1, final_score=10.0,
                             best_score=10.0, final_has_error=False, goal=None, stopped="all OK", seconds=1.0,
                             runtime_errors=0)  # fmt: skip
    ablation.append_result(results, result, {"model": "m"})
    assert json.loads(results.read_text())["task"] == "sorting" and oct(results.stat().st_mode & 0o777) != "0o600"
    results.unlink()
    results.symlink_to(target)
    from robocritics._files import OutputFileError

    with pytest.raises(OutputFileError, match="symbolic link"):
        ablation.append_result(results, result, {"model": "m"})
    assert target.read_text() == "keep me"


# --- classes 5 and 7: the studio's routes and its memory -----------------------------------------------------

API = {"Content-Type": "application/json", "X-Studio": "1"}


def post(studio, path: str, body: bytes | dict) -> tuple[int, dict]:
    conn = http.client.HTTPConnection("127.0.0.1", studio.port, timeout=120)
    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    conn.request("POST", path, body=data, headers=API)
    response = conn.getresponse()
    payload = response.read()
    conn.close()
    first = payload.split(b"\n", 1)[0]  # a chat or Fix answers NDJSON: its first event
    return response.status, json.loads(first)


@pytest.fixture
def studio():
    from robocritics.viz.studio import Studio

    with Studio("sorting", "home()\n", approval_timeout_s=2.0) as s:  # a regression waits 2 s, not 10 minutes
        yield s


@pytest.mark.parametrize(
    "path, body",
    [("/api/approve", b'{"id": 1' + b"0" * 4000 + b', "ok": true}'), ("/api/deploy", {"index": 10**40}),
     ("/api/deploy", {"index": -1}), ("/api/fix", {"index": 10**30}), ("/api/fix", {"index": -5}),
     ("/api/chat", {"text": "hi", "index": 2**63})],
)  # fmt: skip
def test_studio_ids_out_of_range_are_a_400_that_does_not_quote_them(studio, path, body):
    status, answer = post(studio, path, body)
    assert status == 400, answer
    assert "must be an integer from 0 to" in answer["error"] and len(answer["error"]) < 200


def test_a_fix_of_a_revision_that_does_not_exist_is_refused_not_applied_to_the_latest(studio):
    """A Fix of #7 with only #1 silently fixed #1."""
    assert post(studio, "/api/run", {"program": "home()\n"})[0] == 200
    status, answer = post(studio, "/api/fix", {"index": 7})
    assert status == 409 and answer["error"] == "there is no revision 7"
    assert [r.index for r in studio.revisions] == [1] and studio.jobs.snapshot() is None  # nothing ran


def test_the_studio_keeps_the_last_revisions_and_numbers_go_on(studio, monkeypatch):
    from robocritics.viz.studio import server

    monkeypatch.setattr(server, "MAX_REVISIONS", 4)
    for n in range(1, 8):
        status, revision = post(studio, "/api/run", {"program": f"home()\n# {n}\n"})
        assert status == 200 and revision["index"] == n
    assert [r.index for r in studio.revisions] == [4, 5, 6, 7]
    assert [r["index"] for r in studio.state()["revisions"]] == [4, 5, 6, 7]
    assert studio.revision(5).program == "home()\n# 5\n"
    with pytest.raises(LookupError, match="there is no revision 3 \\(only the last 4 are kept\\)"):
        studio.revision(3)
    status, answer = post(studio, "/api/fix", {"index": 2})
    assert status == 409 and "only the last 4 are kept" in answer["error"]
    conn = http.client.HTTPConnection("127.0.0.1", studio.port, timeout=60)
    conn.request("GET", "/api/revision/latest")
    latest = json.loads(conn.getresponse().read())
    conn.close()
    assert latest["index"] == 7 and latest["program"] == "home()\n# 7\n"


STUDIO_MEMORY_CHILD = textwrap.dedent(
    """
    import http.client, json, resource, sys
    from robocritics.viz.studio import Studio
    from robocritics.viz.studio.revisions import MAX_REVISIONS

    body = json.dumps({"program": "#" + "x" * 199_990}).encode()  # the longest program a Run takes
    with Studio("sorting", "home()\\n") as studio:
        conn = http.client.HTTPConnection("127.0.0.1", studio.port, timeout=60)
        headers = {"Content-Type": "application/json", "X-Studio": "1"}
        peaks = []
        for rounds in (MAX_REVISIONS + 50, 500):
            for _ in range(rounds):
                conn.request("POST", "/api/run", body=body, headers=headers)
                response = conn.getresponse()
                response.read()
                assert response.status == 200, response.status
            peaks.append(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
        print(json.dumps({"peaks_kib": peaks, "revisions": len(studio.revisions), "last": studio.revisions[-1].index}))
    """
)


def test_a_long_lived_studio_stays_bounded_after_many_runs():
    """1,500 Runs of a 200 kB program grew the studio from 120 to 409 MB (every revision kept its program and
    verdicts); past MAX_REVISIONS the peak stays put. Measured with getrusage in a child."""
    from robocritics.viz.studio.revisions import MAX_REVISIONS

    done = subprocess.run([sys.executable, "-c", STUDIO_MEMORY_CHILD], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    before, after = result["peaks_kib"]
    assert result["revisions"] == MAX_REVISIONS and result["last"] == MAX_REVISIONS + 550
    # 500 more Runs unbounded would add ~95 MB (0.19 MB each); bounded, only allocator noise
    assert after - before < 30 * 1024, f"the studio grew by {(after - before) / 1024:.0f} MB over 500 Runs"


def test_a_huge_joint_angle_is_shown_short_not_in_310_digits():
    from robocritics import Robot
    from robocritics.errors import RobotModelError

    with pytest.raises(RobotModelError) as raised:
        Robot.ur3e().joint_vector([1e308, 0, 0, 0, 0, 0], "start_q")
    assert "= 1e+308 rad is outside its limits" in str(raised.value) and len(str(raised.value)) < 200
    with pytest.raises(RobotModelError, match=r"= 7\.0000 rad is outside"):
        Robot.ur3e().joint_vector([7, 0, 0, 0, 0, 0], "start_q")
