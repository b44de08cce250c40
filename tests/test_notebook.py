"""The example notebook's code cells run, in order, as a user would run them."""

import json
import os
from pathlib import Path

import pytest

import robocritics.critic
from robocritics.critic import BUILTIN_CRITICS, Flag, get_critics

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture
def notebook(capsys):
    """The notebook's namespace after running every code cell, and what it printed."""
    cells = json.loads((EXAMPLES / "notebook.ipynb").read_text())["cells"]
    namespace: dict = {}
    cwd = os.getcwd()
    os.chdir(EXAMPLES)
    try:
        for cell in cells:
            if cell["cell_type"] == "code":
                exec(compile("".join(cell["source"]), "notebook", "exec"), namespace)
    finally:
        os.chdir(cwd)
        robocritics.critic.unregister("time_budget")  # the notebook registers a critic: leave none behind
    yield namespace, capsys.readouterr().out
    assert "time_budget" not in get_critics()


def test_notebook_cells_run(notebook):
    namespace, printed = notebook
    report, fixed, strict, timed = (namespace[k] for k in ("report", "fixed", "strict", "timed"))
    # the naive program: the critics' errors and warnings, printed as the feedback the model gets
    assert report.score < 10 and report.has_errors
    assert {v.critic for v in report.scored_verdicts if v.flag is Flag.ERROR} == {"space_usage", "collision", "end_effector_pose"}
    assert report.feedback() in printed
    assert report.feedback().startswith("Error: The robot leaves the allowed workspace")
    # the replay cell: an inline iframe holding the whole replay page, with the naive run's verdicts on its timeline
    replay = namespace["replay"]
    assert replay._repr_html_().startswith('<iframe class="robocritics-replay"')
    assert all(v.message.split(":")[0] in replay.html for v in report.verdicts)
    # the careful program passes every motion critic and puts the apple in the box
    assert fixed.score == 10 and all(v.flag is Flag.OK for v in fixed.scored_verdicts)
    assert "10/10 True" in printed
    assert "<svg" in fixed._repr_html_()
    assert [v.critic for v in strict.verdicts] == ["joint_speed", "collision"]
    assert strict.params["collision"]["d_warn_m"] == 0.08
    # the notebook's own critic stands beside the unchanged score and counts toward pass/fail
    assert timed.score == fixed.score
    beside = [v.critic for v in timed.other_verdicts]  # time_budget, after any installed plugin's critics
    assert beside[-1] == "time_budget" and not set(beside) & set(BUILTIN_CRITICS)
    assert timed.flag_of("time_budget") is Flag.WARNING and not timed.passed
    assert [v.critic for v in timed.scored_verdicts] == list(BUILTIN_CRITICS)
    assert "; beside the score: " in printed and f"time_budget Warning; {timed.samples} samples" in printed
