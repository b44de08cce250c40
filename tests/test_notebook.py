"""The example notebook's code cells run, in order, as a user would run them."""

import json
import os
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_notebook_cells_run(capsys):
    notebook = json.loads((EXAMPLES / "notebook.ipynb").read_text())
    namespace: dict = {}
    cwd = os.getcwd()
    os.chdir(EXAMPLES)
    try:
        for cell in notebook["cells"]:
            if cell["cell_type"] == "code":
                exec(compile("".join(cell["source"]), "notebook", "exec"), namespace)
    finally:
        os.chdir(cwd)
    assert namespace["report"].score < 10 <= namespace["fixed"].score
    assert "<svg" in namespace["fixed"]._repr_html_()
    assert [v.critic for v in namespace["strict"].verdicts] == ["joint_speed", "collision"]
    assert namespace["strict"].params["collision"]["d_warn_m"] == 0.08
    assert "Warning" in capsys.readouterr().out or "Error" in namespace["report"].feedback()
