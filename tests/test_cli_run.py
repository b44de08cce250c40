"""``robocritics run`` end to end against the loopback LLM server."""

# ruff: noqa: F811  (pytest fixtures imported from llm_fixtures are parameters here)

from __future__ import annotations

import argparse
import io
import time
from pathlib import Path

import pytest
from llm_fixtures import clean_llm_env, llm_server  # noqa: F401
from llm_server import Fail

from robocritics.cli.run import add_run_parser, run_command
from robocritics.llm.memory import InteractionMemory

pytestmark = pytest.mark.usefixtures("clean_llm_env")

PROGRAMS = Path(__file__).resolve().parent.parent / "examples" / "programs"
NAIVE = (PROGRAMS / "sorting_naive.py").read_text()
CAREFUL = (PROGRAMS / "sorting_careful.py").read_text()
TASK = "sort the apples by ripeness"
SPEED_CRITICS = "joint_speed,end_effector_pose"


def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="robocritics")
    sub = parser.add_subparsers(dest="command", required=True)
    add_run_parser(sub)
    return parser.parse_args(["run", *argv])


def run(*argv: str) -> int:
    args = parse(*argv)
    assert args.func is run_command
    return run_command(args)


def fenced(program: str) -> str:
    return f"```python\n{program}```"


def test_auto_run_end_to_end(llm_server, capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("MY_LLM_KEY", "sk-cli-test-key")
    llm_server.require_api_key = "sk-cli-test-key"
    llm_server.reply(fenced(NAIVE), fenced(CAREFUL), "PROGRAM COMPLETE")
    memory = tmp_path / "memory.sqlite"
    code = run(
        TASK,
        "--scene", "sorting",
        "--base-url", llm_server.url,
        "--model", "cli-model",
        "--api-key-env", "MY_LLM_KEY",
        "--auto",
        "--no-repairs",  # the paper's loop: every fix goes to the model
        "--max-attempts", "4",
        "--critics", SPEED_CRITICS,
        "--memory", str(memory),
    )  # fmt: skip
    out = capsys.readouterr().out
    assert code == 0
    assert "=== attempt 1 [request] ===" in out and "=== attempt 2 [fix] ===" in out
    assert "=== attempt 3" not in out  # every critic OK after the fix: the model is not asked again
    assert "move_down(0.2)" in out and "lib.set_speed(0.3)" in out  # both programs are printed
    assert out.count("RoboCritics report: score") == 2  # str(report) of each attempt
    assert "joint_speed" in out and "end_effector_pose" in out and "collision" not in out
    assert "score: 10/10" in out
    assert "final: attempt 2 of 2, score 10/10, no Error" in out
    assert llm_server.pending == 1
    requests = llm_server.chat_requests()
    assert {r.json["model"] for r in requests} == {"cli-model"}
    assert "Joint speed" in requests[1].text and "fingers point" in requests[1].text  # both critics failed
    with InteractionMemory(memory) as stored:
        assert len(stored) == 2


def test_auto_run_repairs_first_and_asks_the_model_only_when_something_is_left(llm_server, capsys):
    from robocritics import Scene
    from robocritics.repair import repair

    llm_server.reply(fenced(NAIVE), fenced(CAREFUL), "PROGRAM COMPLETE")
    code = run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--auto",
               "--critics", SPEED_CRITICS)  # fmt: skip
    out = capsys.readouterr().out
    repaired = repair(NAIVE, Scene.builtin("sorting"), critics=SPEED_CRITICS.split(","))
    assert repaired.changes  # the naive program spears: the end-effector critic slows its approaches
    assert "=== attempt 2 [repair] ===" in out and "--- critic repairs ---" in out
    assert all(str(change) in out for change in repaired.changes)
    # the repairs lift the Error and the Warnings alike: nothing is left, so the model is not asked again
    assert not repaired.errors and {v.flag.value for v in repaired.report.verdicts} == {"OK"}
    assert len(llm_server.chat_requests()) == 1 and "[fix]" not in out
    assert code == 0 and "final: attempt 2 of 2, score 10/10, no Error" in out


def test_single_request_with_an_error_exits_1(llm_server, capsys):
    llm_server.reply(fenced(NAIVE), fenced(CAREFUL))
    code = run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--critics", SPEED_CRITICS)
    out = capsys.readouterr().out
    assert code == 1  # the naive program spears: an Error
    assert len(llm_server.chat_requests()) == 1  # no --auto: one request
    assert "ERROR" in out and "final: attempt 1, score" in out and "it still has an Error" in out


def test_program_that_does_not_run_exits_1(llm_server, capsys):
    llm_server.reply("```python\nimport os\n```")
    code = run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m")
    out = capsys.readouterr().out
    assert code == 1
    assert "--- did not run ---" in out and "import" in out and "its program did not run" in out


def test_configuration_from_the_environment(llm_server, capsys, monkeypatch):
    monkeypatch.setenv("ROBOCRITICS_BASE_URL", llm_server.url)
    monkeypatch.setenv("ROBOCRITICS_MODEL", "env-model")
    llm_server.reply("```python\nmove_above(green_apple)\n```")
    assert run(TASK, "--scene", "sorting", "--critics", "joint_speed") == 0
    assert llm_server.chat_requests()[0].json["model"] == "env-model"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--model", "m"], "no LLM endpoint configured"),
        (["--base-url", "http://127.0.0.1:9/v1"], "no chat model configured"),
        (["--base-url", "http://127.0.0.1:9/v1", "--model", "m", "--api-key-env", "NOT_SET_ANYWHERE"], "NOT_SET_ANYWHERE"),
        (["--base-url", "http://127.0.0.1:9/v1", "--model", "m", "--critics", "joint_sped"], "did you mean 'joint_speed'"),
        (["--base-url", "http://127.0.0.1:9/v1", "--model", "m", "--scene", "sortin"], "sortin"),
    ],
)
def test_configuration_errors_exit_2(argv, message, capsys):
    if "--scene" not in argv:
        argv = [*argv, "--scene", "sorting"]
    assert run(TASK, *argv) == 2
    captured = capsys.readouterr()
    assert message in captured.err and captured.err.startswith("robocritics run: error:")
    assert captured.out == ""


def test_endpoint_failure_exits_2(llm_server, capsys):
    llm_server.script(Fail(404))
    assert run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m") == 2
    err = capsys.readouterr().err
    assert "LLM endpoint failed" in err and "404" in err


def test_params_file_reaches_the_critics(llm_server, capsys, tmp_path):
    strict = tmp_path / "strict.json"
    strict.write_text('{"joint_speed": {"warn_speed_m_s": 0.001, "max_speed_m_s": 0.002}}')
    program = "```python\nmove_above(green_apple)\n```"
    llm_server.reply(program, program)
    base = (TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--critics", "joint_speed")
    assert run(*base) == 0
    assert run(*base, "--params", str(strict)) == 1  # the same motion is now far too fast
    assert "final: attempt 1, score" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("{not json", "is not valid JSON"),  # the shared loader's own words (cli._common.load_params)
        ('{"joint_speed": 0.8}', "must hold a JSON object of critic names to objects"),
    ],
)
def test_a_bad_params_file_exits_2_before_any_request(llm_server, capsys, tmp_path, content, message):
    bad = tmp_path / "params.json"
    bad.write_text(content)
    assert run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--params", str(bad)) == 2
    assert message in capsys.readouterr().err
    assert llm_server.requests == []


def test_defaults_match_the_library():
    from robocritics.llm.options import DEFAULT_MAX_ATTEMPTS

    args = parse(TASK, "--scene", "sorting")
    assert args.max_attempts == DEFAULT_MAX_ATTEMPTS


# -- hostile servers and inputs (issue 10): exit 2 with one line, never a traceback or a hang --------

# How late past --timeout a run may end on a loaded machine.
SLACK_S = 2.5


def test_a_dripping_server_ends_the_run_at_the_timeout(llm_server, capsys):
    from llm_server import chat_body, drip

    llm_server.script(drip(chat_body("x" * 500), interval_s=0.25))  # 2 minutes of reply, a byte at a time
    started = time.monotonic()
    code = run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--timeout", "1.5")
    elapsed = time.monotonic() - started
    assert code == 2
    err = capsys.readouterr().err
    assert "LLM endpoint failed" in err and "deadline of 1.5 s" in err and "Traceback" not in err
    assert elapsed < 1.5 + SLACK_S


def test_undecodable_text_prints_on_a_strict_ascii_terminal(llm_server):
    llm_server.reply("```python\nmove_above(green_apple)  # gr\u00fcn \ud800\n```")
    raw = io.BytesIO()
    out = io.TextIOWrapper(raw, encoding="ascii", errors="strict")
    args = parse("put the apple \udcff away", "--scene", "sorting", "--base-url", llm_server.url, "--model", "m",
                 "--critics", "joint_speed")  # fmt: skip
    assert run_command(args, stdout=out, stderr=io.StringIO()) == 0
    out.flush()
    printed = raw.getvalue().decode("ascii")
    assert "move_above(green_apple)  # gr?n ?" in printed and "task: put the apple ? away" in printed


def test_a_long_program_is_printed_cut(llm_server, capsys):
    from robocritics.llm.limits import MAX_PRINTED_CHARS

    program = "move_above(green_apple)\n" + "x = 1\n" * 10_000
    llm_server.reply(f"```python\n{program}```")
    run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--critics", "joint_speed",
        "--max-tokens", "100000")  # fmt: skip
    out = capsys.readouterr().out
    assert "more characters of the program not shown" in out
    assert len(out) < MAX_PRINTED_CHARS + 5_000


@pytest.mark.parametrize(
    ("task", "message"),
    [("", "the task description is empty"), ("   ", "the task description is empty"),
     ("t" * 5_000, "is 5,000 characters long; the limit is 4,000")],
)  # fmt: skip
def test_an_unusable_task_exits_2_before_any_request(llm_server, capsys, task, message):
    assert run(task, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m") == 2
    captured = capsys.readouterr()
    assert message in captured.err and captured.out == ""
    assert llm_server.requests == []


@pytest.mark.parametrize("value", ["nan", "inf", "-1", "2.5", "warm"])
def test_a_bad_temperature_is_a_usage_error(value, capsys):
    with pytest.raises(SystemExit) as exited:
        parse(TASK, "--scene", "sorting", "--temperature", value)
    assert exited.value.code == 2
    assert "--temperature" in capsys.readouterr().err


def test_an_unusable_memory_file_exits_2_before_any_request(llm_server, capsys, tmp_path):
    (tmp_path / "notes.txt").write_text("a file where a directory should be")
    code = run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m",
               "--memory", str(tmp_path / "notes.txt" / "memory.sqlite"))  # fmt: skip
    assert code == 2
    err = capsys.readouterr().err
    assert "interaction memory" in err and "cannot be created" in err and "Traceback" not in err
    assert llm_server.requests == []


def test_a_damaged_memory_file_exits_2(llm_server, capsys, tmp_path):
    damaged = tmp_path / "memory.sqlite"
    damaged.write_bytes(b"SQLite format 3\x00" + b"\xff" * 8000)
    code = run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--memory", str(damaged))
    assert code == 2
    assert "damaged or not a database" in capsys.readouterr().err


# --- real servers: bounded generation, progress, small contexts, no embeddings (issue 11) ---------------------


def _endless_tokens():
    """A streamed reply that never ends: a server that ignores max_tokens and the model never stops."""
    import json as _json

    yield b"data: " + _json.dumps({"choices": [{"index": 0, "delta": {"role": "assistant"}}]}).encode() + b"\n\n"
    while True:
        chunk = {"choices": [{"index": 0, "delta": {"content": "move_up(0.01)\n"}, "finish_reason": None}]}
        yield b"data: " + _json.dumps(chunk).encode() + b"\n\n"


def test_auto_against_an_uncapped_server_that_never_stops_ends_at_the_deadline(llm_server, capsys):
    from llm_server import Stream

    llm_server.script(Stream(_endless_tokens, interval_s=0.02, content_type="text/event-stream"))
    started = time.monotonic()
    code = run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--auto", "--timeout", "1.5")
    elapsed = time.monotonic() - started
    captured = capsys.readouterr()
    assert code == 2
    assert "deadline of 1.5 s" in captured.err
    assert elapsed < 1.5 + 3.0  # the deadline and the scene set-up, on a loaded machine
    assert llm_server.cancelled.wait(2.0) or len(llm_server.chat_requests()) == 1
    assert len(llm_server.chat_requests()) == 1  # a timed-out generation is not retried


def test_auto_against_a_slow_capped_server_finishes_with_a_result(llm_server, capsys):
    llm_server.token_interval_s = 0.002
    long_reply = fenced(NAIVE) + "\nNow let me explain every line in detail. " * 200
    llm_server.reply(fenced("# a very long preamble\n" * 400 + NAIVE), long_reply, "PROGRAM COMPLETE")
    code = run(
        TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--auto", "--max-attempts", "3",
        "--critics", SPEED_CRITICS, "--max-tokens", "400", "--timeout", "60",
    )  # fmt: skip
    out = capsys.readouterr().out
    assert code in (0, 1)
    assert {r.json["max_tokens"] for r in llm_server.chat_requests()} == {400}
    assert "Your reply was cut at 400 tokens" in llm_server.chat_requests()[1].text  # said so to the model
    assert "final: attempt" in out


def test_progress_lines_show_the_wait_and_the_tokens(llm_server, capsys, monkeypatch):
    import robocritics.cli.run as run_module

    monkeypatch.setattr(run_module, "_PROGRESS_EVERY_S", 0.0)  # a line per token: the test does not wait
    llm_server.reply(fenced(NAIVE))
    run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--critics", SPEED_CRITICS,
        "--verbose")  # fmt: skip
    err = capsys.readouterr().err
    assert "robocritics run: asking m (prompt ~" in err
    assert "  ... 1 tokens," in err and "  ... 2 tokens," in err
    assert "  reply: " in err and " tokens in " in err


def test_without_verbose_one_line_per_request(llm_server, capsys):
    llm_server.reply(fenced(NAIVE))
    run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--critics", SPEED_CRITICS)
    err = capsys.readouterr().err
    assert err.count("asking m ...") == 1 and err.count("  reply: ") == 1 and "  ... " not in err


def test_the_context_comes_from_the_server_and_the_prompt_fits(llm_server, capsys):
    from llm_server import count_tokens

    llm_server.context_tokens = 2048
    llm_server.props = True
    llm_server.reply(fenced(NAIVE))
    code = run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--critics", SPEED_CRITICS)
    out = capsys.readouterr().out
    assert code == 0 or "final:" in out
    assert "context: 2,048 tokens (from the server)" in out
    (request,) = llm_server.chat_requests()
    assert count_tokens(request.messages) + request.json["max_tokens"] <= 2048


def test_context_tokens_option_wins_over_the_server(llm_server, capsys):
    llm_server.context_tokens = 100_000
    llm_server.props = True
    llm_server.reply(fenced(NAIVE))
    run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--critics", SPEED_CRITICS,
        "--context-tokens", "3000")  # fmt: skip
    assert "context: 3,000 tokens (--context-tokens)" in capsys.readouterr().out


@pytest.mark.parametrize("mode", ["no-embedding", "not-implemented"])
def test_a_server_without_embeddings_warns_once_and_the_run_goes_on(llm_server, capsys, tmp_path, mode):
    memory = tmp_path / "memory.sqlite"
    with InteractionMemory(memory) as stored:
        stored.add("s", "sort the apples by ripeness, carefully", CAREFUL, "all OK", 10.0)
    llm_server.embedding_mode = mode
    llm_server.reply(fenced(NAIVE))
    code = run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--critics", SPEED_CRITICS,
               "--memory", str(memory), "--embedding-model", "e")  # fmt: skip
    captured = capsys.readouterr()
    assert "final: attempt 1" in captured.out and code in (0, 1)
    assert captured.err.count("warning: memory retrieval by embeddings failed") == 1
    assert "keywords (BM25)" in captured.err
    assert len(llm_server.embedding_requests()) == 1


def test_no_stream_asks_for_whole_replies(llm_server, capsys):
    llm_server.reply(fenced(NAIVE))
    run(TASK, "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--critics", SPEED_CRITICS,
        "--no-stream")  # fmt: skip
    assert "stream" not in llm_server.chat_requests()[0].json
