"""The RoboCritics loop against a real OpenAI-compatible server on 127.0.0.1 (no mocks).

The scripted "model" answers with the example programs: the naive one is
criticised (too fast, spearing), the careful one is slower. Each simulation
takes a few tenths of a second, so every test simulates only a few programs.
Tests of the model's side of a Fix use ``repairs=False`` (the paper's loop);
repairs before the model are tested in tests/test_loop_repairs.py.
"""

# ruff: noqa: F811  (pytest fixtures imported from llm_fixtures are parameters here)

from __future__ import annotations

import sqlite3
import sys
from pathlib import Path

import pytest
from llm_fixtures import clean_llm_env, llm_server, make_client  # noqa: F401
from llm_server import Fail, Reply

from robocritics.critic import CriticParams
from robocritics.errors import CriticError, LLMError, RoboCriticsError
from robocritics.llm.loop import Attempt, Loop, NothingToFixError
from robocritics.llm.memory import InteractionMemory
from robocritics.llm.prompts import REVIEW_INSTRUCTION
from robocritics.scene import Scene

pytestmark = pytest.mark.usefixtures("clean_llm_env")

PROGRAMS = Path(__file__).resolve().parent.parent / "examples" / "programs"
NAIVE = (PROGRAMS / "sorting_naive.py").read_text()
CAREFUL = (PROGRAMS / "sorting_careful.py").read_text()
TASK = "sort the apples by ripeness: red apples into the brown box, the green apple into the white box"
# The critics the careful program is written to satisfy and the naive one violates.
SPEED_CRITICS = ["joint_speed", "end_effector_pose"]
# The paper's five motion critics: pinned, so an installed plugin does not change what the tests expect.
MOTION_CRITICS = ["joint_speed", "end_effector_pose", "collision", "pinch_point", "space_usage"]


# A short real motion (a program that does not move at all has nothing to judge).
SHORT = "```python\nmove_above(green_apple)\nhome()\n```"


def fenced(program: str, prose: str = "Here is the program:") -> str:
    return f"{prose}\n\n```python\n{program}```\n"


@pytest.fixture(scope="module")
def sorting() -> Scene:
    return Scene.builtin("sorting")


def last_user(request) -> str:
    return request.messages[-1]["content"]


# --- the fix round trip --------------------------------------------------------------------


def test_fix_round_trip_raises_the_score(llm_server, make_client, sorting):
    llm_server.reply(fenced(NAIVE), fenced(CAREFUL, "I slowed the robot down near the objects:"))
    loop = Loop(make_client(), sorting, repairs=False, critics=MOTION_CRITICS)
    first = loop.request(TASK)
    assert isinstance(first, Attempt) and first.index == 1 and first.kind == "request"
    assert first.program == NAIVE and first.report is not None and first.execution is not None
    assert first.error is None and first.diff == ""  # nothing before it
    failing = [name for name in SPEED_CRITICS if not first.report.verdict(name).ok]
    assert failing, "the naive program should be too fast"

    second = loop.fix(SPEED_CRITICS)
    assert second.kind == "fix" and second.index == 2
    assert second.score > first.score
    assert all(second.report.verdict(name).ok for name in SPEED_CRITICS)
    assert second.diff.startswith("--- attempt 1\n+++ attempt 2\n")
    assert "+lib.set_speed(0.3)" in second.diff and "-move_down(0.2)" in second.diff
    assert loop.current is second and loop.attempts == [first, second]

    # What the model received: the failing critics' messages and the program lines they point at.
    sent = last_user(llm_server.chat_requests()[1])
    assert second.prompt == sent
    naive_lines = NAIVE.splitlines()
    for name in failing:
        verdict = first.report.verdict(name)
        assert verdict.feedback() in sent
        for n in verdict.evidence.lines:
            assert f">> {n:>2} | {naive_lines[n - 1]}" in sent
    for verdict in first.report.verdicts:  # only the selected critics are forwarded
        if verdict.critic not in SPEED_CRITICS:
            assert verdict.message not in sent
    # the conversation so far: system, task, program, fix request
    roles = [m["role"] for m in llm_server.chat_requests()[1].messages]
    assert roles == ["system", "user", "assistant", "user"]
    assert llm_server.chat_requests()[1].messages[2]["content"] == fenced(NAIVE)


def test_fix_refuses_without_anything_to_fix(llm_server, make_client, sorting):
    loop = Loop(make_client(), sorting, critics=SPEED_CRITICS)
    with pytest.raises(NothingToFixError, match="no attempt yet"):
        loop.fix()
    llm_server.reply(fenced(CAREFUL))
    attempt = loop.request(TASK)
    assert attempt.passed and attempt.failing == [] and attempt.score == 10
    with pytest.raises(NothingToFixError, match="passed"):
        loop.fix()
    with pytest.raises(CriticError, match="collision"):
        loop.fix(["collision"])  # not among the critics that ran
    assert len(llm_server.chat_requests()) == 1  # refusals never reach the model


# --- run(): the paper's stop rule ----------------------------------------------------------


def test_run_stops_when_the_model_says_complete(llm_server, make_client, sorting):
    llm_server.reply(fenced(NAIVE), "I have reviewed the feedback. PROGRAM COMPLETE", fenced(CAREFUL))
    seen: list[Attempt] = []
    loop = Loop(make_client(), sorting, repairs=False, critics=MOTION_CRITICS, on_attempt=seen.append)
    best = loop.run(TASK, max_attempts=5)
    assert len(loop.last_run) == 2 and seen == loop.attempts == loop.last_run
    first, done = loop.attempts
    assert done.complete and not done.changed and done.kind == "fix"
    assert done.program == first.program and done.report is first.report and done.score == first.score
    assert best is done  # equal score: the later attempt
    assert llm_server.pending == 1  # the third reply was never asked for
    assert len(llm_server.chat_requests()) == 2


def test_run_same_program_with_complete_counts_as_done(llm_server, make_client, sorting):
    llm_server.reply(fenced(NAIVE), fenced(NAIVE, "No change needed. PROGRAM COMPLETE."))
    loop = Loop(make_client(), sorting, repairs=False, critics=MOTION_CRITICS)
    loop.run(TASK)
    assert [a.complete for a in loop.last_run] == [False, True]
    assert loop.last_run[1].diff == ""


def test_run_stops_when_every_critic_is_ok(llm_server, make_client, sorting):
    llm_server.reply(fenced(NAIVE), fenced(CAREFUL), "PROGRAM COMPLETE")
    loop = Loop(make_client(), sorting, repairs=False, critics=SPEED_CRITICS)
    best = loop.run(TASK, max_attempts=5)
    assert len(loop.last_run) == 2 and best is loop.attempts[1] and best.passed
    assert llm_server.pending == 1  # the model is not asked again once everything is OK


def test_run_stops_at_max_attempts_and_returns_the_best(llm_server, make_client, sorting):
    # A recommended speed of 0.1 m/s: even the careful program gets a warning, so it never passes.
    params = {"joint_speed": {"warn_speed_m_s": 0.1}}
    llm_server.reply(fenced(NAIVE), fenced(CAREFUL), fenced(NAIVE), fenced(NAIVE), fenced(NAIVE))
    loop = Loop(make_client(), sorting, repairs=False, critics=SPEED_CRITICS, params=params, max_attempts=3)
    best = loop.run(TASK)  # the loop's own max_attempts
    assert len(loop.last_run) == 3
    assert [a.changed for a in loop.last_run] == [True, True, True]
    assert loop.attempts[1].report.verdict("joint_speed").flag.label == "Warning"
    assert best is loop.attempts[1]  # the careful program scored best; the last one regressed
    assert loop.current is loop.attempts[2]
    assert llm_server.pending == 2


def test_auto_request_iterates(llm_server, make_client, sorting):
    llm_server.reply(fenced(NAIVE), fenced(CAREFUL))
    loop = Loop(make_client(), sorting, repairs=False, critics=SPEED_CRITICS, automation="auto")
    best = loop.request(TASK)
    assert len(loop.attempts) == 2 and best.passed


def test_manual_only_reports(llm_server, make_client, sorting):
    llm_server.reply("Sure! I'll get right on it.", fenced(CAREFUL))
    loop = Loop(make_client(), sorting, automation="manual")
    attempt = loop.run(TASK, max_attempts=5)
    assert len(loop.attempts) == 1 and attempt.error
    with pytest.raises(RoboCriticsError, match="manual"):
        loop.fix()
    revised = loop.refine("Please write the program now, slowly.")
    assert revised.program == CAREFUL
    sent = last_user(llm_server.chat_requests()[1])
    assert sent.endswith("Please write the program now, slowly.") and "no Python program" in sent


# --- runtime feedback: no code, garbled code, hostile code, unreachable targets ------------------


def test_replies_without_usable_code_are_fed_back(llm_server, make_client, sorting):
    llm_server.reply(
        "I'm sorry, I can't help with moving robots.",
        "```python\nfor apple in objects:\n    move_above(apple\n```",  # garbled: a syntax error
        fenced(NAIVE),
    )
    loop = Loop(make_client(), sorting, critics=SPEED_CRITICS)
    loop.run(TASK, max_attempts=3)
    no_code, garbled, good = loop.attempts
    assert no_code.program is None and no_code.report is None and "no Python program" in no_code.error
    assert garbled.program is not None and garbled.report is None and garbled.execution is None
    assert "line 2, column 15" in garbled.error  # the unclosed '('
    assert good.report is not None and good.error is None
    requests = llm_server.chat_requests()
    assert no_code.error in last_user(requests[1])
    assert "can't help" in last_user(requests[1])  # the reply is quoted
    assert garbled.error in last_user(requests[2])
    assert "move_above(apple" in last_user(requests[2])  # the offending line is quoted
    # the assistant turns are kept verbatim in the conversation
    assert requests[2].messages[2]["content"] == "I'm sorry, I can't help with moving robots."


def test_hostile_program_is_stopped_by_the_sandbox_and_fed_back(llm_server, make_client, sorting, tmp_path):
    marker = tmp_path / "pwned"
    hostile = f"import os\nos.system('touch {marker}')\nmove_to(0.3, 0.0, 0.2)\n"
    llm_server.reply(fenced(hostile), SHORT)
    loop = Loop(make_client(), sorting)
    attempt = loop.request(TASK)
    assert attempt.program == hostile and attempt.report is None
    assert "line 1" in attempt.error and "import os" in attempt.error
    assert not marker.exists()
    # the next turn (here the user's own words) carries the sandbox's message first
    loop.refine("Use only the skill API.")
    sent = last_user(llm_server.chat_requests()[1])
    assert sent.startswith(attempt.error) and sent.endswith("Use only the skill API.")
    assert loop.attempts[1].diff.startswith("--- attempt 1\n")


def test_unreachable_target_is_fed_back_with_its_line(llm_server, make_client, sorting):
    program = "move_above(green_apple)\nmove_to(0.95, 0.0, 0.2)\nhome()\n"
    llm_server.reply(fenced(program), SHORT)
    loop = Loop(make_client(), sorting)
    attempt = loop.request(TASK)
    assert attempt.report is None and "line 2" in attempt.error
    assert ">> 2 | move_to(0.95, 0.0, 0.2)" in attempt.error
    fixed = loop.fix()  # the Fix button forwards the runtime feedback
    assert attempt.error in last_user(llm_server.chat_requests()[1])
    assert fixed.report is not None and fixed.program == "move_above(green_apple)\nhome()\n"


def test_complete_after_a_failure_is_not_accepted(llm_server, make_client, sorting):
    llm_server.reply(fenced("move_to(0.95, 0.0, 0.2)\n"), "PROGRAM COMPLETE", SHORT)
    loop = Loop(make_client(), sorting)
    loop.run(TASK, max_attempts=3)
    failed, claimed, fixed = loop.attempts
    assert not claimed.complete and "did not run" in claimed.error
    assert "did not run" in last_user(llm_server.chat_requests()[2])
    assert fixed.program == "move_above(green_apple)\nhome()\n"
    assert fixed.report is not None and fixed.error is None and loop.current is fixed


# --- approval --------------------------------------------------------------------------------


class BrokenCritic:
    """A third-party critic with a bug."""

    name = "broken"
    description = "Always fails."
    Params = CriticParams

    def check(self, trajectory, scene, params):
        raise ZeroDivisionError("oops")


def test_a_critic_that_cannot_judge_the_motion_does_not_crash_the_loop(llm_server, make_client, sorting):
    llm_server.reply(SHORT, SHORT)
    loop = Loop(make_client(), sorting, critics=["joint_speed", BrokenCritic()])
    assert loop.critics == ["joint_speed", "broken"]
    attempt = loop.request(TASK)
    assert attempt.execution is not None and attempt.report is None
    assert "critics could not check" in attempt.error and "broken" in attempt.error
    assert "- broken: Always fails." not in loop.system  # rules are pasted only when embedded
    loop.fix()
    assert attempt.error in last_user(llm_server.chat_requests()[1])


def test_approve_rejecting_a_revision(llm_server, make_client, sorting):
    seen: list[tuple[str, str]] = []
    answers = iter([False, True])

    def approve(program: str, diff: str) -> bool:
        seen.append((program, diff))
        return next(answers)

    llm_server.reply(fenced(NAIVE), fenced(CAREFUL), fenced(CAREFUL))
    loop = Loop(make_client(), sorting, repairs=False, critics=SPEED_CRITICS, approve=approve)
    first = loop.request(TASK)
    assert seen == []  # the first program is not a revision
    rejected = loop.fix()
    assert rejected.approved is False and rejected.execution is None and rejected.report is None
    assert rejected.program == CAREFUL and "+lib.set_speed(0.3)" in rejected.diff
    assert seen == [(CAREFUL, rejected.diff)]
    assert loop.current is first  # the previous attempt stays current
    accepted = loop.fix()
    sent = last_user(llm_server.chat_requests()[2])
    assert "did not accept" in sent and first.report.verdict("end_effector_pose").message in sent
    assert accepted.approved is True and accepted.report is not None and loop.current is accepted
    assert len(seen) == 2 and accepted.diff == seen[1][1]
    assert Loop.best(loop.attempts) is accepted


def test_approve_raising_leaves_the_conversation_unchanged(llm_server, make_client, sorting):
    def approve(program: str, diff: str) -> bool:
        raise KeyboardInterrupt

    llm_server.reply(SHORT, "```python\nmove_up(0.05)\nhome()\n```")
    loop = Loop(make_client(), sorting, approve=approve)
    first = loop.request(TASK)
    with pytest.raises(KeyboardInterrupt):
        loop.refine("lift first")
    assert loop.attempts == [first] and loop.current is first and len(loop.history) == 2


# --- memory ------------------------------------------------------------------------------------


def test_memory_is_persisted_and_retrieved_by_a_new_loop(llm_server, make_client, sorting, tmp_path):
    path = tmp_path / "memory.sqlite"
    llm_server.reply(fenced(CAREFUL))
    with Loop(make_client(), sorting, memory=path, critics=SPEED_CRITICS) as loop:
        stored = loop.request(TASK)
    assert stored.memory_id is not None
    with InteractionMemory(path) as memory:
        [row] = memory.history(loop.session)
        assert (row.request, row.program, row.score) == (TASK, CAREFUL, stored.score)
        assert row.feedback == stored.report.feedback()

    # A new loop (new session, new memory object, BM25 retrieval) sees it in its system prompt.
    llm_server.reply(SHORT)
    with InteractionMemory(path) as memory:
        loop2 = Loop(make_client(), sorting, memory=memory, critics=SPEED_CRITICS)
        assert loop2.session != loop.session
        loop2.request("sort the apples: the red apples go to the brown box")
        assert [e.id for e in loop2.examples] == [row.id]
    system = llm_server.chat_requests()[-1].messages[0]
    assert system["role"] == "system"
    assert "# Relevant past interactions" in system["content"]
    assert f"Request: {TASK}" in system["content"]
    assert "lib.move_linear(obj.x, obj.y, obj.z)" in system["content"]  # the retrieved program


def test_memory_keeps_embeddings_of_different_models_apart(llm_server, make_client, sorting, tmp_path):
    path = tmp_path / "memory.sqlite"
    client_a = make_client(embedding_model="embed-a")
    llm_server.reply(SHORT)
    with InteractionMemory(path, embedder=client_a) as memory:
        Loop(client_a, sorting, memory=memory).request(TASK)
        assert memory.embed_missing() == 1

    # Switch chat and embedding model (and the vector length): nothing of model a is compared.
    llm_server.embedding_dim = 16
    before = len(llm_server.embedding_requests())
    client_b = make_client(model="other-chat", embedding_model="embed-b")
    llm_server.reply(SHORT)
    with InteractionMemory(path, embedder=client_b) as memory:
        loop = Loop(client_b, sorting, memory=memory)
        loop.request("sort the apples by ripeness")
        assert [e.request for e in loop.examples] == [TASK]
    embedding_calls = llm_server.embedding_requests()[before:]
    assert embedding_calls and {r.json["model"] for r in embedding_calls} == {"embed-b"}
    assert any(TASK in r.text for r in embedding_calls)  # the stored request re-embedded with model b
    assert llm_server.chat_requests()[-1].json["model"] == "other-chat"
    with sqlite3.connect(path) as db:
        rows = dict(db.execute("SELECT model, dim FROM embeddings WHERE interaction_id = 1").fetchall())
    assert rows == {"embed-a": 64, "embed-b": 16}


# --- transport --------------------------------------------------------------------------------


def test_retries_pass_through_the_loop(llm_server, make_client, sorting):
    llm_server.script(Fail(429, retry_after=0), Fail(500), Reply(SHORT))
    loop = Loop(make_client(), sorting)
    attempt = loop.request(TASK)
    assert attempt.report is not None and len(loop.attempts) == 1
    requests = llm_server.chat_requests()
    assert len(requests) == 3 and requests[0].body == requests[1].body == requests[2].body


def test_llm_error_propagates_and_leaves_the_loop_as_it_was(llm_server, make_client, sorting):
    llm_server.script(Fail(401))
    loop = Loop(make_client(), sorting)
    with pytest.raises(LLMError, match="API key"):
        loop.request(TASK)
    assert loop.attempts == [] and loop.history == [] and loop.task is None
    llm_server.reply("Hello?")
    attempt = loop.request(TASK)  # simply repeat the call
    assert attempt.index == 1 and len(loop.history) == 2


# --- conversation ----------------------------------------------------------------------------


def test_history_is_trimmed_but_keeps_the_task(llm_server, make_client, sorting):
    llm_server.reply(*[f"no code, take {i}" for i in range(5)])
    loop = Loop(make_client(), sorting, max_history_messages=4, session="trim")
    loop.request(TASK)
    for _ in range(4):
        loop.fix()
    assert len(loop.history) == 10  # everything is kept locally
    sent = [r.messages for r in llm_server.chat_requests()]
    assert [len(m) for m in sent] == [2, 4, 4, 4, 4]  # system + at most 4 others
    for messages in sent:
        assert messages[0]["role"] == "system"
        assert [m["role"] for m in messages[1:]] == ["user", "assistant", "user"][: len(messages) - 1]
    assert f"Task: {TASK}" in sent[1][1]["content"]  # still in the window
    assert sent[2][1]["content"].startswith(f"(Earlier messages were left out.) The task: {TASK}")
    assert sent[4][2]["content"] == "no code, take 3"


def test_review_turn_and_embedded_rules(llm_server, make_client, sorting):
    llm_server.reply(SHORT, "PROGRAM COMPLETE")
    loop = Loop(make_client(), sorting, critics=MOTION_CRITICS, embedded_rules=True)
    with pytest.raises(NothingToFixError):
        loop.review()
    best = loop.run(TASK, feedback="review")
    assert len(loop.last_run) == 2 and best.complete
    first, second = llm_server.chat_requests()
    assert REVIEW_INSTRUCTION in first.messages[0]["content"]  # the rules are in the system prompt
    assert last_user(second) == REVIEW_INSTRUCTION  # no trace feedback in this condition
    trace_feedback = loop.attempts[0].report.feedback()
    assert trace_feedback and trace_feedback not in second.text  # the first program was criticised, silently


def test_constructor_checks(make_client, sorting):
    client = make_client()
    with pytest.raises(CriticError, match="did you mean"):
        Loop(client, sorting, critics=["joint_sped"])
    with pytest.raises(ValueError, match="automation"):
        Loop(client, sorting, automation="yolo")
    with pytest.raises(ValueError, match="max_history_messages"):
        Loop(client, sorting, max_history_messages=1)
    with pytest.raises(TypeError, match="ChatModel"):
        Loop(object(), sorting)
    loop = Loop(client, sorting, critics="joint_speed, collision")
    assert loop.critics == ["joint_speed", "collision"]
    assert "Loop(model='test-chat'" in repr(loop)


# --- the ablation harness (benchmarks/ablation.py) ----------------------------------------------


def test_ablation_selftest_runs_offline(capsys):
    import importlib.util

    path = Path(__file__).resolve().parent.parent / "benchmarks" / "ablation.py"
    spec = importlib.util.spec_from_file_location("robocritics_ablation", path)
    ablation = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = ablation  # its dataclasses look their module up
    try:
        spec.loader.exec_module(ablation)
        assert ablation.main(["--selftest", "--tasks", "sorting"]) == 0
    finally:
        del sys.modules[spec.name]
    out = capsys.readouterr().out
    rows = {tuple(line.split()[:2]): line.split() for line in out.splitlines() if line.startswith(("sorting", "average"))}
    embedded, external = rows[("sorting", "embedded")], rows[("sorting", "external")]
    assert embedded[2] == "2.0" and embedded[-1] == "complete"  # naive program, then "PROGRAM COMPLETE"
    assert float(external[3]) > float(embedded[3])  # critic feedback led to the careful program
    assert ["paper", "embedded", "2.3", "6.3"] in [line.split() for line in out.splitlines()]
    assert "Reproduce: python benchmarks/ablation.py --selftest --tasks sorting" in out


# --- a simulate hook (the studio checks programs in a worker process) ---------------------------


def test_simulate_hook_checks_every_program_and_its_errors_are_fed_back(llm_server, make_client, sorting):
    from robocritics.critic import critique
    from robocritics.pipeline import simulate

    unreachable = "move_above(green_apple)\nmove_to(0.95, 0.0, 0.2)\nhome()\n"
    llm_server.reply(SHORT, fenced(unreachable))
    checked: list[str] = []

    def check_elsewhere(program):
        checked.append(program)
        execution = simulate(program, sorting)
        return execution, critique(execution.trajectory, sorting, MOTION_CRITICS)

    loop = Loop(make_client(), sorting, critics=MOTION_CRITICS, simulate=check_elsewhere)
    first = loop.request(TASK)
    assert first.report is not None and first.execution is not None and first.score == first.report.score
    second = loop.refine("reach further")
    assert checked == [first.program, unreachable]
    assert second.report is None and second.score is None
    assert "line 2" in second.error and ">> 2 | move_to(0.95, 0.0, 0.2)" in second.error
    with pytest.raises(TypeError, match="simulate"):
        Loop(make_client(), sorting, simulate="not callable")


def test_the_loop_takes_its_options_grouped_or_one_by_one(make_client, sorting):
    from robocritics.llm.options import LoopOptions

    grouped = Loop(make_client(), sorting, critics=["joint_speed"], options=LoopOptions(max_attempts=2, memory_k=0))
    by_keyword = Loop(make_client(), sorting, critics=["joint_speed"], max_attempts=2, memory_k=0)
    assert grouped.options == by_keyword.options and grouped.max_attempts == by_keyword.max_attempts == 2
    # keywords override the grouped options; a misspelt one names the options
    assert Loop(make_client(), sorting, options=LoopOptions(max_attempts=2), max_attempts=4).max_attempts == 4
    with pytest.raises(TypeError, match="max_attempt .*options: automation"):
        Loop(make_client(), sorting, max_attempt=3)
    with pytest.raises(ValueError, match="max_attempts must be at least 1"):
        LoopOptions(max_attempts=0)
