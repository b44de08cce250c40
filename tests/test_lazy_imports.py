"""The check path imports only what it uses: no Pinocchio (a bundled arm's tables are stored, its critics that need
dynamics run on demand), no scipy, no HTTP client, no deploy/LLM/replay/batch code.

Each case runs in a fresh interpreter (``sys.modules`` of this test process holds everything the suite has
imported) and prints the modules loaded after the work is done.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROGRAM = ROOT / "examples" / "programs" / "sorting_careful.py"

#: Packages and robocritics subpackages that ``robocritics check`` and ``simulate() + critique()`` must not load
#: (the ``robocritics.repair`` package itself is light and loads with ``robocritics``; its modules are not).
NOT_ON_THE_PATH = ("pinocchio", "scipy", "httpx", "httpcore", "viser", "ray", "pyarrow", "sqlite3", "yaml", "logging",
                   "robocritics.deploy", "robocritics.llm", "robocritics.viz", "robocritics.batch", "robocritics.repair.",
                   "robocritics.testing", "robocritics.robot.vendor", "robocritics.robot.fit",
                   "robocritics.robot.ik_numeric", "robocritics.formats.urscript",
                   "robocritics.formats.rosbag", "robocritics.formats.export", "robocritics.formats.files",
                   "robocritics.humans")  # fmt: skip


def loaded_after(code: str) -> set[str]:
    script = f"{code}\nimport json, sys\nprint(json.dumps(sorted(sys.modules)), file=sys.stderr)"
    done = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode in (0, 1), done.stderr[-2000:]
    return set(json.loads(done.stderr.strip().splitlines()[-1]))


def offenders(modules: set[str], banned=NOT_ON_THE_PATH) -> list[str]:
    """``modules`` in ``banned``: a name ending in "." bans the package's submodules only."""
    return sorted(m for m in modules if any(m.startswith(b) if b.endswith(".") else m == b or m.startswith(b + ".") for b in banned))


def test_cli_check_loads_only_the_check_subcommand_and_no_heavy_extras():
    mods = loaded_after(
        "from robocritics.cli import main\n"
        f"main(['check', {str(PROGRAM)!r}, '--scene', 'sorting', '--json'])"
    )
    assert "robocritics.geometry.proximity" in mods and "robocritics.critic.builtin.space_usage" in mods  # it really ran
    assert offenders(mods) == []
    other_commands = {f"robocritics.cli.{c}" for c in ("batch", "critics", "deploy", "fix", "run", "studio", "ursim")}
    assert sorted(mods & other_commands) == []


def test_simulate_and_critique_do_not_load_scipy():
    mods = loaded_after(
        "from pathlib import Path\nfrom robocritics import Scene, critique, simulate\n"
        f"critique(simulate(Path({str(PROGRAM)!r}).read_text(), Scene.builtin('sorting')))"
    )
    assert "robocritics.geometry.hull" in mods
    assert offenders(mods) == []


@pytest.mark.parametrize("argv", [["--help"], ["no-such-command"]])
def test_help_and_unknown_commands_still_list_every_subcommand(argv):
    done = subprocess.run([sys.executable, "-m", "robocritics.cli", *argv], cwd=ROOT, capture_output=True, text=True, timeout=120)
    text = done.stdout + done.stderr
    for command in ("batch", "check", "critics", "deploy", "fix", "run", "studio", "ursim"):
        assert command in text


def test_the_check_path_compiles_no_tokenizer_regex():
    """A builtin default factory (``default_factory=list``) of a pydantic field makes pydantic read its signature
    from text, which compiles the tokenizer's regexes once per process (~3 ms of a cold check): the models a check
    builds use Python factories."""
    script = (
        "from robocritics.cli import main\n"
        f"main(['check', {str(PROGRAM)!r}, '--scene', 'sorting', '--json'])\n"
        "import sys\n"
        "tok = sys.modules.get('tokenize')\n"
        "print('compiled', 0 if tok is None else tok._compile.cache_info().currsize, file=sys.stderr)"
    )
    done = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode in (0, 1), done.stderr[-2000:]
    assert done.stderr.strip().splitlines()[-1] == "compiled 0"


def test_the_robot_model_and_the_critics_import_no_pinocchio():
    """Pinocchio (~30-60 ms to import) is loaded where it computes: a URDF of the user's, numeric IK, the payload
    critic's dynamics. Loading the robot model, the pipeline and every built-in critic does not load it, nor does
    reading a bundled UR arm's stored tables (robot/kinematic_tables.py)."""
    mods = loaded_after(
        "import robocritics.robot.model, robocritics.pipeline, robocritics.critic.plugins as plugins\n"
        "plugins.load_plugins()\n"
        "from robocritics.robot.kinematic_tables import stored_tables, bundled_text\n"
        "urdf, text = bundled_text('ur3e')\n"
        "assert stored_tables(urdf.with_name('ur3e.tables.json'), text) is not None"
    )
    assert "robocritics.critic.builtin.payload" in mods and "robocritics.robot.model" in mods  # it really ran
    assert offenders(mods, ("pinocchio", "coal")) == []
