"""pytest fixtures for the LLM tests: a fresh ``LLMServer`` and clients pointed at it.

Import the fixtures into a test module: ``from llm_fixtures import llm_server, make_client, sleeps``.
Modules that build clients from the environment should also use ``clean_llm_env``
(e.g. ``pytestmark = pytest.mark.usefixtures("clean_llm_env")``), so a developer's
real configuration or API key never reaches a test server.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest
from llm_server import LLMServer

from robocritics.llm.client import OpenAICompatible

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


@pytest.fixture
def sleeps() -> list[float]:
    """The pauses (s) that clients made by ``make_client`` asked for between retries, in order."""
    return []


@pytest.fixture
def make_client(llm_server: LLMServer, sleeps: list[float]) -> Iterator[Callable[..., OpenAICompatible]]:
    """Factory of ``OpenAICompatible`` clients for ``llm_server`` that do not really wait between retries.

    Each pause a client would sleep is appended to ``sleeps`` instead, so retry
    timing is asserted exactly and costs no time. Defaults: model ``test-chat``,
    embedding model ``test-embed``, timeout 2 s, backoff base 0.01 s capped at
    0.05 s; any keyword overrides them (``sleep=time.sleep`` for real waits).
    Clients are closed after the test.
    """
    clients: list[OpenAICompatible] = []

    def make(**overrides) -> OpenAICompatible:
        options = dict(
            base_url=llm_server.url,
            model=TEST_MODEL,
            embedding_model=TEST_EMBEDDING_MODEL,
            api_key="sk-test-not-a-secret",
            timeout_s=2.0,
            backoff_base_s=0.01,
            backoff_max_s=0.05,
            sleep=sleeps.append,
        )
        options.update(overrides)
        client = OpenAICompatible(**options)
        clients.append(client)
        return client

    yield make
    for client in clients:
        client.close()
