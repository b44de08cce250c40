"""'Made no skill calls' points at the first line of code, not at a comment on line 1 (issue 11)."""

from __future__ import annotations

import pytest

from robocritics.errors import ProgramError
from robocritics.llm.prompts import runtime_feedback
from robocritics.scene import Scene
from robocritics.pipeline import simulate


@pytest.mark.parametrize(
    "program, line",
    [
        ("x = 1\n", 1),
        ("# sort the apples\n# carefully\n\nx = 1\nprint(x)\n", 4),
        ("\n\n    \n# only a note\nspeed = 0.3\n", 5),
    ],
)
def test_no_skill_calls_is_reported_at_the_first_line_of_code(program, line):
    with pytest.raises(ProgramError, match="made no skill calls") as caught:
        simulate(program, Scene.builtin("sorting"))
    assert caught.value.line == line
    feedback = runtime_feedback(caught.value, program=program)
    assert f"at line {line}" in feedback
    assert program.splitlines()[line - 1].strip() in feedback  # the quoted line is code, not the comment
