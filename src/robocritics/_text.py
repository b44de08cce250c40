"""Text from outside (a controller's messages, names from files, goal names, an LLM's words) made safe to print.

:func:`safe_text` is the one function every path that writes outside text to a terminal, a log or a page uses:
control characters and escape sequences (ANSI CSI/OSC, every C0/C1 control, bidirectional overrides, line
separators, lone surrogates) are shown as visible escapes (``\\x1b``), so text can neither clear the screen, set
the window title, move the cursor to overwrite an earlier line nor forge one of our own lines; and the text is
clipped to a bounded length with a note of how much was cut. :class:`RepeatLimiter` bounds how often lines of one
kind are logged (a flood of tiny packages logs a line per kind and a count, not a line each).
"""

from __future__ import annotations

import re

__all__ = ["safe_text", "RepeatLimiter", "DEFAULT_LIMIT"]

DEFAULT_LIMIT = 300
"""Characters of outside text kept by default (escapes count with their visible length)."""

# Characters a terminal may act on: C0 (except TAB and LF, decided per call), DEL, C1 (0x80-0x9f: 0x9b is an
# 8-bit CSI, 0x9d an OSC), Unicode line/paragraph separators, bidirectional embeddings, overrides and isolates
# (they reorder what is shown), the BOM/zero-width no-break space, and lone surrogates (they cannot be encoded
# to a UTF-8 stream and would raise where the text is printed).
_UNSAFE = "\x00-\x08\x0b-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069\u200e\u200f\u061c\ufeff\ud800-\udfff"
_TOKENS = re.compile(f"([^{_UNSAFE}\t\n]+)|(.)", re.DOTALL)
_NAMED = {"\n": "\\n", "\t": "\\t", "\r": "\\r"}


def _escape(ch: str) -> str:
    if ch in _NAMED:
        return _NAMED[ch]
    code = ord(ch)
    return f"\\x{code:02x}" if code <= 0xFF else f"\\u{code:04x}"


def safe_text(text: object, limit: int = DEFAULT_LIMIT, *, newlines: bool = False, tabs: bool = True) -> str:
    """``text`` made harmless to print: control characters escaped, at most ``limit`` characters kept.

    Every character a terminal could act on is replaced by a visible escape (ESC by ``\\x1b``, a C1 CSI by
    ``\\x9b``, U+202E by ``\\u202e``); a newline is kept only with ``newlines=True`` (else shown as ``\\n``),
    a tab only with ``tabs=True``. Text longer than ``limit`` characters (counting escapes as shown) is cut
    there and ends with ``… [N more characters cut]``, N counted in the original text. The work is bounded by
    ``limit``, not by the length of ``text``. Non-string values are converted with ``str()`` first.
    """
    s = text if isinstance(text, str) else str(text)
    limit = max(0, int(limit))
    out: list[str] = []
    shown = 0
    used = 0
    for m in _TOKENS.finditer(s, 0, min(len(s), limit + 1)):
        piece = m.group(1)
        if piece is not None:  # a run of plain characters
            room = limit - shown
            if len(piece) > room:
                out.append(piece[:room])
                used += room
                break
        else:
            ch = m.group(2)
            keep = (ch == "\n" and newlines) or (ch == "\t" and tabs)
            piece = ch if keep else _escape(ch)
            if shown + len(piece) > limit:
                break
        out.append(piece)
        shown += len(piece)
        used = m.end()
    cut = len(s) - used
    if cut > 0:
        out.append(f"… [{cut:,} more character{'s' if cut != 1 else ''} cut]")
    return "".join(out)


class RepeatLimiter:
    """Lets through the first ``per_kind`` lines of each kind (at most ``kinds`` kinds), counts the rest.

    ``admit(kind)`` is True for a line to log; :meth:`suppressed` tells how many were held back per kind, for
    one summary line. Kinds beyond ``kinds`` are counted under ``"other"``, so a flood of distinct kinds is
    bounded too. Not thread-safe: use it from one thread (or under the caller's lock).
    """

    def __init__(self, per_kind: int = 1, kinds: int = 64) -> None:
        self.per_kind = int(per_kind)
        self.kinds = int(kinds)
        self._seen: dict[object, int] = {}

    def admit(self, kind: object) -> bool:
        if kind not in self._seen and len(self._seen) >= self.kinds:
            kind = "other"
        n = self._seen.get(kind, 0) + 1
        self._seen[kind] = n
        return n <= self.per_kind

    def count(self, kind: object) -> int:
        """Lines of ``kind`` offered so far (let through or not)."""
        return self._seen.get(kind, 0)

    def suppressed(self) -> dict[object, int]:
        """``{kind: lines held back}`` for every kind that had more than ``per_kind`` lines."""
        return {k: n - self.per_kind for k, n in self._seen.items() if n > self.per_kind}
