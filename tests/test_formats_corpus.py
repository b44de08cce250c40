"""The URScript corpus (tests/data/urscript: PolyScope exports, RoboDK output, hand-written scripts): at least
three quarters judged by the critics, the rest refused naming the construct and its line, none crashing."""

from pathlib import Path

import pytest

from robocritics import Robot, Scene, critique
from robocritics.cli import main
from robocritics.formats import load_motion
from robocritics.formats.urscript import UnsupportedURScript

CORPUS = sorted((Path(__file__).parent / "data" / "urscript").glob("*.script"))
#: the files outside the subset, with the construct and line each must be refused with
REFUSED = {
    "force_insert.script": ("force_mode()", 5),
    "speedl_jog.script": ("speedl()", 3),
    "thread_moving.script": ("thread mover commanding motion (movej at line 5)", 9),
    "urcap_struct.script": ("struct field access", 5),
}


def test_the_corpus_is_at_least_three_quarters_judged():
    assert len(CORPUS) >= 20
    assert set(REFUSED) <= {p.name for p in CORPUS}
    assert (len(CORPUS) - len(REFUSED)) / len(CORPUS) >= 0.75


@pytest.mark.parametrize("path", CORPUS, ids=lambda p: p.name)
def test_each_file_is_judged_or_refused_with_construct_and_line(path):
    robot = Robot.ur3e()
    if path.name in REFUSED:
        construct, line = REFUSED[path.name]
        with pytest.raises(UnsupportedURScript) as info:
            load_motion(path, robot, Scene(), gripper_io=0)
        assert construct in str(info.value) and info.value.line == line
        assert path.read_text().splitlines()[line - 1].strip()  # the line named is a line of the file
        return
    execution = load_motion(path, robot, Scene(), gripper_io=0)
    report = critique(execution)
    assert execution.plan is None and execution.source.startswith(f"URScript {path.name}")
    assert report.samples == len(execution.trajectory) > 10
    lines = path.read_text().splitlines()
    for step in execution.trajectory.steps:  # every sample's command is a motion command on its line
        assert step.skill.split("(")[0] in lines[step.line - 1], (step, lines[step.line - 1])


def test_cli_exit_codes_for_judged_and_refused_files(capsys, tmp_path):
    folder = CORPUS[0].parent
    html = tmp_path / "replay.html"
    assert main(["check", str(folder / "handwritten_square.script"), "--html", str(html)]) == 0
    out = capsys.readouterr().out
    assert "motion from URScript handwritten_square.script" in out and "score 10/10" in out
    assert "handwritten_square.script" in html.read_text()
    assert main(["check", str(folder / "handwritten_square.script"), "--goal", "green_apple in white_box", "--scene", "sorting"]) == 2
    assert "goals cannot be checked" in capsys.readouterr().err
    unreachable = tmp_path / "far.script"
    unreachable.write_text("movej([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])\nmovel(p[0.9, 0, 0.2, 0, 3.14, 0])\n")
    assert main(["check", str(unreachable)]) == 1  # the runtime critic's Error, naming the line
    captured = capsys.readouterr()
    assert "ERROR    runtime" in captured.out and "PlanningError: line 2: movel" in captured.err
    assert main(["check", str(folder / "speedl_jog.script")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["robocritics: error: UnsupportedURScript: line 3: unsupported URScript: speedl() (velocity control)"]
