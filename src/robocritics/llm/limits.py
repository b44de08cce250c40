"""Every size and time limit on what the language model sends and what robocritics sends back, in one place.

An LLM's reply is untrusted input: it is bounded in time (one deadline per
request), in bytes (on the wire and after decompression), in nesting (JSON)
and in characters (the reply text), before anything reads it. What is sent
back, printed or stored is bounded too, so a long reply or error text is never
amplified. Each limit below says why it has its value.

Text helpers: :func:`clean_text` replaces lone surrogates (which cannot be
encoded as UTF-8: printing, storing or sending them would crash) and
:func:`cut_text` shortens a text to a limit, saying how much was left out.
"""

from __future__ import annotations

import re

__all__ = [
    "DEFAULT_DEADLINE_S",
    "DEFAULT_MAX_TOKENS",
    "MIN_REPLY_TOKENS",
    "CHARS_PER_TOKEN",
    "MAX_FEEDBACK_CHARS",
    "MAX_JSON_CONTAINERS",
    "MAX_JSON_DEPTH",
    "MAX_MESSAGE_CHARS",
    "MAX_PRINTED_CHARS",
    "MAX_QUERY_TERMS",
    "MAX_REPLY_CHARS",
    "MAX_REQUEST_BYTES",
    "MAX_RESPONSE_BYTES",
    "MAX_STORED_FEEDBACK_CHARS",
    "MAX_STORED_PROGRAM_CHARS",
    "MAX_TASK_CHARS",
    "clean_text",
    "cut_text",
]

# --- one HTTP request ------------------------------------------------------------------------------

#: Seconds one LLM request may take in all (connecting, sending, waiting, reading, retries and their
#: pauses): a local model writing a long program at 10 tokens/s needs a few minutes, never more.
DEFAULT_DEADLINE_S = 300.0

#: Bytes of a response body, counted on the wire and again after decompression: an embeddings reply for
#: 64 texts of 4096 dimensions is about 6 MB of JSON; 8 MiB of JSON becomes at most ~200 MB of Python objects.
MAX_RESPONSE_BYTES = 8 * 1024 * 1024

#: Bytes of a request body: the loop's messages are bounded far below this; a larger request is a bug.
MAX_REQUEST_BYTES = 4 * 1024 * 1024

#: Nesting depth of a JSON reply: OpenAI's replies nest 5 deep; Python's decoder recurses per level.
MAX_JSON_DEPTH = 64

#: Arrays and objects in one JSON reply: 64 embeddings need ~200; each empty one costs ~60 bytes of memory.
MAX_JSON_CONTAINERS = 100_000

#: Characters of one chat reply: the longest program the sandbox accepts and some prose around it; finding the
#: program in a reply this long costs at most a few parses of it (about a second of CPU at worst).
MAX_REPLY_CHARS = 120_000

#: Tokens a chat reply may have (``max_tokens`` sent with every request): the longest example program
#: (breakfast, careful: 40 lines) is about 450 tokens; twice that plus some prose fits. Without a cap a small
#: model can generate until the deadline, and the server keeps generating for a request nobody waits for.
DEFAULT_MAX_TOKENS = 1024

#: Fewest reply tokens a prompt is fitted to leave free in a small context: a short program and no prose.
MIN_REPLY_TOKENS = 256

#: Characters per token of the cheap prompt-size estimate: BPE tokenizers of small open models give 3.2-4
#: characters per token on the system prompt (code, numbers, English); 3 over-estimates, so a fitted prompt fits.
CHARS_PER_TOKEN = 3.0

# --- what the loop sends and stores ------------------------------------------------------------------

#: Characters of a task description: a task is a few sentences; this also bounds every stored request.
MAX_TASK_CHARS = 4_000

#: Characters of one user or assistant message the loop (re)sends: ~8k tokens, a small model's context.
MAX_MESSAGE_CHARS = 32_000

#: Characters of runtime or critic feedback in one message: a few screens, enough to act on.
MAX_FEEDBACK_CHARS = 8_000

#: Characters of a program stored in the interaction memory: the sandbox's limit, so every program that ran fits.
MAX_STORED_PROGRAM_CHARS = 100_000

#: Characters of feedback stored in the interaction memory (examples show 600 of them).
MAX_STORED_FEEDBACK_CHARS = 20_000

#: Distinct words of a memory query that are looked up: a task has a few dozen.
MAX_QUERY_TERMS = 64

#: Characters of a program or reply the command line prints: a few screens; the rest is summarised.
MAX_PRINTED_CHARS = 20_000

# --- text helpers ------------------------------------------------------------------------------------

_SURROGATE = re.compile("[\ud800-\udfff]")


def clean_text(text: str) -> str:
    """``text`` with every lone surrogate (U+D800–U+DFFF) replaced by U+FFFD.

    Such code points arrive from JSON escapes like ``"\\ud800"`` or from
    undecodable command-line bytes; no UTF-8 stream, SQLite database or
    HTTP body can hold them. Linear time; returns ``text`` itself when clean.
    """
    if text.isascii():
        return text
    return _SURROGATE.sub("\ufffd", text)


def cut_text(text: str, max_chars: int, what: str = "characters") -> str:
    """``text`` if it has at most ``max_chars`` characters, else its start and a note of how much was cut.

    The result never exceeds ``max_chars`` (for ``max_chars`` >= 80).
    """
    if len(text) <= max_chars:
        return text
    note = f"\n[... {len(text) - max_chars:,} more {what} not shown]"
    keep = max(max_chars - len(note) - 20, 0)
    note = f"\n[... {len(text) - keep:,} more {what} not shown]"
    return text[:keep] + note
