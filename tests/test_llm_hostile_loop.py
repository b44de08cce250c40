"""Hostile replies past the client: extraction is linear and only raises LLMError; prompts stay bounded (issue 10, item 3).

``extract_code`` reads up to ``MAX_REPLY_CHARS`` of whatever a model sends: prose
by the megabyte, code nested deeper than Python's parser allows, fences by the
thousand. It must stay linear (checked on process CPU time, with a tolerance far
above the measured worst case and far below the minutes the old search took)
and never raise anything but ``LLMError``. The loop must never re-send or store
more than its limits, whatever the model or the user sends.
"""

# ruff: noqa: F811  (pytest fixtures imported from llm_fixtures are parameters here)

from __future__ import annotations

import json
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from llm_fixtures import clean_llm_env, llm_server, make_client  # noqa: F401
from llm_server import Reply

from robocritics.errors import LLMError, ProgramError
from robocritics.llm.limits import MAX_FEEDBACK_CHARS, MAX_MESSAGE_CHARS, MAX_REPLY_CHARS, MAX_TASK_CHARS
from robocritics.llm.loop import Loop
from robocritics.llm.memory import InteractionMemory
from robocritics.llm.prompts import PromptError, extract_code, numbered_program, request_prompt, runtime_feedback
from robocritics.scene import Scene

pytestmark = pytest.mark.usefixtures("clean_llm_env")

# CPU seconds extraction may take for one reply at the size limit (measured worst case ~1.2 s; the old
# span search took minutes on these inputs).
EXTRACT_CPU_S = 5.0

PROSE = "The robot should move carefully around the table and the boxes.\n"
CODE = "".join(f"lib.move_to(apple.x + {i * 0.001:.3f}, apple.y, 0.1)\nif i > 3:\n    lib.close_gripper()\n" for i in range(1300))
DENSE = "f()\n" * 29_500


def cpu_seconds(call) -> tuple[object, float]:
    started = time.process_time()
    result = call()
    return result, time.process_time() - started


@pytest.fixture(scope="module")
def sorting() -> Scene:
    return Scene.builtin("sorting")


# -- extraction: bounded, linear, never anything but LLMError ---------------------------------------


def test_a_5_mb_prose_reply_is_refused_at_once():
    with pytest.raises(LLMError, match=r"reply is 5,120,000 characters long; the limit is"):
        extract_code(PROSE * 80_000)


@pytest.mark.parametrize(
    ("reply", "expected"),
    [
        pytest.param((PROSE * 2000)[: MAX_REPLY_CHARS - 1], None, id="prose-at-the-limit"),
        pytest.param(("x = 1\n" * 30_000)[: MAX_REPLY_CHARS - 1], None, id="code-that-calls-nothing"),
        pytest.param(
            "".join(f"Line {i} of prose.\n" for i in range(20)) + CODE + "".join(f"Prose {i}, it's done.\n" for i in range(20)),
            CODE,
            id="20-prose-lines-at-both-ends",
        ),
        pytest.param(DENSE + "".join(f"if x{i}:\n" for i in range(20)), DENSE, id="dense-code-then-20-open-blocks"),
        pytest.param(DENSE + "".join(f"and then {i} more\n" for i in range(20)), DENSE, id="dense-code-then-20-prose-lines"),
        pytest.param("".join(f"foo({i},\n" for i in range(20)) + DENSE, DENSE, id="20-open-brackets-then-dense-code"),
    ],
)
def test_unfenced_replies_at_the_size_limit_take_linear_time(reply, expected):
    assert len(reply) < MAX_REPLY_CHARS
    code, seconds = cpu_seconds(lambda: extract_code(reply))
    assert code == expected
    assert seconds < EXTRACT_CPU_S


@pytest.mark.parametrize(
    "reply",
    [
        pytest.param("```\nx = " + "-" * 100_000 + "1\n```", id="unary-chain-in-an-untagged-block"),
        pytest.param("x = " + "-" * 100_000 + "1\nfoo()", id="unary-chain-bare"),
        pytest.param("foo(" + "+".join(["1"] * 50_000) + ")", id="binary-chain-bare"),
        pytest.param("foo" + "()" * 50_000, id="call-chain-bare"),
        pytest.param("a" + ".b" * 50_000 + "()", id="attribute-chain-bare"),
        pytest.param("not " * 25_000 + "f()", id="not-chain-bare"),
        pytest.param("lambda: " * 12_000 + "f()", id="lambda-chain-bare"),
        pytest.param("f(" * 10_000 + ")" * 10_000, id="nested-calls-bare"),
        pytest.param("```\n" + "[" * 50_000 + "]" * 50_000 + "\n```", id="nested-lists-untagged"),
        pytest.param("```\n```\n" * 10_000, id="ten-thousand-empty-fences"),
        pytest.param("```\nfoo(\n```\n" * 9_000, id="nine-thousand-broken-blocks"),
        pytest.param("\t" * 100_000 + "f()", id="deep-indentation"),
        pytest.param("f()\x00\n" * 1_000, id="null-bytes"),
    ],
)
def test_code_too_deep_for_the_parser_never_raises(reply):
    assert len(reply) <= MAX_REPLY_CHARS
    code, seconds = cpu_seconds(lambda: extract_code(reply))  # no MemoryError, RecursionError or ValueError
    assert code is None or (isinstance(code, str) and code.endswith("\n"))
    assert seconds < EXTRACT_CPU_S


HOSTILE = st.text(alphabet="([{-+*~ not lambda:if\n\t`'\"\\f().x=1,", max_size=2_000)


@settings(max_examples=300, deadline=None)
@given(HOSTILE)
def test_hostile_text_only_ever_gives_none_or_tidy_code(text):
    code = extract_code(text)
    assert code is None or (code.endswith("\n") and code.strip() and not code.startswith("\n"))


def test_extracted_code_has_no_lone_surrogates():
    code = extract_code("```python\nlib.say('\ud800')\n```")
    assert code == "lib.say('\ufffd')\n"
    code.encode("utf-8")


# -- prompts: what is sent back is bounded ------------------------------------------------------------


def test_a_huge_error_message_is_cut_in_the_runtime_feedback():
    error = ProgramError("KeyError: " + "k" * 10_000_000, line=3)
    feedback = runtime_feedback(error, program="a = 1\nb = 2\nc = {}['" + "k" * 500_000 + "']\n")
    assert len(feedback) <= MAX_FEEDBACK_CHARS
    assert "line 3" in feedback and "KeyError: kkk" in feedback and "not shown" in feedback


def test_a_very_long_program_line_is_cut_in_a_listing():
    listing = numbered_program("x = 1\ny = '" + "z" * 100_000 + "'\n", [2])
    assert len(listing) < 1_000 and ">> 2 | y = 'zzz" in listing and "characters of this line not shown" in listing


@pytest.mark.parametrize(
    ("task", "message"),
    [("", "empty"), ("   \n", "empty"), ("t" * (MAX_TASK_CHARS + 1), f"is {MAX_TASK_CHARS + 1:,} characters long")],
)
def test_unusable_tasks_are_prompt_errors(task, message):
    with pytest.raises(PromptError, match=message):
        request_prompt(task)
    assert issubclass(PromptError, ValueError)


# -- the loop: nothing re-sent or stored beyond its limits --------------------------------------------


def test_a_long_reply_is_not_re_sent_in_full(llm_server, make_client, sorting, tmp_path):
    rejected = "x = 1\n" * 10_000 + "import os\n"  # 60 kB; the sandbox stops it at the import
    llm_server.reply(f"```python\n{rejected}```", "```python\nmove_above(green_apple)\nhome()\n```")
    with Loop(make_client(max_tokens=None), sorting, critics=["joint_speed"], memory=tmp_path / "m.sqlite") as loop:
        first = loop.request("put the green apple in the white box")
        assert first.error is not None and first.report is None
        loop.fix()
        stored = loop.memory.history(loop.session)
    second = llm_server.chat_requests()[1]
    for message in second.messages[1:]:  # everything after the system prompt
        assert len(message["content"]) <= MAX_MESSAGE_CHARS
    assert len(second.body) < 100_000  # the 60 kB reply went out once, not twice
    assert "more characters not shown" in second.messages[2]["content"]  # the assistant turn, cut and saying so
    assert len(stored[0].program) == len(rejected)  # within the memory's program limit, so stored whole


def test_a_reply_over_the_limit_from_any_model_leaves_the_conversation_as_it_was(llm_server, make_client, sorting):
    llm_server.script(Reply("y" * (MAX_REPLY_CHARS + 10)), Reply("```python\nhome()\n```"))
    loop = Loop(make_client(max_reply_chars=10 * MAX_REPLY_CHARS), sorting, critics=["joint_speed"])
    with pytest.raises(LLMError, match="characters long; the limit is"):
        loop.request("go home")
    assert loop.attempts == [] and loop.history == [] and loop.task is None
    assert loop.request("go home").program == "home()\n"  # the call can simply be repeated


def test_an_overlong_task_is_refused_before_any_request(llm_server, make_client, sorting):
    loop = Loop(make_client(), sorting)
    with pytest.raises(PromptError, match="characters long"):
        loop.request("sort " * 10_000)
    assert llm_server.requests == []


def test_a_task_with_undecodable_bytes_is_cleaned_before_sending_and_storing(llm_server, make_client, sorting):
    task = "put the green apple \udcff\udcfe in the white box"  # what Python makes of non-UTF-8 argv bytes
    llm_server.reply("```python\nmove_above(green_apple)\nhome()\n```")
    with InteractionMemory() as memory:
        attempt = Loop(make_client(), sorting, critics=["joint_speed"], memory=memory).request(task)
        assert memory.get(attempt.memory_id).request == "put the green apple \ufffd\ufffd in the white box"
    sent = llm_server.chat_requests()[0]
    assert "apple \ufffd\ufffd in" in json.loads(sent.body.decode("utf-8"))["messages"][-1]["content"]
