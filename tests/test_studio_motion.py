"""The studio's handling of motion from other tools (issue 25) without a browser: the worker's child judges a
URScript file with the installation's options exactly as `load_motion` does in-process, and what the studio does
not offer for imported motion is refused with the reason. The page is in test_studio_motion_browser.py."""

from __future__ import annotations

from pathlib import Path

import pytest

from robocritics import Scene, critique
from robocritics.cli import main
from robocritics.formats import load_motion
from robocritics.viz.studio import Studio, StudioError

SCRIPT = Path(__file__).resolve().parent / "data" / "urscript" / "handwritten_square.script"
START_Q = (-0.3, -1.7, 1.5, -1.4, -1.57, 0.2)


def test_the_worker_judges_a_script_with_its_options_as_load_motion_does():
    """The same trajectory (by hash) and verdicts as the in-process check, with a start pose and TCP given, and a
    different trajectory than without them (the options reach the child)."""
    options = {"start_q": START_Q, "tcp": (0.0, 0.0, 0.12, 0.0, 0.0, 0.0)}
    expected = load_motion(SCRIPT, scene=Scene(), **options)
    report = critique(expected)
    with Studio(Scene(), motion=SCRIPT, motion_options=options) as studio:
        assert studio.program == SCRIPT.read_text()
        revision = studio.run(studio.program)
        assert revision.error is None
        assert revision.trajectory_hash == expected.trajectory.content_hash()
        assert revision.execution.source == expected.source
        assert {v.critic: v.flag for v in revision.report.verdicts} == {v.critic: v.flag for v in report.verdicts}
        studio.motion_options = {}
        assert studio.run(studio.program).trajectory_hash != revision.trajectory_hash


def test_what_the_studio_refuses_for_imported_motion(tmp_path):
    with pytest.raises(StudioError, match="goals cannot be checked"):
        Studio(Scene.builtin("sorting"), motion=SCRIPT, goals=["green_apple in white_box"])
    with pytest.raises(StudioError, match="not a URScript file or a recording"):
        Studio(Scene(), motion=tmp_path / "notes.txt")
    with pytest.raises(StudioError, match="no such file"):
        Studio(Scene(), motion=tmp_path / "missing.csv")
    studio = Studio(Scene(), motion=SCRIPT, deploy={"host": "127.0.0.1"})  # a controller configured: still refused
    state = studio.state()
    assert state["motion"]["kind"] == "urscript" and "skill API" in state["chat"]
    assert "not deployed" in state["deploy"]
    with pytest.raises(StudioError, match="not deployed"):
        studio.deploy(1)
    with pytest.raises(StudioError, match="skill API"):
        studio.llm_turn("chat", text="make it faster")


def test_the_cli_refuses_motion_options_for_a_program(capsys):
    program = Path(__file__).resolve().parent.parent / "examples" / "programs" / "sorting_naive.py"
    assert main(["studio", "--no-browser", "--program", str(program), "--tcp", "0,0,0.1,0,0,0"]) == 2
    assert "--tcp" in capsys.readouterr().err


def test_a_script_that_does_not_run_is_the_runtime_error_check_gives_naming_its_line():
    """The worker's answer rebuilt in the studio says what `robocritics check` says: the error and its line."""
    from robocritics import Robot
    from robocritics.critic import runtime_report
    from robocritics.formats.urscript import URScriptError, run_urscript

    broken = SCRIPT.read_text().splitlines()
    broken.insert(3, "  x = = 1")
    broken = "\n".join(broken) + "\n"
    with pytest.raises(URScriptError) as raised:
        run_urscript(broken, Robot.ur3e(), Scene())
    expected = runtime_report(raised.value).verdicts[0]
    with Studio(Scene(), motion=SCRIPT) as studio:
        revision = studio.run(broken)
    (row,) = revision.full()["verdicts"]
    assert (row["critic"], row["flag"], row["lines"]) == ("runtime", "error", [4])
    assert row["message"] == expected.message and "column" not in row["message"]
