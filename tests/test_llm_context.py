"""The loop against real-server behaviour: small contexts, replies cut at the token limit, servers that cannot
embed, and which past interactions come back as examples."""



from __future__ import annotations

from pathlib import Path

import pytest
from llm_fixtures import clean_llm_env, llm_server, make_client
from llm_server import count_tokens

from robocritics.llm.fitting import CONTEXT_MARGIN_TOKENS
from robocritics.llm.loop import Loop
from robocritics.llm.memory import InteractionMemory
from robocritics.llm.prompts import (
    PromptError,
    compact_api_reference,
    estimate_tokens,
    system_prompt,
)
from robocritics.program.skills import SKILLS
from robocritics.scene import Scene

pytestmark = pytest.mark.usefixtures("clean_llm_env")

PROGRAMS = Path(__file__).resolve().parent.parent / "examples" / "programs"
NAIVE = (PROGRAMS / "sorting_naive.py").read_text()
CAREFUL = (PROGRAMS / "sorting_careful.py").read_text()
TASK = "sort the apples by ripeness"


def fenced(program: str) -> str:
    return f"Here it is:\n```python\n{program}```\n"


@pytest.fixture(scope="module")
def sorting() -> Scene:
    return Scene.builtin("sorting")


# --- the estimate and the compact prompts --------------------------------------------------------------


@pytest.mark.parametrize("name", ["recycling", "sorting", "breakfast"])
def test_the_estimate_is_above_the_servers_count_and_the_short_prompts_are_short(name):
    scene = Scene.builtin(name)
    full, compact, minimal = (system_prompt(scene, compact_api=level) for level in (False, "compact", "minimal"))
    for text in (full, compact, minimal):
        assert estimate_tokens(text) >= count_tokens([{"content": text}]) - 4  # never under a word+punctuation count
    assert estimate_tokens(compact) < 0.75 * estimate_tokens(full)
    assert estimate_tokens(minimal) < 0.4 * estimate_tokens(full)
    for text in (compact, minimal):  # the API and the scene always survive
        assert all(f"{skill}(" in text for skill in SKILLS)
        assert "green_apple" in text or name != "sorting"
        assert f"# Scene: {name}" in text


def test_the_compact_reference_keeps_each_skills_first_sentence():
    text = compact_api_reference("compact")
    assert "reduce_speed(percent) - Set the speed of the following moves" in text
    assert "Example:" not in text
    with pytest.raises(ValueError):
        compact_api_reference("tiny")


# --- fitting the prompt -------------------------------------------------------------------------------


def test_a_2048_token_context_gets_a_prompt_that_fits(llm_server, make_client, sorting):
    llm_server.context_tokens = 2048  # llama-cpp-python's default n_ctx: the full prompt is refused
    llm_server.reply(fenced(NAIVE), fenced(CAREFUL))
    loop = Loop(make_client(), sorting, critics=["joint_speed"], context_tokens=2048)
    first = loop.request(TASK)
    second = loop.fix()
    assert first.report is not None and second.report is not None
    for request in llm_server.chat_requests():
        assert count_tokens(request.messages) + request.json["max_tokens"] <= 2048
        assert TASK in request.text  # the task always survives
        assert "move_above(obj, height=0.1)" in request.messages[0]["content"]  # and so does the API
    assert loop.last_prompt_tokens + llm_server.chat_requests()[-1].json["max_tokens"] <= 2048 - CONTEXT_MARGIN_TOKENS


def test_the_context_is_learnt_from_the_servers_error_and_the_turn_sent_again(llm_server, make_client, sorting):
    llm_server.context_tokens = 2048
    llm_server.responder = lambda request: fenced(NAIVE)  # (a scripted reply would go to the refused request)
    loop = Loop(make_client(), sorting, critics=["joint_speed"])  # context unknown
    attempt = loop.request(TASK)
    assert attempt.report is not None and loop.context_tokens == 2048
    statuses = llm_server.chat_requests()
    assert len(statuses) == 2  # refused once (400 "exceed context window of 2048"), then fitted
    assert count_tokens(statuses[1].messages) + statuses[1].json["max_tokens"] <= 2048


def test_a_context_too_small_for_the_task_and_api_is_a_clear_error(llm_server, make_client, sorting):
    loop = Loop(make_client(), sorting, critics=["joint_speed"], context_tokens=600)
    with pytest.raises(PromptError, match="needs a context of at least"):
        loop.request(TASK)
    assert llm_server.chat_requests() == []  # nothing was sent
    with pytest.raises(ValueError, match="at least 512"):
        Loop(make_client(), sorting, context_tokens=100)


def test_memory_examples_go_first_when_the_context_is_small(llm_server, make_client, sorting, tmp_path):
    with InteractionMemory(tmp_path / "m.sqlite") as memory:
        for i in range(3):
            memory.add("old", f"sort the apples by ripeness, take {i}", CAREFUL, "all OK", 10.0)
        llm_server.reply(fenced(NAIVE), fenced(NAIVE))
        roomy = Loop(make_client(), sorting, critics=["joint_speed"], memory=memory, context_tokens=32_000)
        roomy.request(TASK)
        small = Loop(make_client(), sorting, critics=["joint_speed"], memory=memory, context_tokens=4096)
        small.request(TASK)
    big, fitted = (r.messages[0]["content"] for r in llm_server.chat_requests())
    assert big.count("## Past interaction") == 3
    assert fitted.count("## Past interaction") < 3
    assert "## Skills\n" in fitted  # examples were dropped before the skill reference was shortened


def test_a_long_history_is_dropped_but_the_task_restated(llm_server, make_client, sorting):
    llm_server.reply(*[fenced(NAIVE.replace("0.2", f"0.2{i}")) for i in range(6)])
    loop = Loop(make_client(), sorting, critics=["joint_speed"], context_tokens=2048)
    loop.request(TASK)
    for _ in range(4):
        loop.fix()
    last = llm_server.chat_requests()[-1]
    assert count_tokens(last.messages) + last.json["max_tokens"] <= 2048
    assert TASK in last.text


# --- replies cut at the token limit ---------------------------------------------------------------------


def test_a_reply_cut_at_max_tokens_is_fed_back_as_too_long_not_as_a_broken_line(llm_server, make_client, sorting):
    llm_server.reply(fenced(CAREFUL), fenced(NAIVE))
    loop = Loop(make_client(max_tokens=60), sorting, critics=["joint_speed"])
    cut = loop.request(TASK)
    assert cut.report is None and cut.program is None
    assert "cut at 60 tokens" in cut.error and "shorter program" in cut.error
    assert "line" not in cut.error.split("Send")[0]  # no syntax error blamed on its last line
    loop.fix()
    assert "Your reply was cut at 60 tokens" in llm_server.chat_requests()[1].messages[-1]["content"]


def test_a_reply_cut_after_its_closed_code_block_is_run(llm_server, make_client, sorting):
    from llm_server import tokens

    reply = fenced(NAIVE) + "This program moves each apple in turn, " + "and it is careful " * 50
    llm_server.reply(reply)
    cap = len(tokens(fenced(NAIVE))) + 5
    attempt = Loop(make_client(max_tokens=cap), sorting, critics=["joint_speed"]).request(TASK)
    assert attempt.report is not None  # the program was complete: only the prose after it was cut


# --- memory: servers that cannot embed, programs that never ran -------------------------------------------


@pytest.mark.parametrize("mode", ["no-embedding", "not-implemented"])
def test_a_server_without_embeddings_does_not_stop_the_run(llm_server, make_client, sorting, tmp_path, caplog, mode):
    llm_server.embedding_mode = mode
    with InteractionMemory(tmp_path / "m.sqlite") as memory:
        memory.add("old", "sort the apples by ripeness quickly", CAREFUL, "all OK", 10.0)
        memory.embedder = make_client()
        llm_server.reply(fenced(NAIVE), fenced(NAIVE))
        loop = Loop(make_client(), sorting, critics=["joint_speed"], memory=memory)
        attempt = loop.request(TASK)
        Loop(make_client(), sorting, critics=["joint_speed"], memory=memory).request(TASK)
    assert attempt.report is not None
    assert "Past interaction 1" in llm_server.chat_requests()[0].messages[0]["content"]  # BM25 found it
    assert len(llm_server.embedding_requests()) == 1  # not retried, and not tried again
    warnings = [r for r in caplog.records if "keywords (BM25)" in r.getMessage()]
    assert len(warnings) == 1 and loop.keyword_memory_reason


def test_programs_that_never_ran_are_not_shown_as_past_interactions(llm_server, make_client, sorting, tmp_path):
    with InteractionMemory(tmp_path / "m.sqlite") as memory:
        memory.add("old", "sort the apples by ripeness", "import os\n", "did not run: imports", None)
        memory.add("old", "sort the apples by ripeness now", CAREFUL, "all OK", 10.0)
        llm_server.reply(fenced(NAIVE))
        loop = Loop(make_client(), sorting, critics=["joint_speed"], memory=memory)
        loop.request(TASK)
    system = llm_server.chat_requests()[0].messages[0]["content"]
    assert "import os" not in system and "## Past interaction 1" in system and "## Past interaction 2" not in system
