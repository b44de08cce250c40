"""`robocritics check` does not import numpy.ma: plain ``np.unique(x)`` (numpy 2.4) asks ``np.ma.is_masked``,
and loading numpy.ma costs about 9 ms of a cold check; the check path uses robocritics._arrays instead."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = ROOT / "examples" / "programs"


@pytest.mark.parametrize("name", ["sorting_careful", "sorting_naive", "breakfast_naive"])
def test_cli_check_does_not_import_numpy_ma(name):
    script = (
        "import json, sys\nfrom robocritics.cli.main import main\n"
        "try:\n"
        f"    main(['check', {str(PROGRAMS / f'{name}.py')!r}, '--scene', {name.split('_')[0]!r}, '--json'])\n"
        "except SystemExit:\n    pass\n"
        "print(json.dumps(sorted(sys.modules)), file=sys.stderr)"
    )
    done = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    modules = set(json.loads(done.stderr.strip().splitlines()[-1]))
    assert "robocritics.critic.builtin.space_usage" in modules and "robocritics.geometry.hull" in modules  # it really ran
    assert json.loads(done.stdout)["verdicts"]  # and judged the program
    assert "numpy.ma" not in modules
