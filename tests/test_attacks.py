"""Attacks found by a hostile review of the sandbox (issue 10): each case once escaped the cost model.

Every case must end in the exact typed error naming its line, within a bounded CPU time, with a
clock that never advances (so the work budget, not the wall-clock backstop, must stop it).
"""

from __future__ import annotations

import time

import pytest

from robocritics.program import Budget, BudgetError, run_program
from robocritics.scene import Scene

SCENE = Scene.builtin("sorting")
NO_CLOCK = Budget(clock=lambda: 0.0)

ATTACKS = {
    # str.strip(chars) looks every stripped character up in chars: 100k x 100k wide characters took 12 s
    "strip_wide_chars": (
        "s = '\\U0001F601' * 100000\nc = '\\U0001F600' * 99999 + '\\U0001F601'\nx = s.strip(c)\n",
        BudgetError,
        3,
    ),
    "lstrip_ucs2_chars": (
        "s = '\\u0101' * 100000\nc = '\\u0100' * 99999 + '\\u0101'\nx = s.lstrip(c)\n",
        BudgetError,
        3,
    ),
    "rstrip_in_one_statement": (
        "s = 'a' * 100000\nc = '\\U0001F600' * 99999 + 'a'\nx = [s.rstrip(c), s.rstrip(c), s.rstrip(c)]\n",
        BudgetError,
        3,
    ),
}


@pytest.mark.parametrize("name", sorted(ATTACKS))
def test_attack_is_stopped_at_its_line(name: str) -> None:
    source, error, line = ATTACKS[name]
    start = time.process_time()
    with pytest.raises(error) as info:
        run_program(source, SCENE, NO_CLOCK)
    assert time.process_time() - start < 2.0
    assert info.value.line == line
    assert f"line {line}" in str(info.value)
    assert len(str(info.value)) < 4000


def test_strip_with_short_chars_still_works() -> None:
    plan = run_program('s = "  hi \\n" * 1000\nprint(len(s.strip(" \\n")), "--x--".strip("-"))\n', SCENE)
    assert plan.output == ["5996 x"]


@pytest.mark.parametrize("command", ["check", "run"])
def test_cli_long_critic_name_is_quoted_briefly(command: str, tmp_path, capsys) -> None:
    """An unknown critic name was echoed in full: a 100,000-character --critics made a 100 kB error line."""
    from robocritics import cli

    program = tmp_path / "prog.py"
    program.write_text("home()\n")
    first = str(program) if command == "check" else "a task"
    start = time.process_time()
    code = cli.main([command, first, "--critics", "joint_speed," + "x" * 100_000])
    assert time.process_time() - start < 2.0
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert "argument --critics" in err and "longer than 100 characters" in err
    assert len(err) < 400 and "Traceback" not in err
