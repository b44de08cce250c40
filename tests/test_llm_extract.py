"""extract_code: finding the Python program in the many shapes of an LLM reply."""

from __future__ import annotations

import ast

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics.llm.prompts import extract_code

PROGRAM = """\
apple = scene.find("green_apple")
lib.move_to(apple.x, apple.y, apple.z + 0.1)
lib.close_gripper()
"""

HELPER = """\
def move_above_pos(pos, height=0.1):
    lib.move_to(pos[0], pos[1], pos[2] + height)
"""


@pytest.mark.parametrize(
    "reply",
    [
        f"```python\n{PROGRAM}```",
        f"```py\n{PROGRAM}```",
        f"```Python3\n{PROGRAM}```",
        f'```python title="pick.py"\n{PROGRAM}```',
        f"```{{python}}\n{PROGRAM}```",
        f"~~~python\n{PROGRAM}~~~",
        f"````python\n{PROGRAM}````",
        f"```\n{PROGRAM}```",
        f"~~~\n{PROGRAM}~~~",
        f"Here is the program:\n\n```python\n{PROGRAM}```\n\nIt picks up the apple.",
        f"```python\n{PROGRAM}",  # unterminated final fence
        f"Explanation first.\n```python\n{PROGRAM}\n\n",  # unterminated, trailing blank lines
        f"```python   \n\n\n{PROGRAM}\n\n```   ",  # blank lines and trailing spaces around
        f"1. The code:\n\n    ```python\n    {PROGRAM.replace(chr(10), chr(10) + '    ').rstrip()}\n    ```\n",  # indented in a list
        f"```python\r\n{PROGRAM.replace(chr(10), chr(13) + chr(10))}```\r\n",  # Windows line ends
        PROGRAM,  # no fence, the whole reply is code
        f"Here is the program:\n{PROGRAM}",  # no fence, prose before
        f"{PROGRAM}\nThis moves above the apple and grasps it.",  # no fence, prose after
        f"Sure, here you go:\n{PROGRAM}\nLet me know if you need changes!",
    ],
)
def test_the_program_is_found(reply):
    assert extract_code(reply) == PROGRAM


def test_a_fence_in_the_middle_of_a_line_does_not_open_a_block():
    reply = f"Sure! ```python\n{PROGRAM}```"
    # The only fence line is the closing one, which opens an (empty, unterminated) block;
    # the code is then taken from the prose.
    assert extract_code(reply) == PROGRAM


def test_several_python_blocks_are_joined_in_order():
    reply = f"First a helper:\n```python\n{HELPER}```\nThen the task:\n```python\n{PROGRAM}```\n"
    assert extract_code(reply) == HELPER + "\n" + PROGRAM
    ast.parse(extract_code(reply))


def test_python_blocks_win_over_untagged_and_other_languages():
    reply = (
        "Output will look like:\n```\nmoved to (0.1, 0.2, 0.3)\n```\n"
        'Scene:\n```json\n{"objects": []}\n```\n'
        f"Program:\n```python\n{PROGRAM}```\n"
        "Run it with:\n```bash\npython pick.py\n```\n"
    )
    assert extract_code(reply) == PROGRAM


def test_untagged_blocks_that_parse_win_over_ones_that_do_not():
    reply = f"It prints:\n```\nMoving... done (3 steps)\n```\nCode:\n```\n{PROGRAM}```"
    assert extract_code(reply) == PROGRAM


def test_an_untagged_block_with_a_syntax_error_is_still_returned():
    broken = "lib.move_to(0.1, 0.2\nlib.close_gripper()\n"
    assert extract_code(f"```\n{broken}```") == broken


def test_a_python_block_with_a_syntax_error_is_returned_for_the_sandbox_to_report():
    broken = "for i in range(3)\n    lib.open_gripper()\n"
    assert extract_code(f"```python\n{broken}```") == broken


def test_only_other_languages_means_no_program():
    assert extract_code("```bash\npip install robocritics\n```") is None
    assert extract_code('```json\n{"move_to": [1, 2, 3]}\n```') is None


@pytest.mark.parametrize(
    "reply",
    [
        "",
        "   \n\n",
        "I cannot help with that.",
        "Done",
        "The program is complete and needs no further changes.",
        "```python\n```",
        "```python\n\n\n```\nNo changes needed.",
        "x = 1",  # parses, but calls nothing
    ],
)
def test_no_program(reply):
    assert extract_code(reply) is None


def test_none_and_non_strings_give_none():
    assert extract_code(None) is None  # type: ignore[arg-type]


def test_backticks_inside_the_program_do_not_end_it_early():
    program = 'note = "use ``` for code"\nlib.say(note)\n'
    assert extract_code(f"```python\n{program}```") == program


def test_a_shorter_fence_does_not_close_a_longer_one():
    program = 'doc = """\n```\n"""\nlib.say(doc)\n'
    assert extract_code(f"````python\n{program}````") == program


def test_tilde_and_backtick_fences_do_not_close_each_other():
    program = 'doc = """\n```\n"""\nlib.say(doc)\n'
    assert extract_code(f"~~~python\n{program}~~~") == program


def test_indentation_inside_the_program_is_kept():
    assert (
        extract_code(f"```python\n{HELPER}\nmove_above_pos((0, 0, 0))\n```") == HELPER + "\nmove_above_pos((0, 0, 0))\n"
    )


# -- property-based ----------------------------------------------------------------

identifiers = st.from_regex(r"[a-z_][a-z0-9_]{0,8}", fullmatch=True).filter(
    lambda s: s.isidentifier() and not __import__("keyword").iskeyword(s)
)
numbers = st.floats(min_value=-1, max_value=1, allow_nan=False).map(lambda x: f"{x:.3f}")
calls = st.builds(lambda f, args: f"lib.{f}({', '.join(args)})", identifiers, st.lists(numbers, max_size=3))
assignments = st.builds(lambda name, value: f"{name} = {value}", identifiers, numbers)
programs = (
    st.lists(st.one_of(calls, assignments), min_size=1, max_size=8)
    .filter(lambda lines: any(line.startswith("lib.") for line in lines))
    .map(lambda lines: "\n".join(lines) + "\n")
)
prose = st.lists(
    st.sampled_from(
        [
            "Here is the updated program.",
            "I reduced the speed near the box.",
            "This avoids the cup!",
            "Note: the gripper opens first.",
            "Let me know if you need anything else.",
            "",
        ]
    ),
    max_size=3,
).map("\n".join)
fences = st.sampled_from(["```python", "```py", "```", "~~~python", "~~~", "````python"])


@settings(max_examples=200, deadline=None)
@given(before=prose, program=programs, after=prose, fence=fences, terminated=st.booleans())
def test_any_fenced_program_surrounded_by_prose_is_found(before, program, after, fence, terminated):
    closing = fence.rstrip("python") if terminated else ""
    reply = f"{before}\n{fence}\n{program}{closing}\n{after if terminated else ''}"
    assert extract_code(reply) == program


@settings(max_examples=200, deadline=None)
@given(programs=st.lists(programs, min_size=1, max_size=4), gaps=prose)
def test_all_python_blocks_are_joined_in_order(programs, gaps):
    reply = "".join(f"{gaps}\n```python\n{p}```\n" for p in programs)
    assert extract_code(reply) == "\n".join(programs)


@settings(max_examples=200, deadline=None)
@given(before=prose, program=programs, after=prose)
def test_unfenced_code_between_prose_is_found(before, program, after):
    assert extract_code(f"{before}\n{program}\n{after}") == program


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=300))
def test_arbitrary_text_never_crashes_and_any_result_is_tidy(text):
    code = extract_code(text)
    assert code is None or (code.endswith("\n") and code.strip() and not code.startswith("\n"))
