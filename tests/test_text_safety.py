"""Issue 22, class 6: one escaping/clipping function for text from outside (robocritics._text.safe_text), checked
against a plain character-by-character reference, and the repeat limiter for log lines."""

from __future__ import annotations

import unicodedata

from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics._text import RepeatLimiter, safe_text
from robocritics.cli._common import ONE_LINE_CHARS, one_line

BIDI_AND_SEPARATORS = set("\u2028\u2029\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069\u200e\u200f\u061c\ufeff")


def acts_on_a_terminal(ch: str, newlines: bool, tabs: bool) -> bool:
    if ch == "\n":
        return not newlines
    if ch == "\t":
        return not tabs
    code = ord(ch)
    return code < 0x20 or 0x7F <= code <= 0x9F or ch in BIDI_AND_SEPARATORS or unicodedata.category(ch) == "Cs"


def reference(text: str, limit: int, newlines: bool, tabs: bool) -> str:
    """Character by character: escape, stop before the limit would be passed, note what was cut."""
    out, shown = [], 0
    used = 0
    for ch in text:
        if acts_on_a_terminal(ch, newlines, tabs):
            piece = {"\n": "\\n", "\t": "\\t", "\r": "\\r"}.get(ch) or (
                f"\\x{ord(ch):02x}" if ord(ch) <= 0xFF else f"\\u{ord(ch):04x}")
        else:
            piece = ch
        if shown + len(piece) > limit:
            break
        out.append(piece)
        shown += len(piece)
        used += 1
    cut = len(text) - used
    return "".join(out) + (f"… [{cut:,} more character{'s' if cut != 1 else ''} cut]" if cut else "")


NASTY = st.text(alphabet=st.one_of(
    st.characters(min_codepoint=0, max_codepoint=0xA0),
    st.sampled_from(sorted(BIDI_AND_SEPARATORS) + ["\ud800", "\udfff", "é", "字", "😀"]),
), max_size=300)


@settings(max_examples=400, deadline=None)
@given(NASTY, st.integers(0, 120), st.booleans(), st.booleans())
def test_safe_text_matches_the_character_by_character_reference(text, limit, newlines, tabs):
    got = safe_text(text, limit, newlines=newlines, tabs=tabs)
    assert got == reference(text, limit, newlines, tabs)
    kept = got.split("… [")[0]
    assert len(kept) <= limit
    assert not any(acts_on_a_terminal(c, newlines, tabs) for c in kept)
    got.encode("utf-8")  # printable to a UTF-8 stream (no lone surrogate)


def test_what_an_attacker_sends_is_shown_not_obeyed():
    evil = "\x1b[2J\x1b]0;title\x07\x9b1mDEPLOYED OK\r\n\u202efdp.exe"
    assert safe_text(evil) == "\\x1b[2J\\x1b]0;title\\x07\\x9b1mDEPLOYED OK\\r\\n\\u202efdp.exe"
    assert safe_text("two\nlines", newlines=True) == "two\nlines"
    assert safe_text(12345.5) == "12345.5"


def test_the_work_is_bounded_by_the_limit_not_the_text():
    huge = "x" * 900_000 + "\x1b" * 900_000
    out = safe_text(huge, 100)
    assert out == "x" * 100 + "… [1,799,900 more characters cut]"


def test_cli_messages_are_one_escaped_clipped_line():
    """A 900,000-character frame name or a 100 kB goal name quoted in an error is cut; control characters in it
    are escapes."""
    line = one_line("no frame '" + "\x1b]0;x\x07" + "f" * 900_000 + "'\n  in the trajectory")
    assert "\n" not in line and "\x1b" not in line and "\x07" not in line
    assert len(line) < ONE_LINE_CHARS + 50 and line.endswith("more characters cut]")


def test_the_repeat_limiter_lets_the_first_lines_of_each_kind_through_and_counts_the_rest():
    lim = RepeatLimiter(per_kind=2, kinds=3)
    passed = [lim.admit(k) for k in ["a", "a", "a", "b", "a", "c"]]
    assert passed == [True, True, False, True, False, True]
    assert lim.suppressed() == {"a": 2} and lim.count("a") == 4
    # kinds beyond the bound share one count: a flood of distinct kinds is bounded too
    assert [lim.admit(f"k{i}") for i in range(5)] == [True, True, False, False, False]
    assert lim.suppressed() == {"a": 2, "other": 3}
