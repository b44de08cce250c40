"""Hostile LLM servers: every reply is bounded in time, bytes, nesting and text (issue 10, item 3).

Each case is a real HTTP server on 127.0.0.1 (tests/llm_server.py) doing what an
attacker (or a broken proxy) would: dripping bytes, inflating a gzip bomb,
sending 50 MB, nesting JSON 100 000 deep, asking to retry in an hour, sending lone
surrogates. Each must end within the configured deadline with an ``LLMError``
and bounded memory. Retry pauses are recorded, not slept; the only real waits
are the deadline cases, whose tolerance (``SLACK_S``) holds on a loaded 2-core
machine while the unbounded behaviour they guard against lasts a minute or more.
"""

# ruff: noqa: F811  (pytest fixtures imported from llm_fixtures are parameters here)

from __future__ import annotations

import io
import json
import time
import tracemalloc

import pytest
from llm_fixtures import clean_llm_env, llm_server, make_client  # noqa: F401
from llm_server import Delay, Fail, Garbage, RawJSON, Reply, SlowHeaders, Stream, chat_body, drip, gzip_bomb

from robocritics.errors import LLMError
from robocritics.llm.protocol import LLMArgumentError
from robocritics.llm.limits import MAX_JSON_DEPTH, MAX_REPLY_CHARS, MAX_RESPONSE_BYTES, clean_text

pytestmark = pytest.mark.usefixtures("clean_llm_env")

USER = [{"role": "user", "content": "put the green apple in the white box"}]

# How late past its deadline a call may end on a loaded machine (scheduling, one socket read, the error).
SLACK_S = 2.5
# A stall no deadline here comes near (it ends when the server stops).
STALL_S = 60.0
# Python heap a bounded reply may use while it is read and decoded (the body cap is 8 MiB).
HEAP_LIMIT_B = 64 * 1024 * 1024


def timed_failure(call) -> tuple[LLMError, float]:
    started = time.monotonic()
    with pytest.raises(LLMError) as caught:
        call()
    return caught.value, time.monotonic() - started


def peak_heap(call) -> tuple[BaseException | None, int]:
    """Run ``call``; return what it raised and the peak of the Python heap (bytes) above the start."""
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        try:
            call()
            raised = None
        except BaseException as exc:  # noqa: BLE001 - the test inspects it
            raised = exc
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    return raised, peak


# -- time: one deadline per request ----------------------------------------------------------------


def test_a_body_dripping_one_byte_at_a_time_ends_at_the_deadline(llm_server, make_client):
    # 400 bytes at one per 0.25 s would take 100 s; every single read is well inside timeout_s.
    llm_server.script(drip(chat_body("x" * 300), interval_s=0.25))
    client = make_client(timeout_s=2.0, deadline_s=1.5)
    error, elapsed = timed_failure(lambda: client.complete(USER))
    assert "deadline of 1.5 s" in str(error)
    assert 1.4 <= elapsed < 1.5 + SLACK_S
    assert len(llm_server.requests) == 1  # no retry once the deadline has passed


def test_headers_dripping_one_byte_at_a_time_end_at_the_deadline(llm_server, make_client):
    llm_server.script(SlowHeaders(interval_s=0.25))
    client = make_client(timeout_s=2.0, deadline_s=1.5)
    error, elapsed = timed_failure(lambda: client.complete(USER))
    assert "deadline of 1.5 s" in str(error)
    assert 1.4 <= elapsed < 1.5 + SLACK_S


def test_stalls_and_retries_together_end_at_the_deadline(llm_server, make_client):
    llm_server.script(*[Delay(STALL_S)] * 20)
    client = make_client(timeout_s=0.6, deadline_s=1.5, max_retries=20)
    # embeddings: a stalled chat is never retried (the server may still be generating), an embedding call is
    error, elapsed = timed_failure(lambda: client.embed(["hello"]))
    assert "did not finish within its deadline of 1.5 s" in str(error) and "timed out" in str(error)
    assert elapsed < 1.5 + SLACK_S
    assert 2 <= len(llm_server.requests) <= 3  # 0.6 s + 0.6 s + what is left; never 21


def test_retry_after_pauses_count_against_the_deadline(llm_server, make_client):
    llm_server.script(*[Fail(503, retry_after=2)] * 5, Reply("too late"))
    client = make_client(deadline_s=5.0, retry_after_cap_s=10.0, max_retries=5)
    with pytest.raises(LLMError, match=r"next attempt would start after the deadline \(a 2 s pause"):
        client.complete(USER)
    assert make_client.sleeps == [2.0, 2.0]  # a third 2 s pause would end past the 5 s deadline
    assert len(llm_server.requests) == 3


def test_a_retry_after_of_an_hour_fails_at_once_with_the_default_settings(llm_server, make_client):
    llm_server.script(Fail(429, retry_after=3600), Reply("never"))
    client = make_client(backoff_base_s=0.5, backoff_max_s=30.0)  # the library's backoff; default cap
    with pytest.raises(LLMError, match=r"retry after 3600 s, more than retry_after_cap_s=60 s"):
        client.complete(USER)
    assert make_client.sleeps == []


def test_an_http_date_retry_after_far_in_the_future_fails_at_once(llm_server, make_client):
    import email.utils

    llm_server.script(Fail(503, retry_after=email.utils.formatdate(time.time() + 7200, usegmt=True)))
    with pytest.raises(LLMError, match="treated as down"):
        make_client().complete(USER)
    assert make_client.sleeps == []


# -- bytes: bodies capped on the wire and decompressed ---------------------------------------------


def test_a_gzip_bomb_is_stopped_at_the_size_limit_with_bounded_memory(llm_server, make_client):
    bomb = gzip_bomb(2048)  # 2 MB on the wire, 2 GiB inflated
    assert len(bomb) < 2_200_000
    llm_server.script(Garbage(bomb, content_type="application/json", headers={"Content-Encoding": "gzip"}))
    client = make_client()
    raised, peak = peak_heap(lambda: client.complete(USER))
    assert isinstance(raised, LLMError)
    assert f"inflates (gzip) to more than the limit of {MAX_RESPONSE_BYTES:,} bytes" in str(raised)
    assert peak < HEAP_LIMIT_B


def test_a_deflate_bomb_is_stopped_too(llm_server, make_client):
    import zlib

    bomb = zlib.compress(bytes(200 * 1024 * 1024), 9)  # zlib-wrapped deflate, 200 MiB inflated
    llm_server.script(Garbage(bomb, content_type="application/json", headers={"Content-Encoding": "deflate"}))
    client = make_client()
    raised, peak = peak_heap(lambda: client.complete(USER))
    assert isinstance(raised, LLMError) and "inflates (deflate)" in str(raised)
    assert peak < HEAP_LIMIT_B


def test_a_50_mb_reply_is_refused_while_it_arrives(llm_server, make_client):
    piece = b"x" * (1 << 20)
    head = b'{"choices": [{"message": {"role": "assistant", "content": "'

    def body():
        yield head
        for _ in range(50):
            yield piece
        yield b'"}}]}'

    llm_server.script(Stream(body))  # chunked: no Content-Length to refuse it by
    client = make_client()
    raised, peak = peak_heap(lambda: client.complete(USER))
    assert isinstance(raised, LLMError)
    assert f"larger than the limit of {MAX_RESPONSE_BYTES:,} bytes; stopped reading" in str(raised)
    assert peak < HEAP_LIMIT_B


def test_the_body_limit_is_configurable_and_counts_wire_bytes(llm_server, make_client):
    llm_server.script(Reply("y" * 5000))
    with pytest.raises(LLMError, match="larger than the limit of 1,000 bytes"):
        make_client(max_response_bytes=1000).complete(USER)


def test_a_reply_text_over_the_character_limit_is_refused(llm_server, make_client):
    llm_server.script(Reply("z" * (MAX_REPLY_CHARS + 1)))
    with pytest.raises(LLMError, match=f"is {MAX_REPLY_CHARS + 1:,} characters long; the limit is"):
        make_client(stream=False).complete(USER)


def test_a_streamed_reply_over_the_character_limit_is_refused_while_it_arrives(llm_server, make_client):
    llm_server.script(Reply("zz " * MAX_REPLY_CHARS))
    with pytest.raises(LLMError, match=f"longer than {MAX_REPLY_CHARS:,} characters"):
        make_client(max_tokens=None).complete(USER)
    assert llm_server.cancelled.wait(5.0)  # the client hung up instead of reading the rest


def test_an_error_page_is_read_only_as_far_as_it_is_quoted(llm_server, make_client):
    def endless():
        while True:
            yield b"<p>overloaded</p>" * 4096

    llm_server.script(Stream(endless, status=400, content_type="text/html"))
    error, elapsed = timed_failure(lambda: make_client().complete(USER))
    assert "rejected with HTTP 400" in str(error) and "overloaded" in str(error)
    assert len(str(error)) < 1000 and elapsed < SLACK_S


@pytest.mark.parametrize(
    ("headers", "body", "message"),
    [
        ({"Content-Encoding": "br"}, b"\x1b\x00", "Content-Encoding 'br'"),
        ({"Content-Encoding": "gzip"}, b"definitely not gzip", "not valid gzip data"),
        ({"Content-Encoding": "gzip, gzip"}, b"", "Content-Encoding 'gzip, gzip'"),
    ],
    ids=["brotli", "not-gzip", "double-gzip"],
)
def test_bodies_that_cannot_be_decoded_are_llm_errors(llm_server, make_client, headers, body, message):
    llm_server.script(Garbage(body, content_type="application/json", headers=headers))
    with pytest.raises(LLMError, match=message):
        make_client().complete(USER)


def test_a_gzipped_reply_is_read_normally(llm_server, make_client):
    import gzip

    llm_server.script(
        Garbage(gzip.compress(chat_body("lib.home()")), content_type="application/json", headers={"Content-Encoding": "gzip"})
    )
    assert make_client().complete(USER) == "lib.home()"
    assert "gzip" in llm_server.requests[0].headers["accept-encoding"]


# -- nesting and numbers: JSON decoded only when it is safe to -------------------------------------


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (b"[" * 100_000 + b"]" * 100_000, "nests 100,000 levels deep"),
        (b'{"choices": ' + b'{"a": ' * 50_000 + b"1" + b"}" * 50_001, "nests 50,001 levels deep"),
        (b"[" + b"[]," * 200_000 + b"[]]", "holds 200,002 arrays and objects"),
    ],
    ids=["100k-deep-arrays", "50k-deep-objects", "200k-empty-arrays"],
)
def test_deep_or_huge_json_is_refused_before_decoding(llm_server, make_client, body, message):
    llm_server.script(Garbage(body, content_type="application/json"))
    with pytest.raises(LLMError, match=message):
        make_client().complete(USER)


def test_deep_json_in_an_error_body_is_quoted_not_decoded(llm_server, make_client):
    llm_server.script(Garbage(b"[" * 100_000, status=400, content_type="application/json"))
    with pytest.raises(LLMError, match=r"rejected with HTTP 400 \(server says: \[\[\["):
        make_client().complete(USER)


def test_brackets_inside_strings_do_not_count_as_nesting(llm_server, make_client):
    program = "grid = " + "[" * (MAX_JSON_DEPTH * 4) + "]" * (MAX_JSON_DEPTH * 4)
    llm_server.reply(program)
    assert make_client().complete(USER) == program


def test_a_number_with_100000_digits_is_an_llm_error(llm_server, make_client):
    llm_server.script(Garbage(b'{"choices": [], "n": ' + b"9" * 100_000 + b"}", content_type="application/json"))
    with pytest.raises(LLMError, match="not JSON"):
        make_client().complete(USER)


def test_embedding_indices_that_are_not_a_permutation_are_llm_errors(llm_server, make_client):
    data = [{"index": 0, "embedding": [1.0]}, {"index": 0, "embedding": [2.0]}]
    llm_server.script(RawJSON({"data": data}))
    with pytest.raises(LLMError, match="'index' fields are not 0..1 once each"):
        make_client().embed(["a", "b"])
    mixed = [{"index": "x", "embedding": [1.0]}, {"index": 1, "embedding": [2.0]}]
    llm_server.script(RawJSON({"data": mixed}))  # unusable indices: the server's order is kept, no TypeError
    assert make_client().embed(["a", "b"]).tolist() == [[1.0], [2.0]]


# -- text: lone surrogates never crash printing, storing or the next request -----------------------


def test_lone_surrogates_in_a_reply_are_replaced(llm_server, make_client):
    llm_server.reply("move_to(0.1) \ud800 done \udfff")  # json.dumps sends them as \ud800 escapes
    client = make_client()
    reply = client.complete(USER)
    assert reply == "move_to(0.1) \ufffd done \ufffd"
    strict = io.TextIOWrapper(io.BytesIO(), encoding="utf-8", errors="strict")
    print(reply, file=strict)  # printing works
    strict.flush()
    assert client.complete([{"role": "user", "content": reply}]) == reply  # and so does the next request


def test_lone_surrogates_in_messages_are_replaced_before_sending(llm_server, make_client):
    client = make_client()
    client.complete([{"role": "user", "content": "task from argv \udcff bytes"}])
    sent = llm_server.requests[0]
    assert sent.json["messages"][0]["content"] == "task from argv \ufffd bytes"
    sent.body.decode("utf-8")  # valid UTF-8 on the wire


def test_a_lone_surrogate_in_a_server_error_is_replaced(llm_server, make_client):
    llm_server.script(Fail(400, body=json.dumps({"error": {"message": "bad \ud800 input"}})))
    with pytest.raises(LLMError) as caught:
        make_client().complete(USER)
    assert "bad \ufffd input" in str(caught.value)
    str(caught.value).encode("utf-8")


def test_clean_text_leaves_valid_text_alone():
    assert clean_text("grüne Äpfel 🍏") == "grüne Äpfel 🍏"
    assert clean_text("a\ud83db") == "a\ufffdb"


# -- what is sent is bounded and valid --------------------------------------------------------------


def test_a_request_over_the_size_limit_is_refused_before_sending(llm_server, make_client):
    with pytest.raises(LLMArgumentError, match="the request is .* bytes; the limit is 1,000"):
        make_client(max_request_bytes=1000).complete([{"role": "user", "content": "w" * 2000}])
    assert llm_server.requests == []


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"deadline_s": 0}, "deadline_s must be a finite number > 0"),
        ({"deadline_s": float("inf")}, "deadline_s must be a finite number"),
        ({"timeout_s": float("nan")}, "timeout_s must be a finite number"),
        ({"temperature": float("nan")}, "temperature must be a number from 0 to 2"),
        ({"max_response_bytes": 0}, "max_response_bytes must be a whole number >= 1"),
        ({"max_retries": -1}, "max_retries must be a whole number >= 0"),
    ],
)
def test_bad_client_settings_are_typed_errors(llm_server, make_client, options, message):
    with pytest.raises(LLMArgumentError, match=message):
        make_client(**options)


def test_a_nan_temperature_per_call_is_refused_before_sending(llm_server, make_client):
    with pytest.raises(LLMArgumentError, match="temperature"):
        make_client().complete(USER, temperature=float("nan"))
    assert llm_server.requests == []


def test_deadlines_are_per_call_when_threads_share_a_client(llm_server, make_client):
    import threading

    def responder(request):
        text = request["messages"][-1]["content"]
        return drip(chat_body("x" * 200), interval_s=0.25) if text.startswith("slow") else f"done {text}"

    llm_server.responder = responder
    client = make_client(timeout_s=2.0, deadline_s=1.5)
    outcomes: dict[str, object] = {}

    def call(text: str) -> None:
        started = time.monotonic()
        try:
            outcomes[text] = (client.complete([{"role": "user", "content": text}]), time.monotonic() - started)
        except LLMError as exc:
            outcomes[text] = (exc, time.monotonic() - started)

    names = [f"{kind} {i}" for i in range(4) for kind in ("slow", "fast")]
    threads = [threading.Thread(target=call, args=(name,)) for name in names]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=30)
    assert len(outcomes) == 8
    for name, (result, elapsed) in outcomes.items():
        if name.startswith("slow"):
            assert isinstance(result, LLMError) and "deadline of 1.5 s" in str(result), name
            assert elapsed < 1.5 + SLACK_S
        else:
            assert result == f"done {name}"  # the slow calls' deadlines never touched these
