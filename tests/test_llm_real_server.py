"""Optional: the client against a real llama.cpp server on this machine (skipped without one).

Start ``llama-server -m MODEL.gguf --port 8080 -c 2048`` and set
``ROBOCRITICS_TEST_LLAMA_URL=http://127.0.0.1:8080/v1`` (see docs/llm.md). Only loopback addresses are
used: the tests never reach outside this machine.
"""

from __future__ import annotations

import os
import urllib.parse

import httpx
import pytest

from robocritics.llm.protocol import EmbeddingsUnavailableError
from robocritics.llm.providers.openai_compatible import OpenAICompatible
from robocritics.llm.loop import Loop
from robocritics.scene import Scene

URL = os.environ.get("ROBOCRITICS_TEST_LLAMA_URL", "")
MODEL = os.environ.get("ROBOCRITICS_TEST_LLAMA_MODEL", "local")


def _reachable(url: str) -> str | None:
    """Why the tests are skipped, or None to run them."""
    if not url:
        return "ROBOCRITICS_TEST_LLAMA_URL is not set (a llama.cpp server's /v1 URL on this machine)"
    host = urllib.parse.urlsplit(url).hostname or ""
    if host not in ("127.0.0.1", "localhost", "::1"):
        return f"ROBOCRITICS_TEST_LLAMA_URL names {host!r}: only a server on this machine is used"
    root = url.rstrip("/").removesuffix("/v1")
    try:
        httpx.get(root + "/health", timeout=2.0)
    except httpx.HTTPError as exc:
        return f"no server answers at {root} ({type(exc).__name__})"
    return None


pytestmark = pytest.mark.skipif(_reachable(URL) is not None, reason=str(_reachable(URL)))


@pytest.fixture
def client():
    with OpenAICompatible(base_url=URL, model=MODEL, api_key="none", deadline_s=120.0, timeout_s=60.0) as c:
        yield c


def test_a_streamed_reply_is_capped(client):
    reply = client.chat([{"role": "user", "content": "Count from 1 to 500, one number per line."}], max_tokens=16)
    assert reply.streamed
    assert reply.finish_reason in ("length", "stop")
    assert reply.completion_tokens is not None and reply.completion_tokens <= 16


def test_the_server_reports_its_context(client):
    context = client.server_context_tokens()
    assert context is None or context >= 256


def test_a_loop_request_fits_the_servers_context(client):
    context = client.server_context_tokens()
    loop = Loop(client, Scene.builtin("sorting"), critics=["joint_speed"], context_tokens=context,
                model_options={"max_tokens": 256})  # fmt: skip
    attempt = loop.request("put the green apple in the white box")
    assert attempt.reply  # some reply came back; a small model's program may well not run


def test_embeddings_work_or_fail_as_final(client):
    client.embedding_model = MODEL
    try:
        vectors = client.embed(["sort the apples", "plate"])
    except EmbeddingsUnavailableError:
        return  # a server started without --embeddings: final, not retried
    assert vectors.shape[0] == 2 and vectors.shape[1] > 0
