"""Bounded, streamed generation against the loopback server speaking real servers' protocol.

Streaming (server-sent events), ``max_tokens`` and ``finish_reason: "length"``, the inactivity timeout and the
total deadline of a stream, hanging up (the server sees it), the fallback for servers that do not stream,
context-window errors and the server's context size, and embedding servers that cannot embed.
"""



from __future__ import annotations

import json
import time

import numpy as np
import pytest
from llm_fixtures import clean_llm_env, llm_server, make_client
from llm_server import Delay, Reply, Stream, hashed_embedding, tokens

from robocritics.errors import LLMError
from robocritics.llm.protocol import ChatProgress, ContextLengthError, EmbeddingsUnavailableError, GenerationTimeoutError
from robocritics.llm.limits import DEFAULT_MAX_TOKENS

pytestmark = pytest.mark.usefixtures("clean_llm_env")

USER = [{"role": "user", "content": "write a program"}]
# Seconds a real-time assertion may overrun on a loaded 2-core machine.
SLACK_S = 2.0
LONG = " ".join(f"word{i}" for i in range(2000))


def sse(*events: object, sep: bytes = b"\n\n") -> bytes:
    out = b""
    for e in events:
        data = e if isinstance(e, bytes) else json.dumps(e).encode()
        out += b"data: " + data + sep
    return out


def delta(text: str | None = None, finish: str | None = None) -> dict:
    d = {} if text is None else {"content": text}
    return {"object": "chat.completion.chunk", "choices": [{"index": 0, "delta": d, "finish_reason": finish}]}


def events(body: bytes, piece: int = 1) -> Stream:
    return Stream(lambda: (body[i : i + piece] for i in range(0, len(body), piece)), content_type="text/event-stream")


# --- streaming -------------------------------------------------------------------------------------


def test_replies_are_streamed_with_a_token_cap_and_progress(llm_server, make_client):
    seen: list[ChatProgress] = []
    llm_server.reply("move_to(1, 2, 3)\nhome()\n")
    reply = make_client(on_progress=seen.append).chat(USER)
    assert reply.content == "move_to(1, 2, 3)\nhome()\n"
    assert reply.streamed and reply.finish_reason == "stop" and not reply.truncated
    sent = llm_server.chat_requests()[0].json
    assert sent["stream"] is True and sent["max_tokens"] == DEFAULT_MAX_TOKENS
    assert [p.phase for p in seen] == ["waiting"] + ["receiving"] * len(tokens(reply.content)) + ["done"]
    assert [p.tokens for p in seen if p.phase == "receiving"] == list(range(1, len(tokens(reply.content)) + 1))
    assert seen[-1].tokens == len(tokens(reply.content)) and seen[-1].chars == len(reply.content)


def test_progress_carries_the_reply_text_as_it_arrives(llm_server, make_client):
    pieces = ["move_to(0.3, ", "0.0, 0.2)\n", "", "home()", "\n"]
    body = sse(*(delta(p) for p in pieces), delta(finish="stop"), b"[DONE]")
    llm_server.script(events(body, piece=7))  # events split across reads, as a real server's are
    texts: list[str] = []
    seen: list[ChatProgress] = []

    def show(progress: ChatProgress) -> None:
        texts.append(progress.text)  # read while the reply arrives, as a UI does
        seen.append(progress)

    reply = make_client(on_progress=show).chat(USER)
    assert reply.content == "".join(pieces)
    received = [text for text, p in zip(texts, seen) if p.phase == "receiving"]
    assert received == ["move_to(0.3, ", "move_to(0.3, 0.0, 0.2)\n", "move_to(0.3, 0.0, 0.2)\nhome()", reply.content]
    assert texts[0] == "" and texts[-1] == reply.content and seen[-1].phase == "done"
    # each progress keeps the text of its moment (read after the whole reply arrived)
    assert [p.text for p in seen] == texts and all(len(p.text) == p.chars for p in seen)


@pytest.mark.parametrize("stream", [True, False])
def test_a_reply_cut_at_max_tokens_says_so(llm_server, make_client, stream):
    llm_server.reply(LONG)
    reply = make_client(max_tokens=40, stream=stream).chat(USER)
    assert reply.truncated and reply.finish_reason == "length"
    assert reply.completion_tokens == 40 and reply.max_tokens == 40
    assert reply.content == "".join(tokens(LONG)[:40])
    assert llm_server.chat_requests()[0].json["max_tokens"] == 40


def test_max_tokens_none_sends_no_cap_and_a_call_may_override(llm_server, make_client):
    client = make_client(max_tokens=None)
    client.chat(USER)
    client.chat(USER, max_tokens=7)
    first, second = (r.json for r in llm_server.chat_requests())
    assert "max_tokens" not in first and second["max_tokens"] == 7


def test_a_server_that_ignores_stream_is_read_as_json(llm_server, make_client):
    llm_server.stream_mode = "ignore"
    reply = make_client().chat(USER)
    assert reply.content == "write a program" and not reply.streamed


def test_a_server_that_refuses_stream_is_asked_again_without_it_from_then_on(llm_server, make_client):
    llm_server.stream_mode = "refuse"
    client = make_client()
    assert client.complete(USER) == "write a program"
    assert client.complete(USER) == "write a program"
    sent = [r.json.get("stream") for r in llm_server.chat_requests()]
    assert sent == [True, None, None] and client.stream is False


def test_events_split_anywhere_with_crlf_comments_and_no_space_are_read(llm_server, make_client):
    body = (
        b": keep-alive\r\n\r\n"
        + sse(delta("move_"), delta("to(1, 2, 3)"), sep=b"\r\n\r\n").replace(b"data: ", b"data:")
        + b": ping\n\n"
        + sse(delta("\nhome()"), delta(None, "stop"), b"[DONE]")
    )
    llm_server.script(events(body, piece=1))  # one byte per chunk
    assert make_client().complete(USER) == "move_to(1, 2, 3)\nhome()"


def test_reading_stops_at_done(llm_server, make_client):
    body = sse(delta("ok"), delta(None, "stop"), b"[DONE]") + b"data: {not json\n\n"
    llm_server.script(events(body, piece=7))
    assert make_client().complete(USER) == "ok"


def test_an_error_event_in_the_stream_raises_with_the_servers_words(llm_server, make_client):
    body = sse(delta("half a pro"), {"error": {"message": "slot 0 crashed", "type": "server_error"}})
    llm_server.script(events(body))
    with pytest.raises(LLMError, match="slot 0 crashed"):
        make_client().complete(USER)


def test_a_stream_that_ends_in_the_middle_is_an_error_not_a_short_program(llm_server, make_client):
    llm_server.script(events(sse(delta("move_to(1, "))))
    with pytest.raises(LLMError, match="ended after 1 tokens without a finish reason"):
        make_client().complete(USER)


# --- time: inactivity, the total deadline, hanging up -------------------------------------------------


def test_a_silent_stream_ends_at_the_inactivity_timeout_and_is_not_retried(llm_server, make_client):
    llm_server.token_interval_s = 60.0  # headers and the first event arrive, then nothing
    llm_server.reply("never finished")
    client = make_client(idle_timeout_s=0.3, timeout_s=30.0, deadline_s=60.0)
    started = time.monotonic()
    with pytest.raises(GenerationTimeoutError, match="sent nothing for 0.3 s while generating"):
        client.complete(USER)
    assert 0.3 <= time.monotonic() - started < 0.3 + SLACK_S
    assert len(llm_server.chat_requests()) == 1  # not retried: the server is not asked to generate twice
    assert make_client.sleeps == []


def test_tokens_that_keep_coming_end_at_the_total_deadline_and_the_server_sees_the_hang_up(llm_server, make_client):
    llm_server.token_interval_s = 0.05  # 20 tokens/s, for ever: the inactivity timeout never trips
    llm_server.reply(LONG)
    client = make_client(max_tokens=None, idle_timeout_s=5.0, timeout_s=5.0, deadline_s=1.0)
    started = time.monotonic()
    with pytest.raises(LLMError, match="deadline of 1 s"):
        client.complete(USER)
    assert 1.0 <= time.monotonic() - started < 1.0 + SLACK_S
    assert llm_server.cancelled.wait(SLACK_S)  # the connection was closed: the server stopped generating
    sent = llm_server.tokens_sent
    time.sleep(0.3)
    assert llm_server.tokens_sent == sent < len(tokens(LONG))
    assert len(llm_server.chat_requests()) == 1


def test_an_exception_in_the_progress_callback_closes_the_connection(llm_server, make_client):
    llm_server.token_interval_s = 0.02
    llm_server.reply(LONG)

    def interrupt(progress: ChatProgress) -> None:
        if progress.tokens >= 3:
            raise KeyboardInterrupt  # Ctrl-C while tokens arrive

    with pytest.raises(KeyboardInterrupt):
        make_client(max_tokens=None, on_progress=interrupt).complete(USER)
    assert llm_server.cancelled.wait(SLACK_S)
    assert llm_server.tokens_sent < 100


def test_a_non_streamed_chat_that_times_out_is_not_retried(llm_server, make_client):
    llm_server.script(Delay(60.0), Reply("late"))
    with pytest.raises(GenerationTimeoutError):
        make_client(stream=False, timeout_s=0.3).complete(USER)
    assert len(llm_server.chat_requests()) == 1


# --- the context window ------------------------------------------------------------------------------


@pytest.mark.parametrize("style", ["llama-cpp-python", "llama.cpp"])
def test_a_prompt_over_the_context_is_a_final_error_naming_the_context(llm_server, make_client, style):
    llm_server.context_tokens = 50
    llm_server.context_style = style
    big = [{"role": "user", "content": "word " * 60}]
    with pytest.raises(ContextLengthError) as caught:
        make_client(max_tokens=10).complete(big)
    assert caught.value.context_tokens == 50
    prompt = 60 + 4  # 60 words and 4 tokens of message overhead, as the server counts
    assert caught.value.requested_tokens == (prompt + 10 if style == "llama-cpp-python" else prompt)
    assert "context of 50 tokens" in str(caught.value)
    assert len(llm_server.chat_requests()) == 1  # not retried


def test_the_context_comes_from_llama_cpp_props(llm_server, make_client):
    llm_server.context_tokens = 2048
    assert make_client().server_context_tokens() is None  # no /props: the server does not say
    llm_server.props = True
    assert make_client().server_context_tokens() == 2048


# --- embeddings ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("mode, status", [("no-embedding", 500), ("not-implemented", 501)])
def test_a_server_that_cannot_embed_fails_at_once(llm_server, make_client, mode, status):
    llm_server.embedding_mode = mode
    with pytest.raises(EmbeddingsUnavailableError, match=f"HTTP {status}.*not retried"):
        make_client().embed(["sort the apples"])
    assert len(llm_server.embedding_requests()) == 1
    assert make_client.sleeps == []


def test_a_plain_500_from_the_embedding_server_is_still_retried(llm_server, make_client):
    from llm_server import Fail

    llm_server.script(Fail(500))
    assert make_client().embed(["sort the apples"]).shape == (1, llm_server.embedding_dim)
    assert len(llm_server.embedding_requests()) == 2


def test_per_token_vectors_are_mean_pooled(llm_server, make_client, caplog):
    llm_server.embedding_mode = "per-token"
    text = "sort the apples"
    vectors = make_client().embed([text, "plate"])
    expected = np.mean([hashed_embedding(w, llm_server.embedding_dim, "test-embed") for w in text.split()], axis=0)
    assert vectors.shape == (2, llm_server.embedding_dim)
    np.testing.assert_allclose(vectors[0], expected)
    assert sum("mean-pooled" in r.getMessage() for r in caplog.records) == 1


def test_vllms_context_error_is_read_too(llm_server, make_client):
    from llm_server import Fail

    message = (
        "This model's maximum context length is 2048 tokens. However, you requested 2764 tokens "
        "(1740 in the messages, 1024 in the completion). Please reduce the length of the messages or completion."
    )
    llm_server.script(Fail(400, body=json.dumps({"object": "error", "message": message, "type": "BadRequestError"})))
    with pytest.raises(ContextLengthError) as caught:
        make_client().complete(USER)
    assert (caught.value.context_tokens, caught.value.requested_tokens) == (2048, 2764)


def test_a_last_event_without_its_blank_line_is_read(llm_server, make_client):
    llm_server.script(events(sse(delta("home()")) + b"data: " + json.dumps(delta(None, "stop")).encode()))
    assert make_client().complete(USER) == "home()"
