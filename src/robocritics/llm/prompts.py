"""Prompts for the language model, and reading its replies.

``extract_code`` finds the Python program in a model's reply.
"""

from __future__ import annotations

import ast
import re
import textwrap
from dataclasses import dataclass

__all__ = ["extract_code"]

#: Info-string words that mark a fenced block as Python (compared lower-case).
PYTHON_TAGS = frozenset({"python", "py", "python3", "py3", "ipython", "ipython3"})

# An opening fence: indentation, 3+ backticks or tildes, then an optional info string.
# Backtick fences may not have a backtick in their info string (CommonMark).
_OPENING = re.compile(r"^(?P<indent>[ \t]*)(?P<fence>`{3,}|~{3,})(?P<info>.*)$")

# With no fences: try the whole reply, then spans that drop up to this many lines of prose at either end.
_MAX_TRIMMED_LINES = 20


@dataclass(frozen=True)
class _Block:
    language: str  # "" when untagged
    text: str


def extract_code(reply: str) -> str | None:
    """Return the Python program in an LLM ``reply``, or None if there is none.

    Rules, in order:

    1. Fenced blocks (```` ``` ```` or ``~~~``, any indentation, closed by a
       fence of the same character at least as long; a final block left open
       runs to the end of the reply). Blocks tagged ``python``/``py``/
       ``python3``/``py3``/``ipython`` win: all of them are joined in order,
       separated by a blank line, since models often split one program into
       several blocks.
    2. Otherwise untagged blocks: those that parse as Python are joined in
       order; if none parses, all untagged blocks are joined anyway so the
       sandbox can report the syntax error with a line number.
    3. Blocks tagged with another language (``json``, ``bash``, ``text`` ...)
       are never returned.
    4. No fences at all: the whole reply if it parses with ``ast`` and
       contains a call; else the longest span that does after dropping up to
       20 lines of prose at its start and/or end.

    Empty blocks are ignored. The result has its common indentation removed,
    no leading or trailing blank lines, and ends with one newline.
    """
    if not isinstance(reply, str) or not reply.strip():
        return None
    blocks, saw_fence = _fenced_blocks(reply)
    if saw_fence:
        python = [b.text for b in blocks if b.language in PYTHON_TAGS]
        if python:
            return _join(python)
        untagged = [b.text for b in blocks if not b.language]
        if untagged:
            parsing = [text for text in untagged if _parses(text)]
            return _join(parsing or untagged)
        if blocks:
            return None  # only blocks in other languages
        # Fences with nothing inside: fall through and look at the prose itself.
    return _bare_code(reply)


def _fenced_blocks(reply: str) -> tuple[list[_Block], bool]:
    """Non-empty fenced blocks in order, and whether any fence was seen at all."""
    lines = reply.splitlines()
    blocks: list[_Block] = []
    saw_fence = False
    i = 0
    while i < len(lines):
        opening = _OPENING.match(lines[i])
        if opening is None or (opening["fence"][0] == "`" and "`" in opening["info"]):
            i += 1
            continue
        saw_fence = True
        fence = opening["fence"]
        closing = re.compile(rf"^[ \t]*{re.escape(fence[0])}{{{len(fence)},}}[ \t]*$")
        body: list[str] = []
        i += 1
        while i < len(lines) and not closing.match(lines[i]):
            body.append(lines[i])
            i += 1
        i += 1  # skip the closing fence (or run past the end of an unterminated block)
        text = _tidy("\n".join(body))
        if text:
            blocks.append(_Block(language=_language(opening["info"]), text=text))
    return blocks, saw_fence


def _language(info: str) -> str:
    """The language word of a fence's info string: '```Python title="x"' -> 'python', '```{py}' -> 'py'."""
    words = info.strip().split()
    if not words:
        return ""
    return words[0].strip("{}.").lower()


def _bare_code(reply: str) -> str | None:
    lines = _tidy(reply).splitlines()
    n = len(lines)
    trim = min(_MAX_TRIMMED_LINES, max(n - 1, 0))
    spans = sorted(
        ((start, end) for start in range(trim + 1) for end in range(n - trim, n + 1) if end > start),
        key=lambda span: (span[0] - span[1], span[0]),  # longest first, then earliest
    )
    for start, end in spans:
        candidate = _tidy("\n".join(lines[start:end]))
        if candidate and _is_code(candidate):
            return candidate + "\n"
    return None


def _is_code(text: str) -> bool:
    """Parses as Python and calls something (bare prose like 'Done' parses as a name but calls nothing)."""
    try:
        tree = ast.parse(text)
    except (SyntaxError, ValueError):
        return False
    return any(isinstance(node, ast.Call) for node in ast.walk(tree))


def _parses(text: str) -> bool:
    try:
        ast.parse(text)
    except (SyntaxError, ValueError):
        return False
    return True


def _tidy(text: str) -> str:
    """Dedent, drop leading/trailing blank lines and trailing spaces."""
    text = textwrap.dedent(text)
    lines = [line.rstrip() for line in text.splitlines()]
    while lines and not lines[0]:
        lines.pop(0)
    while lines and not lines[-1]:
        lines.pop()
    return "\n".join(lines)


def _join(texts: list[str]) -> str:
    return "\n\n".join(texts) + "\n"
