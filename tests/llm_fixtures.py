"""pytest fixtures for the LLM tests: a fresh ``LLMServer`` and clients pointed at it.

Import the fixtures into a test module: ``from llm_fixtures import llm_server, make_client``.
Modules that build clients from the environment should also use ``clean_llm_env``
(e.g. ``pytestmark = pytest.mark.usefixtures("clean_llm_env")``), so a developer's
real configuration or API key never reaches a test server.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
from llm_server import LLMServer

from robocritics.llm.providers.openai_compatible import OpenAICompatible

TEST_MODEL = "test-chat"
TEST_EMBEDDING_MODEL = "test-embed"

LLM_ENVIRONMENT = (
    "ROBOCRITICS_BASE_URL",
    "ROBOCRITICS_MODEL",
    "ROBOCRITICS_EMBEDDING_MODEL",
    "ROBOCRITICS_API_KEY",
    "OPENAI_API_KEY",
)


@pytest.fixture
def clean_llm_env(monkeypatch: pytest.MonkeyPatch) -> None:
    """Remove every environment variable ``OpenAICompatible`` reads, for the test's duration."""
    for name in LLM_ENVIRONMENT:
        monkeypatch.delenv(name, raising=False)


@pytest.fixture
def llm_server() -> Iterator[LLMServer]:
    """A started ``LLMServer`` on 127.0.0.1, stopped after the test."""
    with LLMServer() as server:
        yield server


class ClientFactory:
    """Makes ``OpenAICompatible`` clients for one ``LLMServer`` that do not really wait between retries.

    Each pause a client would sleep is appended to ``sleeps`` instead, so retry
    timing is asserted exactly and costs no time. The clients' clock is the
    real monotonic clock plus every recorded pause (``clock()``), so pauses
    count against the request deadline as if they had been slept. Defaults:
    model ``test-chat``, embedding model ``test-embed``, timeout 2 s, backoff
    base 0.01 s capped at 0.05 s; any keyword overrides them
    (``sleep=time.sleep, clock=time.monotonic`` for real waits).
    """

    def __init__(self, server: LLMServer):
        self.server = server
        self.sleeps: list[float] = []
        self.clients: list[OpenAICompatible] = []

    def clock(self) -> float:
        """Seconds: ``time.monotonic()`` plus all recorded pauses."""
        return time.monotonic() + sum(self.sleeps)

    def __call__(self, **overrides) -> OpenAICompatible:
        options = dict(
            base_url=self.server.url,
            model=TEST_MODEL,
            embedding_model=TEST_EMBEDDING_MODEL,
            api_key="sk-test-not-a-secret",
            timeout_s=2.0,
            backoff_base_s=0.01,
            backoff_max_s=0.05,
            sleep=self.sleeps.append,
            clock=self.clock,
        )
        options.update(overrides)
        client = OpenAICompatible(**options)
        self.clients.append(client)
        return client


@pytest.fixture
def make_client(llm_server: LLMServer) -> Iterator[ClientFactory]:
    """A :class:`ClientFactory` for ``llm_server``; its clients are closed after the test."""
    factory = ClientFactory(llm_server)
    yield factory
    for client in factory.clients:
        client.close()
