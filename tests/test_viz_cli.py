"""`robocritics check --html OUT.html`: the offline replay file from the command line."""

from __future__ import annotations

import json
import re
from pathlib import Path

import robocritics as rc
from robocritics.cli import main

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "programs" / "sorting_careful.py"


def test_html_file_holds_the_replay_and_the_report_of_the_run(tmp_path, capsys):
    out = tmp_path / "careful.html"
    assert main(["check", str(EXAMPLE), "--scene", "sorting", "--html", str(out)]) == 0
    printed = capsys.readouterr().out
    page = out.read_text(encoding="utf-8")
    data = json.loads(re.search(r'<script type="application/json" id="replay-data">(.*?)</script>', page, re.S).group(1))
    execution = rc.simulate(EXAMPLE.read_text(), rc.Scene.builtin("sorting"))
    report = rc.critique(execution)
    assert data["score_text"] == report.score_text and report.score_text in printed
    assert [v["flag"] for v in data["verdicts"]] == [v.flag.value for v in report.verdicts]
    assert abs(data["duration_s"] - execution.duration_s) < 1e-9
    assert f"<title>{EXAMPLE} in sorting: {report.score_text}</title>" in page


def test_html_into_a_missing_directory_fails_before_simulating(tmp_path, capsys):
    out = tmp_path / "no" / "such" / "dir" / "x.html"
    assert main(["check", str(EXAMPLE), "--html", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""  # nothing was simulated or printed
    assert "--html" in captured.err and "does not exist" in captured.err
    assert not out.exists()


def test_html_at_a_directory_is_refused_before_simulating(tmp_path, capsys):
    target = tmp_path / "taken"
    target.mkdir()  # a directory where the file should go
    assert main(["check", str(EXAMPLE), "--html", str(target)]) == 2
    captured = capsys.readouterr()
    assert "is a directory" in captured.err and "Traceback" not in captured.err and captured.out == ""


def test_html_that_cannot_be_written_is_a_clear_error(tmp_path):
    """A disk that fills while the page is written (RLIMIT_FSIZE in the child): one line, and no partial file."""
    import resource
    import signal
    import subprocess
    import sys

    def small_files() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (10_000, 10_000))

    out = tmp_path / "replay.html"
    done = subprocess.run([sys.executable, "-m", "robocritics.cli", "check", str(EXAMPLE), "--html", str(out)],
                          capture_output=True, text=True, timeout=300, preexec_fn=small_files)  # fmt: skip
    assert done.returncode == 2 and "cannot write --html" in done.stderr and "File too large" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr and sorted(p.name for p in tmp_path.iterdir()) == []
