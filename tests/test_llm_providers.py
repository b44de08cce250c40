"""Language-model providers are plugins: the built-in one is registered through the hook, as a third party's is."""

from __future__ import annotations

import pytest

from robocritics import hookimpl
from robocritics.critic.plugins import pm
from robocritics.errors import LLMError
from robocritics.llm.providers import DEFAULT_PROVIDER, provider, providers
from robocritics.llm.providers.openai_compatible import OpenAICompatible


def test_the_builtin_provider_is_registered_through_the_hook_and_builds_a_client():
    assert DEFAULT_PROVIDER in providers()
    client = provider()(base_url="http://127.0.0.1:9/v1", model="tiny")  # built, never connected
    try:
        assert isinstance(client, OpenAICompatible) and client.name == "tiny"
    finally:
        client.close()


def test_a_plugin_registers_a_provider_beside_the_builtin_one():
    class Echo:
        name = "echo"

        def complete(self, messages, **kw):
            return messages[-1]["content"]

    class Plugin:
        @hookimpl
        def register_llm_providers(self, register):
            register("echo", Echo)
            register(DEFAULT_PROVIDER, Echo)  # a name already taken: the first registration wins

    plugin = Plugin()
    pm.register(plugin, name="test-echo-provider")
    try:
        found = providers()
        assert found["echo"] is Echo and found[DEFAULT_PROVIDER] is not Echo
        assert provider("echo")().complete([{"role": "user", "content": "hi"}]) == "hi"
    finally:
        pm.unregister(plugin)
    assert "echo" not in providers()


def test_an_unknown_provider_names_the_registered_ones():
    with pytest.raises(LLMError, match="no language-model provider 'nope' \\(registered: .*openai-compatible"):
        provider("nope")
