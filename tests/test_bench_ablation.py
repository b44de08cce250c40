"""benchmarks/ablation.py keeps every finished cell: JSON lines written as cells complete, resumed, an LLM error
ends only its cell, Ctrl-C loses nothing done; a runtime-error column; a reproduce line with every option.
The repairs-vs-LLM table (--repairs): its modes on the same scripted replies, checked against repair() itself."""



from __future__ import annotations

import importlib.util
import json
import os
import signal
import sys
import threading
from pathlib import Path

import pytest
from llm_fixtures import clean_llm_env, llm_server
from llm_server import Delay, Fail

pytestmark = pytest.mark.usefixtures("clean_llm_env")

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def ablation():
    path = ROOT / "benchmarks" / "ablation.py"
    spec = importlib.util.spec_from_file_location("robocritics_ablation_cells", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    yield module
    sys.modules.pop(spec.name, None)


def lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def args(server_url: str, results: Path, *extra: str) -> list[str]:
    return ["--base-url", server_url, "--model", "scripted", "--tasks", "recycling,sorting", "--conditions",
            "external", "--max-attempts", "2", "--results", str(results), "--timeout", "30", *extra]  # fmt: skip


def scene_of(request: dict) -> str:
    return "sorting" if "# Scene: sorting" in request["messages"][0]["content"] else "other"


def test_cells_are_written_as_they_finish_and_a_second_run_resumes(ablation, llm_server, tmp_path, capsys):
    results = tmp_path / "cells.jsonl"
    seen_when_sorting_starts: list[int] = []

    def responder(request):
        if scene_of(request) == "sorting" and not seen_when_sorting_starts:
            seen_when_sorting_starts.append(len(lines(results)) if results.exists() else 0)
        return ablation.scripted_responder(request)

    llm_server.responder = responder
    assert ablation.main(args(llm_server.url, results)) == 0
    assert seen_when_sorting_starts == [1]  # the recycling cell was on disk before the sorting cell began
    cells = lines(results)
    assert [(c["task"], c["condition"], c["repeat"]) for c in cells] == [("recycling", "external", 0),
                                                                         ("sorting", "external", 0)]  # fmt: skip
    assert all(c["config"]["model"] == "scripted" and c["llm_error"] is None for c in cells)
    first_out = capsys.readouterr().out
    asked = len(llm_server.chat_requests())

    assert ablation.main(args(llm_server.url, results)) == 0
    captured = capsys.readouterr()
    assert "2 of 2 cells already done" in captured.err
    assert len(llm_server.chat_requests()) == asked  # nothing was asked again
    assert len(lines(results)) == 2
    table = lambda out: out.split("Reproduce:")[0].split("\n", 1)[1]
    assert table(captured.out) == table(first_out)  # the same table, from the file


def test_one_llm_error_ends_only_its_cell_and_is_retried_on_resume(ablation, llm_server, tmp_path, capsys):
    results = tmp_path / "cells.jsonl"
    broken = {"on": True}

    def responder(request):
        if broken["on"] and scene_of(request) == "sorting":
            return Fail(400, body=json.dumps({"error": {"message": "model crashed on this prompt"}}))
        return ablation.scripted_responder(request)

    llm_server.responder = responder
    assert ablation.main(args(llm_server.url, results)) == 1
    captured = capsys.readouterr()
    assert "model crashed on this prompt" in captured.err and "1 cell(s) ended with an LLM error" in captured.err
    cells = lines(results)
    assert [c["stopped"] for c in cells] == ["all OK", "llm error"]
    assert "model crashed" in cells[1]["llm_error"]

    broken["on"] = False
    assert ablation.main(args(llm_server.url, results)) == 0
    captured = capsys.readouterr()
    assert "1 of 2 cells already done" in captured.err
    assert [c["stopped"] for c in lines(results)] == ["all OK", "llm error", "all OK"]
    assert "llm error" not in captured.out  # the table has the finished cell


def test_ctrl_c_keeps_the_finished_cells(ablation, llm_server, tmp_path, capsys):
    results = tmp_path / "cells.jsonl"

    def responder(request):
        if scene_of(request) == "sorting":  # Ctrl-C while the second cell waits for the model
            threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGINT)).start()
            # the reply never comes before the interrupt, however late a loaded machine delivers it
            # (the server stops waiting when it shuts down)
            return Delay(25.0)
        return ablation.scripted_responder(request)

    llm_server.responder = responder
    # Ctrl-C raises KeyboardInterrupt even when the test run itself was started with SIGINT ignored
    # (a shell's background job), as it does for a user at a terminal
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        code = ablation.main(args(llm_server.url, results))
    finally:
        signal.signal(signal.SIGINT, previous)
    captured = capsys.readouterr()
    assert code == 130
    assert "Interrupted: 1 of 2 cells done" in captured.err and "resume" in captured.err
    assert [c["task"] for c in lines(results)] == ["recycling"]
    assert "recycling  external" in captured.out  # the table of what was done is still printed


def test_a_line_cut_by_a_crash_and_cells_of_another_configuration_are_not_reused(ablation, llm_server, tmp_path,
                                                                                 capsys):  # fmt: skip
    results = tmp_path / "cells.jsonl"
    llm_server.responder = ablation.scripted_responder
    assert ablation.main(args(llm_server.url, results)) == 0
    with open(results, "a") as f:
        f.write('{"config": {"model": "scripted"}, "task": "sor')  # the process died while writing
    capsys.readouterr()
    assert ablation.main(args(llm_server.url, results, "--max-tokens", "900")) == 0
    err = capsys.readouterr().err
    assert "1 unreadable line(s)" in err and "2 cell(s) in" in err and "another configuration" in err


def test_the_table_has_a_runtime_error_column_and_the_reproduce_line_every_option(ablation, llm_server, tmp_path,
                                                                                  capsys):  # fmt: skip
    results = tmp_path / "cells.jsonl"
    replies = iter(["no code here, sorry", None])

    def responder(request):
        reply = next(replies, None)
        return reply if reply is not None else ablation.scripted_responder(request)

    llm_server.responder = responder
    assert ablation.main(args(llm_server.url, results, "--max-tokens", "700", "--context-tokens", "8192")) == 0
    out = capsys.readouterr().out
    header = out.splitlines()[2]
    assert "runtime errors" in header
    row = next(line for line in out.splitlines() if line.startswith("recycling"))
    assert row.split()[-3] == "1.0" and row.endswith("all OK")  # the reply without code
    reproduce = next(line for line in out.splitlines() if line.startswith("Reproduce:"))
    for option in ("--timeout 30", "--max-tokens 700", "--context-tokens 8192", f"--results {results}",
                   "--max-attempts 2", "--conditions external"):  # fmt: skip
        assert option in reproduce


# --- repairs vs LLM (--repairs) -----------------------------------------------------------------------


def test_the_repairs_table_compares_the_modes_on_the_same_scripted_replies(ablation, llm_server, tmp_path, capsys):
    from robocritics.repair import repair
    from robocritics.scene import Scene

    llm_server.responder = ablation.scripted_responder
    out_json = tmp_path / "repairs.json"
    argv = ["--base-url", llm_server.url, "--model", "scripted", "--repairs", "--tasks", "sorting",
            "--max-attempts", "3", "--timeout", "30", "--json", str(out_json)]  # fmt: skip
    assert ablation.main(argv) == 0
    out = capsys.readouterr().out
    rows = json.loads(out_json.read_text())
    by = {r["mode"]: r for r in rows}
    assert [r["mode"] for r in rows] == [*ablation.REPAIR_MODES, "careful"] and {r["task"] for r in rows} == {"sorting"}
    # every model reply the table counts is a request the server answered (the careful row asks nothing)
    assert sum(r["llm_calls"] for r in rows if r["llm_calls"] is not None) == len(llm_server.chat_requests())
    assert by["careful"]["llm_calls"] is None and by["careful"]["repairs"] == 0
    assert 1 <= by["repairs+llm"]["llm_calls"] <= by["llm-only"]["llm_calls"] <= 3
    assert by["llm-only"]["repairs"] == 0 and by["repairs-only"]["llm_calls"] == 1
    for r in rows:
        assert r["cycle_time_s"] > 0 and r["cpu_s"] > 0 and 0 <= r["final_score"] <= 10
        assert r["goal"] is True  # every mode still does the task (the loops check its goals)

    # repairs-only is exactly repair() on the naive program with the task's goals (the reference)
    scene = Scene.builtin("sorting")
    reference = repair(ablation.example_programs("sorting")[0], scene, goal=ablation.task_goals("sorting", scene))
    assert by["repairs-only"]["repairs"] == len(reference.changes)
    assert by["repairs-only"]["final_score"] == reference.report.score
    assert by["repairs-only"]["errors_left"] == [v.critic for v in reference.report.verdicts if v.flag.name == "ERROR"]
    assert by["repairs-only"]["cycle_time_s"] == pytest.approx(reference.execution.duration_s)

    lines_out = out.splitlines()
    header = next(line for line in lines_out if line.startswith("task"))
    for column in ("mode", "LLM calls", "repairs", "final score", "Error left", "cycle s", "CPU s", "goal"):
        assert column in header
    table_rows = [line.split()[:3] for line in lines_out if line.startswith("sorting")]
    assert table_rows == [["sorting", r["mode"], "-" if r["llm_calls"] is None else str(r["llm_calls"])]
                          for r in rows]  # fmt: skip
    reproduce = next(line for line in lines_out if line.startswith("Reproduce:"))
    assert "--repairs" in reproduce and "--tasks sorting" in reproduce and "--max-attempts 3" in reproduce
    assert "--repeats" not in reproduce and "--results" not in reproduce  # options the table does not use


def test_repairs_never_cost_model_calls_even_with_a_model_that_never_improves(ablation, llm_server):
    llm_server.responder = ablation.stubborn_responder  # the naive program, whatever it is told
    from robocritics.llm.providers.openai_compatible import OpenAICompatible

    with OpenAICompatible(base_url=llm_server.url, model="stubborn", timeout_s=30) as client:
        runs = {mode: ablation.run_repairs_one(client, "sorting", mode, max_attempts=3)
                for mode in ("llm-only", "repairs+llm")}  # fmt: skip
    assert runs["llm-only"].llm_calls == 3  # it never passes, so every reply is used
    assert runs["repairs+llm"].llm_calls <= runs["llm-only"].llm_calls
    assert runs["repairs+llm"].repairs > 0 and runs["llm-only"].repairs == 0
    # the program handed back is never worse for the repairs (they never make a verdict worse)
    assert len(runs["repairs+llm"].errors_left) <= len(runs["llm-only"].errors_left)
    assert runs["repairs+llm"].final_score >= runs["llm-only"].final_score


def test_the_paper_protocol_runs_without_repairs(ablation, llm_server, tmp_path):
    llm_server.responder = ablation.scripted_responder
    results = tmp_path / "cells.jsonl"
    assert ablation.main(args(llm_server.url, results, "--tasks", "sorting")) == 0
    (cell,) = lines(results)
    # naive program, then the model's careful one: two replies, no repair in between (it would be a third attempt)
    assert cell["attempts"] == 2 and len(cell["scores"]) == 2 and len(llm_server.chat_requests()) == 2


def test_the_stubborn_model_is_only_a_self_test(ablation, capsys):
    assert ablation.main(["--stubborn", "--base-url", "http://127.0.0.1:9/v1", "--model", "m"]) == 2
    assert "--stubborn is a scripted model" in capsys.readouterr().err
