"""The runtime-level critic: a program that does not run gets a report with one Error naming the line."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest
from llm_fixtures import clean_llm_env, llm_server  # noqa: F401

from robocritics.cli import main
from robocritics.critic import RUNTIME, CriticParams, Flag
from robocritics.pipeline import check
from robocritics.errors import CriticError, GoalError
from robocritics.critic.report import Report
from robocritics.scene import Scene

EXAMPLES = Path(__file__).parent.parent / "examples" / "programs"
pytestmark = pytest.mark.usefixtures("clean_llm_env")


@pytest.fixture(scope="module")
def sorting():
    return Scene.builtin("sorting")


@pytest.mark.parametrize(
    "program, kind, line, words",
    [
        ("import os\nos.system('true')\n", "ProgramError", 1, "import of 'os' is not allowed"),
        ("home()\nmove_to(2.0, 0.0, 0.1)\n", "PlanningError", 2, "out of reach"),
        ("home()\nfor i in range(1000):\n    wait(10)\n", "MotionBudgetError", 3, "needs more than 1,000,000 samples"),
        ("# nothing\n\nx = 1\n", "ProgramError", 3, "made no skill calls"),
    ],
)
def test_a_program_that_does_not_run_gets_one_runtime_error(sorting, program, kind, line, words):
    execution, report = check(program, sorting)
    assert execution is None
    assert isinstance(report, Report) and len(report.verdicts) == 1
    verdict = report.verdicts[0]
    assert verdict.critic == RUNTIME == "runtime" and verdict.flag is Flag.ERROR
    assert verdict.evidence.lines == [line]
    assert words in verdict.message and kind in verdict.message
    assert verdict.details["error"] == kind and verdict.details["line"] == line
    assert verdict.hint
    assert report.score == 0.0 and report.has_errors and not report.passed
    assert Report.model_validate_json(report.to_json()) == report
    assert "no motion (the program did not run)" in report.to_text()


def test_a_program_that_runs_gets_the_critics_and_its_execution(sorting):
    execution, report = check(
        (EXAMPLES / "sorting_careful.py").read_text(), sorting, goals=["green_apple in white_box"]
    )
    assert execution is not None and len(execution.trajectory) == report.samples
    assert report.critics[-1] == "task_outcome" and report.passed


def test_check_keeps_the_error_and_judges_a_given_execution_the_same_way(sorting):
    from robocritics.errors import PlanningError
    from robocritics.pipeline import simulate

    checked = check("home()\nmove_to(2.0, 0.0, 0.1)\n", sorting)
    assert checked.execution is None and isinstance(checked.error, PlanningError) and checked.error.line == 2
    assert checked.report.verdicts[0].details["text"] == str(checked.error)
    program = (EXAMPLES / "sorting_naive.py").read_text()
    from_source = check(program, sorting, critics=["joint_speed", "collision"])
    given = check(simulate(program, sorting), critics=["joint_speed", "collision"])  # only critiqued
    assert from_source.error is None and given.error is None
    assert given.report == from_source.report and given.report.flag_of("joint_speed") is Flag.WARNING


def test_a_critic_that_fails_raises_with_the_run_it_could_not_judge(sorting):
    class Broken:
        name, description = "broken", "fails"

        class Params(CriticParams):
            pass

        def check(self, execution, params):
            raise ZeroDivisionError("oops")

    with pytest.raises(CriticError, match="critic 'broken' failed: ZeroDivisionError") as caught:
        check((EXAMPLES / "sorting_careful.py").read_text(), sorting, critics=[Broken()])
    assert len(caught.value.execution.trajectory) > 0


def test_bad_input_of_the_caller_still_raises_before_simulating(sorting):
    with pytest.raises(CriticError, match="did you mean 'joint_speed'"):
        check("import os\n", sorting, critics=["joint_sped"])
    with pytest.raises(GoalError):
        check("import os\n", sorting, goals=["green_apple in bin"])


def test_check_prints_the_runtime_report_and_exits_1(capsys, tmp_path):
    program = tmp_path / "prog.py"
    program.write_text("home()\nmove_to(2.0, 0.0, 0.1)\n")
    code = main(["check", str(program), "--scene", "sorting"])
    out, err = capsys.readouterr()
    assert code == 1
    assert out.startswith("RoboCritics report: score 0/10 (1 error)")
    assert "runtime" in out and "line 2" in out
    # the error line of before, still on stderr
    assert err.startswith("robocritics: error: PlanningError: line 2: move_to(") and err.count("\n") == 1
    code = main(["check", str(program), "--scene", "sorting", "--json"])
    out, _ = capsys.readouterr()
    assert code == 1 and json.loads(out)["verdicts"][0]["critic"] == "runtime"


def test_check_goal_option(capsys):
    program = str(EXAMPLES / "sorting_careful.py")
    code = main(["check", program, "--goal", "green_apple in white_box", "--goal", "red_apple_1 in brown_box"])
    out, _ = capsys.readouterr()
    assert code == 0 and "task_outcome OK" in out
    code = main(["check", program, "--goal", "green_apple in brown_box"])
    out, _ = capsys.readouterr()
    assert code == 1 and "task_outcome Error" in out and "green_apple ended in white_box" in " ".join(out.split())
    code = main(["check", program, "--goal", "green_aple in white_box"])
    _, err = capsys.readouterr()
    assert code == 2 and "GoalError" in err and "did you mean 'green_apple'" in err
    code = main(["check", program, "--goal", "green_apple at white_box"])
    _, err = capsys.readouterr()
    assert code == 2 and "argument --goal" in err and "use 'in' or 'on'" in err


def _run_with_a_goal_the_program_misses(llm_server, capsys):
    """``robocritics run --goal 'green_apple in white_box'``; the model states the goal with expect(...) and puts
    the green apple in the wrong box; returns (exit status, stdout)."""
    from robocritics.cli.run import add_run_parser, run_command

    source = (EXAMPLES / "sorting_careful.py").read_text().replace(
        'box = brown_box if apple.ripeness == "ripe" else white_box', "box = brown_box"
    ).replace('"brown_box": [(-0.05, -0.05), (0.05, 0.05)]', '"brown_box": [(-0.05, -0.05), (0.05, 0.05), (0.0, 0.0)]')
    source += "\nexpect(green_apple, inside=white_box)\n"
    llm_server.reply(f"```python\n{source}```")
    parser = argparse.ArgumentParser(prog="robocritics")
    add_run_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(
        ["run", "sort the apples", "--scene", "sorting", "--base-url", llm_server.url, "--model", "m",
         "--goal", "green_apple in white_box"]
    )  # fmt: skip
    code = run_command(args)
    out = capsys.readouterr().out
    task_text = llm_server.chat_requests()[0].text
    assert "Goals (checked on the final scene; state each with expect(...)): green_apple in white_box" in task_text
    assert "expect(obj, inside=container)" in task_text  # the rule in the system prompt
    return code, out


def test_run_goal_option_reaches_the_model(llm_server, capsys):
    _run_with_a_goal_the_program_misses(llm_server, capsys)


def test_run_goal_option_fails_a_program_that_misses_it(llm_server, capsys):
    code, out = _run_with_a_goal_the_program_misses(llm_server, capsys)
    assert code == 1 and "task_outcome Error" in out


def test_run_refuses_a_bad_goal_before_asking_the_model(llm_server, capsys):
    from robocritics.cli.run import add_run_parser, run_command

    parser = argparse.ArgumentParser(prog="robocritics")
    add_run_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(
        ["run", "sort", "--scene", "sorting", "--base-url", llm_server.url, "--model", "m", "--goal", "apple in box"]
    )
    assert run_command(args) == 2
    assert "no object 'apple' in scene 'sorting'" in capsys.readouterr().err
    assert llm_server.chat_requests() == []
