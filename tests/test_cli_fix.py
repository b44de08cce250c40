"""``robocritics fix``: the diff, the changes and the new report; exit 0 when no Error is left."""

from __future__ import annotations

from pathlib import Path

from robocritics.cli.main import main

PROGRAMS = Path(__file__).resolve().parents[1] / "examples" / "programs"


def test_fix_repairs_sorting_writes_the_program_and_exits_0(tmp_path, capsys):
    out = tmp_path / "fixed.py"
    code = main(["fix", str(PROGRAMS / "sorting_naive.py"), "--goal", "green_apple in white_box", "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "+move_down(0.1)" in text and "-move_down(0.2)" in text
    assert "changed: space_usage (line 11)" in text
    assert "move_down(0.1)" in out.read_text()
    assert main(["check", str(out), "--scene", "sorting"]) == 0


def test_fix_exits_1_when_an_error_is_left(capsys):
    # the wrong box: no edit of heights or speeds can put the apple where the goal says
    code = main(["fix", str(PROGRAMS / "sorting_naive.py"), "--goal", "green_apple in brown_box"])
    assert code == 1
    assert "task_outcome" in capsys.readouterr().out


def test_fix_usage_errors_exit_2(tmp_path, capsys):
    assert main(["fix", str(tmp_path / "missing.py")]) == 2
    assert main(["fix", str(PROGRAMS / "sorting_naive.py"), "--goal", "green_apple in nowhere"]) == 2
    assert main(["fix", str(PROGRAMS / "sorting_naive.py"), "-o", str(tmp_path / "no" / "dir.py")]) == 2
