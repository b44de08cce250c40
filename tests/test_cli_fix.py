"""``robocritics fix``: the diff, the changes and the new report; exit 0 when no Error is left."""

from __future__ import annotations

import re
from pathlib import Path

from robocritics.cli.main import main
from robocritics.repair import repair

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


CHANGE_LINE = re.compile(r"^changed: (\w+) \(line (\d+)\): (.+) -- (.+) \[([+-]\d+\.\d\d) s\]$", re.M)


def test_fix_prints_every_change_with_critic_line_what_why_and_cost(capsys):
    # recycling_naive needs several kinds of repair; each printed change names all five fields
    path = PROGRAMS / "recycling_naive.py"
    goals = ["coffee_cup in trash_bin", "food_container in trash_bin", "water_bottle in trash_bin"]
    code = main(["fix", str(path), *[a for g in goals for a in ("--goal", g)]])
    text = capsys.readouterr().out
    assert code == 0, text
    printed = CHANGE_LINE.findall(text)
    expected = repair(path.read_text(), "recycling", goal=goals).changes
    assert [(c, int(ln), w, y, float(s)) for c, ln, w, y, s in printed] == [
        (c.critic, c.line, c.what, c.why, round(c.cost_s, 2)) for c in expected
    ]
    assert {"collision", "end_effector_pose"} <= {c for c, *_ in printed}


def test_fix_repairs_a_program_that_does_not_run(tmp_path, capsys):
    src = tmp_path / "sorting_high.py"
    src.write_text("move_above(green_apple, height=0.42)\nmove_linear(green_apple)\nclose_gripper()\nmove_up(0.12)\n"
                   "move_above(white_box, 0.1)\nopen_gripper()\nhome()\n")  # fmt: skip
    assert main(["check", str(src), "--scene", "sorting"]) == 1  # the runtime critic's Error
    capsys.readouterr()
    code = main(["fix", str(src), "--scene", "sorting", "--goal", "green_apple in white_box"])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "changed: runtime (line 1): target lowered by" in text and "-move_above(green_apple, height=0.42)" in text


def test_fix_of_a_program_the_sandbox_rejects_prints_the_runtime_error_and_exits_1(tmp_path, capsys):
    src = tmp_path / "broken.py"
    src.write_text("move_to(0.3, 0.0\n")
    assert main(["fix", str(src), "--scene", "sorting"]) == 1
    text = capsys.readouterr().out
    assert "(no change)" in text and "runtime" in text and "syntax error" in text


def test_fix_writes_the_best_program_found_and_says_what_is_left(tmp_path, capsys):
    # the wrong box: the goal cannot be met, yet the repaired program (faster faults fixed) is written
    out = tmp_path / "best.py"
    code = main(["fix", str(PROGRAMS / "sorting_naive.py"), "--goal", "green_apple in brown_box", "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 1
    assert out.read_text() != (PROGRAMS / "sorting_naive.py").read_text()
    assert re.search(r"^left: task_outcome ERROR: .*green_apple", text, re.M), text
    assert re.search(r"^repair: \d+ change\(s\), score \d+/10 -> \d+/10, cycle [\d.]+ s -> [\d.]+ s; 1 Error\(s\)", text, re.M)
