"""The `robocritics` command: `critics` listing, `check` input errors and exit codes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from robocritics import cli
from robocritics.critic import BUILTIN_CRITICS, CriticParams, Flag, Verdict, register, unregister


def run(capsys, *argv):
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_critics_lists_name_package_and_description(capsys):
    code, out, err = run(capsys, "critics")
    assert code == 0
    lines = out.splitlines()
    assert lines[0].split() == ["NAME", "PACKAGE", "DESCRIPTION"]
    for name in BUILTIN_CRITICS:
        row = next(l for l in lines if l.startswith(name + " "))
        assert "robocritics 0.1.0" in row


def test_critics_verbose_shows_parameters(capsys):
    code, out, _ = run(capsys, "critics", "-v")
    assert code == 0
    assert "warn_speed_m_s = 1.0" in out and "d_min_m = 0.025" in out


def test_critics_json(capsys):
    code, out, _ = run(capsys, "critics", "--json")
    data = json.loads(out)
    names = [c["name"] for c in data["critics"]]
    assert names[:5] == list(BUILTIN_CRITICS)
    assert data["critics"][0]["package"] == "robocritics"
    assert "warn_fraction" in data["critics"][0]["params"]
    assert data["failed_plugins"] == []


def test_help_and_usage_errors(capsys):
    assert cli.main(["--help"]) == 0
    assert "check" in capsys.readouterr().out
    assert cli.main([]) == 2
    assert cli.main(["nonsense"]) == 2
    capsys.readouterr()
    assert cli.main(["check", "x.py", "--rate", "-5"]) == 2
    err = capsys.readouterr().err
    assert err == (
        "robocritics check: error: argument --rate: the sample rate must lie in [25, 500] Hz (sparser sampling "
        "hides fast motion from the critics), got -5 (see robocritics check --help)\n"
    )


def test_check_missing_program_is_exit_2_with_one_line(capsys, tmp_path):
    code, out, err = run(capsys, "check", str(tmp_path / "nope.py"))
    assert code == 2 and out == ""
    assert err.strip().count("\n") == 0
    assert err.startswith("robocritics: error: no such program file")


@pytest.mark.parametrize(
    "args, message",
    [
        (["--critics", "joint_sped"], "unknown critic 'joint_sped'; did you mean 'joint_speed'?"),
        (["--scene", "sortng"], "did you mean 'sorting'?"),
        (["--params", "PARAMS_BAD_JSON"], "is not valid JSON"),
        (["--params", "PARAMS_NOT_OBJECT"], "must hold a JSON object"),
        (["--params", "PARAMS_BAD_FIELD"], "critic 'joint_speed'"),
    ],
)
def test_check_bad_input_is_exit_2(capsys, tmp_path, args, message):
    program = tmp_path / "prog.py"
    program.write_text("home()\n")
    files = {
        "PARAMS_BAD_JSON": "{not json",
        "PARAMS_NOT_OBJECT": "[1, 2]",
        "PARAMS_BAD_FIELD": json.dumps({"joint_speed": {"warn_speed_m_s": "fast"}}),
    }
    args = list(args)
    for i, a in enumerate(args):
        if a in files:
            path = tmp_path / "params.json"
            path.write_text(files[a])
            args[i] = str(path)
    code, out, err = run(capsys, "check", str(program), *args)
    assert code == 2, err
    assert message in err and err.strip().count("\n") == 0


def test_subcommand_registry_accepts_new_commands(capsys):
    @cli.subcommand("hello")
    def _build(sub):
        p = sub.add_parser("hello")
        p.add_argument("--fail", action="store_true")

        def handler(args):
            if args.fail:
                raise cli.UsageError("no greeting today")
            print("hello")
            return 0

        p.set_defaults(func=handler)

    try:
        assert run(capsys, "hello")[:2] == (0, "hello\n")
        code, _, err = run(capsys, "hello", "--fail")
        assert code == 2 and "no greeting today" in err
    finally:
        del cli.SUBCOMMANDS["hello"]


EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "programs"


def test_check_simulates_and_critiques_a_program(capsys, tmp_path):
    program = tmp_path / "prog.py"
    program.write_text("move_to(0.3, 0.0, 0.25)\nmove_to(0.25, 0.1, 0.2)\nhome()\n")
    code, out, err = run(capsys, "check", str(program), "--scene", "sorting", "--json", "--rate", "125")
    data = json.loads(out)
    assert [v["critic"] for v in data["verdicts"]][:5] == list(BUILTIN_CRITICS)
    assert code == (1 if any(v["flag"] == "ERROR" for v in data["verdicts"]) else 0), err
    code, out, err = run(capsys, "check", str(program), "--scene", "sorting", "--critics", "joint_speed,pinch_point")
    assert out.startswith("RoboCritics report: score ")
    assert "joint_speed" in out and "collision" not in out


def test_check_exit_status_and_score_of_the_example_programs(capsys):
    five = ",".join(BUILTIN_CRITICS)
    code, out, _ = run(capsys, "check", str(EXAMPLES / "sorting_careful.py"), "--critics", five)
    assert code == 0 and out.startswith("RoboCritics report: score 10/10 (all passed); ")
    code, out, _ = run(capsys, "check", str(EXAMPLES / "sorting_naive.py"), "--critics", five)
    assert code == 1 and out.startswith("RoboCritics report: score 3/10 (3 errors, 1 warning); ")


class _AlwaysError:
    name = "house_rule"
    description = "a site rule that this program breaks"
    Params = CriticParams

    def check(self, trajectory, scene, params):
        return Verdict(critic=self.name, flag=Flag.ERROR, message="broken", hint="fix it", value=1.0, threshold=0.0, unit="")


def test_a_critic_beside_the_score_still_fails_check(capsys):
    register(_AlwaysError())
    try:
        code, out, _ = run(capsys, "check", str(EXAMPLES / "sorting_careful.py"))
    finally:
        unregister("house_rule")
    assert code == 1
    assert out.startswith("RoboCritics report: score 10/10 (1 error")
    assert "beside the score: " in out and "house_rule Error" in out


def test_a_program_that_does_not_run_is_a_runtime_error_report_exit_1(capsys, tmp_path):
    program = tmp_path / "prog.py"
    program.write_text("import os\nos.system('true')\n")
    code, out, err = run(capsys, "check", str(program), "--scene", "sorting")
    assert code == 1  # a report with the runtime critic's Error, like any other Error
    assert "runtime" in out and "ERROR" in out and "line 1" in out
    assert err.startswith("robocritics: error: ProgramError") and err.strip().count("\n") == 0
