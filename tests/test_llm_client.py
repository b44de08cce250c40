"""OpenAICompatible against a real HTTP server on 127.0.0.1 (tests/llm_server.py).

Retry pauses are recorded, not slept (``make_client.sleeps``), so their timing is asserted exactly;
only the network timeouts are real, against a server that stalls far longer than the timeout.
"""

# ruff: noqa: F811  (pytest fixtures imported from llm_fixtures are parameters here)

from __future__ import annotations

import email.utils
import logging
import pickle
import socket
import time
import traceback

import httpx
import numpy as np
import pytest
from llm_fixtures import TEST_EMBEDDING_MODEL, TEST_MODEL, clean_llm_env, llm_server, make_client  # noqa: F401
from llm_server import Delay, Drop, Fail, Garbage, LLMServer, RawJSON, Reply, hashed_embedding

from robocritics.errors import LLMError, RoboCriticsError
from robocritics.llm.protocol import ChatModel, ChatReply, EmbeddingModel, embedding_space_name
from robocritics.llm.providers.openai_compatible import OpenAICompatible
from robocritics.llm.providers.wire import _redact_secret, _retry_after_seconds

pytestmark = pytest.mark.usefixtures("clean_llm_env")

USER = [{"role": "user", "content": "put the green apple in the white box"}]

# A server stall no client timeout in these tests comes near (it ends when the server stops).
STALL_S = 60.0


def chained_text(exc: BaseException) -> str:
    """Everything a traceback of ``exc`` (with its causes) would print."""
    return "".join(traceback.format_exception(exc))


# -- happy path ---------------------------------------------------------------


def test_complete_returns_the_reply_and_sends_an_openai_request(llm_server, make_client):
    llm_server.reply("lib.open_gripper()")
    client = make_client()
    assert client.complete(USER) == "lib.open_gripper()"

    (request,) = llm_server.requests
    assert request.path == "/v1/chat/completions"
    assert request.json["model"] == TEST_MODEL
    assert request.json["messages"] == USER
    assert request.json["temperature"] == 0.0
    assert request.headers["authorization"] == "Bearer sk-test-not-a-secret"
    assert request.headers["content-type"] == "application/json"


def test_chat_reports_usage_finish_reason_and_attempts(llm_server, make_client):
    llm_server.script(Reply("half a progr", finish_reason="length"))
    reply = make_client().chat(USER)
    assert isinstance(reply, ChatReply)
    assert reply.content == "half a progr"
    assert reply.finish_reason == "length"
    assert reply.model == TEST_MODEL
    assert reply.attempts == 1
    assert reply.usage["total_tokens"] == reply.usage["prompt_tokens"] + reply.usage["completion_tokens"]


def test_keyword_options_reach_the_request_body(llm_server, make_client):
    client = make_client(temperature=0.3)
    client.complete(USER, max_tokens=123, seed=7)
    client.complete(USER, temperature=1.0)
    first, second = llm_server.requests
    assert first.json["temperature"] == 0.3
    assert first.json["max_tokens"] == 123 and first.json["seed"] == 7
    assert second.json["temperature"] == 1.0


def test_a_responder_sees_the_request_and_the_feedback_reaches_the_model(llm_server, make_client):
    llm_server.responder = lambda request: f"saw {len(request['messages'])} messages"
    feedback = "Warning: Joint speed is higher than the recommended value of 1 m/s."
    messages = USER + [
        {"role": "assistant", "content": "move_to(0.3, 0.1, 0.2)"},
        {"role": "user", "content": feedback},
    ]
    assert make_client().complete(messages) == "saw 3 messages"
    assert feedback in llm_server.requests[-1].text


def test_default_responder_echoes_the_last_user_message(llm_server, make_client):
    assert make_client().complete(USER) == USER[0]["content"]


def test_content_given_as_parts_is_joined(llm_server, make_client):
    parts = [{"type": "text", "text": "move_to("}, {"type": "text", "text": "0, 0, 0)"}]
    llm_server.script(RawJSON({"choices": [{"message": {"role": "assistant", "content": parts}}]}))
    assert make_client().complete(USER) == "move_to(0, 0, 0)"


def test_client_satisfies_both_protocols():
    client = OpenAICompatible(base_url="http://127.0.0.1:9/v1", model="m", embedding_model="e")
    try:
        assert isinstance(client, ChatModel)
        assert isinstance(client, EmbeddingModel)
        assert client.name == "m"
        assert embedding_space_name(client) == "e"
    finally:
        client.close()


def test_client_is_usable_from_several_threads(llm_server, make_client):
    from concurrent.futures import ThreadPoolExecutor

    llm_server.responder = lambda request: request["messages"][0]["content"].upper()
    client = make_client()
    with ThreadPoolExecutor(8) as pool:
        answers = list(pool.map(lambda i: client.complete([{"role": "user", "content": f"task {i}"}]), range(32)))
    assert answers == [f"TASK {i}" for i in range(32)]


# -- configuration --------------------------------------------------------------


def test_configuration_comes_from_the_environment(llm_server, monkeypatch):
    monkeypatch.setenv("ROBOCRITICS_BASE_URL", llm_server.url + "/")
    monkeypatch.setenv("ROBOCRITICS_MODEL", "env-model")
    monkeypatch.setenv("ROBOCRITICS_EMBEDDING_MODEL", "env-embed")
    monkeypatch.delenv("ROBOCRITICS_API_KEY", raising=False)
    monkeypatch.setenv("OPENAI_API_KEY", "sk-from-env")
    with OpenAICompatible() as client:
        assert client.base_url == llm_server.url
        client.complete(USER)
        client.embed(["a"])
    chat, embeddings = llm_server.requests
    assert chat.json["model"] == "env-model"
    assert embeddings.json["model"] == "env-embed"
    assert chat.headers["authorization"] == "Bearer sk-from-env"


def test_arguments_win_over_the_environment(llm_server, monkeypatch):
    monkeypatch.setenv("ROBOCRITICS_BASE_URL", "http://127.0.0.1:9/v1")
    monkeypatch.setenv("ROBOCRITICS_MODEL", "env-model")
    with OpenAICompatible(base_url=llm_server.url, model="arg-model") as client:
        client.complete(USER)
    assert llm_server.requests[0].json["model"] == "arg-model"


def test_no_api_key_sends_no_authorization_header(llm_server, monkeypatch):
    monkeypatch.delenv("ROBOCRITICS_API_KEY", raising=False)
    monkeypatch.delenv("OPENAI_API_KEY", raising=False)
    with OpenAICompatible(base_url=llm_server.url, model="llama3.1") as client:
        client.complete(USER)
    assert "authorization" not in llm_server.requests[0].headers


def test_missing_base_url_names_the_argument_and_variable(monkeypatch):
    monkeypatch.delenv("ROBOCRITICS_BASE_URL", raising=False)
    with pytest.raises(LLMError, match="base_url=.*ROBOCRITICS_BASE_URL"):
        OpenAICompatible(model="m")


def test_missing_model_names_the_argument_and_variable(monkeypatch):
    monkeypatch.delenv("ROBOCRITICS_MODEL", raising=False)
    with pytest.raises(LLMError, match="model=.*ROBOCRITICS_MODEL"):
        OpenAICompatible(base_url="http://127.0.0.1:9/v1")


def test_llm_errors_belong_to_the_library_error_tree(monkeypatch):
    monkeypatch.delenv("ROBOCRITICS_MODEL", raising=False)
    with pytest.raises(RoboCriticsError):
        OpenAICompatible(base_url="http://127.0.0.1:9/v1")


def test_base_url_must_be_http():
    with pytest.raises(LLMError, match="http://"):
        OpenAICompatible(base_url="localhost:11434/v1", model="m")


def test_a_full_endpoint_url_is_accepted_as_base_url(llm_server):
    with OpenAICompatible(base_url=llm_server.url + "/chat/completions", model="m") as client:
        client.complete(USER)
    assert llm_server.requests[0].path == "/v1/chat/completions"


def test_malformed_messages_are_rejected_before_any_request(llm_server, make_client):
    client = make_client()
    for bad in ([], "hello", [{"content": "no role"}], ["just text"]):
        with pytest.raises(ValueError):
            client.complete(bad)
    assert llm_server.requests == []


# -- retries --------------------------------------------------------------------


def test_429_is_retried_after_the_retry_after_delay(llm_server, make_client):
    llm_server.script(Fail(429, retry_after=1), Reply("ok"))
    client = make_client(retry_after_scale=0.25, retry_after_cap_s=5.0)
    reply = client.chat(USER)
    assert reply.content == "ok" and reply.attempts == 2
    assert len(llm_server.requests) == 2
    assert make_client.sleeps == [0.25]  # Retry-After 1 s x scale 0.25, above the 0.01 s backoff


def test_a_retry_after_within_the_cap_is_waited(llm_server, make_client):
    llm_server.script(Fail(429, retry_after=0.15), Reply("ok"))
    assert make_client(retry_after_cap_s=0.15).complete(USER) == "ok"
    assert make_client.sleeps == [0.15]


def test_a_retry_after_beyond_the_cap_gives_up_at_once(llm_server, make_client):
    llm_server.script(Fail(429, retry_after=3600), Reply("never sent"))
    with pytest.raises(LLMError, match=r"retry after 3600 s, more than retry_after_cap_s=0.15 s.*treated as down"):
        make_client(retry_after_cap_s=0.15).complete(USER)
    assert make_client.sleeps == []  # no waiting at all
    assert len(llm_server.requests) == 1 and llm_server.pending == 1


def test_retry_after_ms_header_is_honoured(llm_server, make_client):
    llm_server.script(Fail(503, headers={"retry-after-ms": "200"}), Reply("ok"))
    assert make_client().complete(USER) == "ok"
    assert make_client.sleeps == [0.2]


def test_the_default_sleep_really_waits(llm_server, make_client):
    llm_server.script(Fail(503, headers={"retry-after-ms": "100"}), Reply("ok"))
    assert make_client(sleep=time.sleep).complete(USER) == "ok"
    first, second = llm_server.requests
    assert second.time_s - first.time_s >= 0.1  # a lower bound: it holds on any machine


def test_retry_after_parsing():
    assert _retry_after_seconds(httpx.Headers({"Retry-After": "2"})) == 2.0
    assert _retry_after_seconds(httpx.Headers({"Retry-After": "0.5"})) == 0.5
    assert _retry_after_seconds(httpx.Headers({"Retry-After": "-3"})) is None
    assert _retry_after_seconds(httpx.Headers({"Retry-After": "soon"})) is None
    assert _retry_after_seconds(httpx.Headers({})) is None
    assert _retry_after_seconds(httpx.Headers({"retry-after-ms": "1500", "Retry-After": "9"})) == 1.5
    now_s = 1_700_000_000.0
    in_30_s = email.utils.formatdate(now_s + 30, usegmt=True)
    assert _retry_after_seconds(httpx.Headers({"Retry-After": in_30_s}), now_s=now_s) == 30.0
    long_ago = email.utils.formatdate(0, usegmt=True)
    assert _retry_after_seconds(httpx.Headers({"Retry-After": long_ago})) == 0.0


def test_backoff_grows_exponentially(llm_server, make_client):
    llm_server.script(Fail(500), Fail(500), Fail(500), Reply("ok"))
    client = make_client(backoff_base_s=0.05, backoff_max_s=10.0)
    assert client.complete(USER) == "ok"
    assert len(llm_server.requests) == 4
    assert make_client.sleeps == [0.05, 0.1, 0.2]


def test_backoff_is_capped(llm_server, make_client):
    llm_server.script(Fail(500), Fail(500), Fail(500), Fail(500), Reply("ok"))
    assert make_client(backoff_base_s=0.01, backoff_max_s=0.03, max_retries=4).complete(USER) == "ok"
    assert make_client.sleeps == [0.01, 0.02, 0.03, 0.03]


@pytest.mark.parametrize("status", [500, 502, 503, 504, 408, 409])
def test_transient_statuses_are_retried(llm_server, make_client, status):
    llm_server.script(Fail(status), Reply("ok"))
    reply = make_client().chat(USER)
    assert reply.content == "ok" and reply.attempts == 2


def test_an_embedding_timeout_is_retried(llm_server, make_client):
    llm_server.script(Delay(STALL_S))
    client = make_client(timeout_s=1.0)  # the retry's answer must come within it, also on a loaded machine
    started = time.monotonic()
    vectors = client.embed(["hello"])
    assert vectors.shape == (1, llm_server.embedding_dim)
    assert time.monotonic() - started >= 1.0  # the real timeout ran out (a lower bound)
    assert len(llm_server.embedding_requests()) == 2
    assert make_client.sleeps == [0.01]


def test_a_chat_that_times_out_generating_is_not_retried(llm_server, make_client):
    from robocritics.llm.protocol import GenerationTimeoutError

    llm_server.script(Delay(STALL_S), Reply("never asked for"))
    client = make_client(timeout_s=0.5)
    with pytest.raises(GenerationTimeoutError, match="not retried"):
        client.chat(USER)
    assert len(llm_server.chat_requests()) == 1  # the server is not asked to generate twice
    assert make_client.sleeps == []


def test_a_dropped_connection_is_retried(llm_server, make_client):
    llm_server.script(Drop(), Reply("ok"))
    reply = make_client().chat(USER)
    assert reply.content == "ok" and reply.attempts == 2


def test_a_non_json_5xx_is_retried(llm_server, make_client):
    llm_server.script(Garbage(b"<html>Bad Gateway</html>", status=502), Reply("ok"))
    assert make_client().complete(USER) == "ok"


def test_gives_up_after_max_retries_naming_the_last_status(llm_server, make_client):
    llm_server.script(Fail(500), Fail(502), Fail(503), Fail(503))
    client = make_client(max_retries=2)
    with pytest.raises(LLMError) as caught:
        client.complete(USER)
    message = str(caught.value)
    assert "3 attempts" in message
    assert "HTTP 503" in message
    assert "scripted failure 503" in message  # the server's own words
    assert len(llm_server.requests) == 3
    assert llm_server.pending == 1
    assert make_client.sleeps == [0.01, 0.02]  # none after the last attempt


def test_gives_up_after_repeated_timeouts(llm_server, make_client):
    llm_server.script(Delay(STALL_S), Delay(STALL_S))
    client = make_client(timeout_s=0.2, max_retries=1)
    with pytest.raises(LLMError, match="2 attempts.*timed out"):
        client.embed(["hello"])


def test_max_retries_zero_sends_one_request(llm_server, make_client):
    llm_server.script(Fail(429, retry_after=0))
    with pytest.raises(LLMError, match="1 attempts.*HTTP 429"):
        make_client(max_retries=0).complete(USER)
    assert len(llm_server.requests) == 1
    assert make_client.sleeps == []


def test_nothing_listening_is_a_connection_error():
    with socket.socket() as sock:  # find a loopback port with nobody on it
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    pauses: list[float] = []
    client = OpenAICompatible(
        base_url=f"http://127.0.0.1:{port}/v1", model="m", max_retries=1, timeout_s=1.0, sleep=pauses.append
    )
    with client, pytest.raises(LLMError, match="2 attempts.*connection failed"):
        client.complete(USER)
    assert pauses == [0.5]  # the default backoff base


# -- errors that are not retried -------------------------------------------------


@pytest.mark.parametrize("status", [401, 403])
def test_auth_failures_point_at_the_api_key_and_are_not_retried(llm_server, make_client, status):
    llm_server.script(Fail(status))
    with pytest.raises(LLMError, match=f"HTTP {status}.*check your API key.*OPENAI_API_KEY"):
        make_client().complete(USER)
    assert len(llm_server.requests) == 1


def test_404_points_at_base_url_and_model_name(llm_server, make_client):
    llm_server.models = {"llama3.1"}
    with pytest.raises(LLMError) as caught:
        make_client(model="llama3.2").complete(USER)
    message = str(caught.value)
    assert "HTTP 404" in message
    assert "check base_url" in message and "model name" in message
    assert "'llama3.2'" in message
    assert "not found" in message  # the server's words are passed on
    assert len(llm_server.requests) == 1


def test_wrong_path_gives_404_hint(llm_server):
    base = llm_server.url.removesuffix("/v1")  # forgot the /v1, a classic with Ollama
    with OpenAICompatible(base_url=base, model="m") as client, pytest.raises(LLMError, match="404.*/v1"):
        client.complete(USER)


def test_a_redirect_points_at_base_url(llm_server, make_client):
    llm_server.script(Fail(301, headers={"Location": "https://example.invalid/v1/chat/completions"}))
    with pytest.raises(LLMError, match="redirected \\(HTTP 301\\) to https://example.invalid/.*check base_url"):
        make_client().complete(USER)
    assert len(llm_server.requests) == 1  # not followed anywhere


def test_other_client_errors_carry_the_server_message(llm_server, make_client):
    llm_server.script(Fail(400, body='{"error": {"message": "max_tokens is too large"}}'))
    with pytest.raises(LLMError, match="HTTP 400.*max_tokens is too large"):
        make_client().complete(USER)
    assert len(llm_server.requests) == 1


# -- garbled replies ---------------------------------------------------------------


def test_a_non_json_body_is_reported_with_an_excerpt(llm_server, make_client):
    llm_server.script(Garbage(b"<html>captive portal</html>"))
    with pytest.raises(LLMError, match=r"HTTP 200 \(text/html\).*not JSON.*captive portal"):
        make_client().complete(USER)


def test_a_huge_garbage_body_is_truncated_in_the_error(llm_server, make_client):
    llm_server.script(Garbage("x" * 100_000, content_type="text/plain"))
    with pytest.raises(LLMError) as caught:
        make_client().complete(USER)
    message = str(caught.value)
    assert len(message) < 1000
    assert "100000 chars, truncated" in message


def test_json_without_choices_is_reported(llm_server, make_client):
    llm_server.script(RawJSON({"result": "fine"}))
    with pytest.raises(LLMError, match=r"no 'choices'.*\"result\": \"fine\""):
        make_client().complete(USER)


def test_json_error_object_with_status_200_is_reported(llm_server, make_client):
    llm_server.script(RawJSON({"error": {"message": "context length exceeded"}}))
    with pytest.raises(LLMError, match="no 'choices'.*context length exceeded"):
        make_client().complete(USER)


def test_empty_choices_is_reported(llm_server, make_client):
    llm_server.script(RawJSON({"choices": []}))
    with pytest.raises(LLMError, match=r"empty or invalid 'choices'.*\[\]"):
        make_client().complete(USER)


@pytest.mark.parametrize(
    "body, expected",
    [
        ({"choices": [{"index": 0}]}, "no 'message'"),
        ({"choices": [{"message": {"role": "assistant"}}]}, "no text 'content'"),
        ({"choices": [{"message": {"role": "assistant", "content": None, "tool_calls": [{}]}}]}, "tool calls"),
        ({"choices": ["text"]}, "no 'message'"),
        ([1, 2, 3], "expected a JSON object"),
    ],
)
def test_malformed_choices_are_reported(llm_server, make_client, body, expected):
    llm_server.script(RawJSON(body))
    with pytest.raises(LLMError, match=expected):
        make_client().complete(USER)


def test_garbled_replies_are_not_retried(llm_server, make_client):
    llm_server.script(RawJSON({"choices": []}), Reply("never used"))
    with pytest.raises(LLMError):
        make_client().complete(USER)
    assert llm_server.pending == 1


# -- the API key never leaks --------------------------------------------------------

SECRET = "sk-live-4f9a2c81d7e3b6a5c0f1e2d3c4b5a697"


def assert_no_secret(text: str) -> None:
    assert SECRET not in text
    for start in range(len(SECRET) - 8 + 1):
        assert SECRET[start : start + 8] not in text, f"part of the key leaked: {text!r}"


def test_repr_and_str_hide_the_key():
    client = OpenAICompatible(base_url="http://127.0.0.1:9/v1", model="m", api_key=SECRET)
    with client:
        assert_no_secret(repr(client))
        assert_no_secret(str(client))
        assert_no_secret(f"{client!r} {client}")
        assert "api_key='***'" in repr(client)
        assert_no_secret(repr(vars(client)))


def test_a_401_that_echoes_the_key_does_not_leak_it(caplog):
    caplog.set_level(logging.DEBUG)  # every logger, httpx and httpcore included
    with LLMServer(require_api_key="the-right-key") as server:
        client = OpenAICompatible(base_url=server.url, model="m", api_key=SECRET, backoff_base_s=0.01)
        with client, pytest.raises(LLMError) as caught:
            client.complete(USER)
        assert server.requests[0].headers["authorization"] == f"Bearer {SECRET}"  # it was sent...
    assert "Incorrect API key provided: ***" in str(caught.value)  # ...and the echo was scrubbed
    assert_no_secret(str(caught.value))
    assert_no_secret(repr(caught.value))
    assert_no_secret(chained_text(caught.value))
    assert_no_secret(caplog.text)


def test_partial_echoes_of_the_key_are_scrubbed_from_retried_errors(llm_server, caplog):
    caplog.set_level(logging.DEBUG)
    masked = SECRET[:12] + "*" * 20 + SECRET[-10:]  # how OpenAI echoes a wrong key
    llm_server.script(
        Fail(503, body=f'{{"error": {{"message": "overloaded for key {masked}"}}}}'),
        Fail(503, body=f'{{"error": {{"message": "overloaded for key {SECRET}"}}}}'),
    )
    client = OpenAICompatible(base_url=llm_server.url, model="m", api_key=SECRET, max_retries=1, backoff_base_s=0.01)
    with client, pytest.raises(LLMError) as caught:
        client.complete(USER)
    assert "overloaded for key" in str(caught.value)
    assert_no_secret(chained_text(caught.value))
    assert "retrying" in caplog.text and "overloaded for key" in caplog.text  # the retry was logged...
    assert_no_secret(caplog.text)  # ...with the first body scrubbed


def test_garbage_that_contains_the_key_is_scrubbed(llm_server):
    llm_server.script(Garbage(f"debug: Authorization: Bearer {SECRET}".encode()))
    client = OpenAICompatible(base_url=llm_server.url, model="m", api_key=SECRET)
    with client, pytest.raises(LLMError) as caught:
        client.complete(USER)
    assert "Bearer ***" in str(caught.value)
    assert_no_secret(chained_text(caught.value))


def test_the_client_cannot_be_pickled_with_its_key():
    client = OpenAICompatible(base_url="http://127.0.0.1:9/v1", model="m", api_key=SECRET)
    with client, pytest.raises(TypeError) as caught:
        pickle.dumps(client)
    assert_no_secret(str(caught.value))


def test_redaction_of_runs_of_the_secret():
    secret = "abcdefghijklmnop"
    assert _redact_secret("key abcdefghijklmnop!", secret) == "key ***!"
    assert _redact_secret("key abcdefgh...mnop", secret) == "key ***...mnop"  # 8+ char run goes
    assert _redact_secret("key ghijklmnopqrs", secret) == "key ***qrs"
    assert _redact_secret("nothing here", secret) == "nothing here"
    assert _redact_secret("abcdefg", secret) == "abcdefg"  # 7 chars are not a leak


# -- embeddings ------------------------------------------------------------------


def test_embed_returns_one_float_row_per_text(llm_server, make_client):
    texts = ["green apple", "white box", "green apple"]
    vectors = make_client().embed(texts)
    assert vectors.shape == (3, llm_server.embedding_dim)
    assert vectors.dtype == np.float64
    np.testing.assert_allclose(np.linalg.norm(vectors, axis=1), 1.0)
    np.testing.assert_array_equal(vectors[0], vectors[2])
    np.testing.assert_allclose(
        vectors[1], hashed_embedding("white box", llm_server.embedding_dim, TEST_EMBEDDING_MODEL)
    )
    (request,) = llm_server.requests
    assert request.path == "/v1/embeddings"
    assert request.json == {"model": TEST_EMBEDDING_MODEL, "input": texts}


def test_embed_batches_and_keeps_order(llm_server, make_client):
    llm_server.embedding_dim = 16
    texts = [f"object number {i}" for i in range(5)]
    vectors = make_client(embedding_batch_size=2).embed(texts)
    assert vectors.shape == (5, 16)
    assert [len(r.json["input"]) for r in llm_server.embedding_requests()] == [2, 2, 1]
    for text, row in zip(texts, vectors):
        np.testing.assert_allclose(row, hashed_embedding(text, 16, TEST_EMBEDDING_MODEL))


def test_embed_of_nothing_sends_nothing(llm_server, make_client):
    assert make_client().embed([]).shape == (0, 0)
    assert llm_server.requests == []


def test_embed_without_an_embedding_model_says_what_to_set(llm_server, make_client, monkeypatch):
    monkeypatch.delenv("ROBOCRITICS_EMBEDDING_MODEL", raising=False)
    with pytest.raises(LLMError, match="embedding_model=.*ROBOCRITICS_EMBEDDING_MODEL"):
        make_client(embedding_model=None).embed(["x"])


def test_embed_retries_like_chat(llm_server, make_client):
    llm_server.script(Fail(429, retry_after=0), Drop())
    assert make_client().embed(["a", "b"]).shape == (2, 64)
    assert len(llm_server.embedding_requests()) == 3
    assert make_client.sleeps == [0.01, 0.02]


def test_embed_accepts_base64_vectors_and_out_of_order_indices(llm_server, make_client):
    import base64

    a = np.array([1.0, 0.0, 0.5], dtype="<f4")
    b = np.array([0.0, 2.0, 0.0], dtype="<f4")
    data = [
        {"index": 1, "embedding": base64.b64encode(b.tobytes()).decode()},
        {"index": 0, "embedding": a.tolist()},
    ]
    llm_server.script(RawJSON({"data": data}))
    np.testing.assert_allclose(make_client().embed(["a", "b"]), [a, b])


@pytest.mark.parametrize(
    "body, expected",
    [
        ({"data": [{"index": 0, "embedding": [1.0, 2.0]}]}, "1 vectors for 2 texts"),
        ({"data": [{"index": 0, "embedding": [1.0]}, {"index": 1, "embedding": [1.0, 2.0]}]}, "different lengths"),
        ({"data": [{"index": 0, "embedding": ["a"]}, {"index": 1, "embedding": [1.0]}]}, "not numbers"),
        ({"data": [{"index": 0, "embedding": []}, {"index": 1, "embedding": [1.0]}]}, "empty"),
        ({"object": "list"}, "no 'data'"),
        ({"error": "model is not an embedding model"}, "not an embedding model"),
    ],
)
def test_bad_embedding_replies_are_reported(llm_server, make_client, body, expected):
    llm_server.script(RawJSON(body))
    with pytest.raises(LLMError, match=expected):
        make_client().embed(["a", "b"])


def test_embedding_garbage_is_reported(llm_server, make_client):
    llm_server.script(Garbage(b"\x00\x01 not json", content_type="application/octet-stream"))
    with pytest.raises(LLMError, match="not JSON"):
        make_client().embed(["a"])
