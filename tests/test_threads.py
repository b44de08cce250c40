"""The command line starts numpy with one BLAS thread (robocritics._threads), unless the user says otherwise.

Each case runs in a fresh interpreter: this test process has numpy loaded already.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from robocritics._threads import SINGLE_THREADED_ENV, single_threaded_blas

ROOT = Path(__file__).resolve().parents[1]
PROGRAM = ROOT / "examples" / "programs" / "sorting_naive.py"

# after a whole check: the process's OS threads (an OpenBLAS pool would add one per core) and the variable
SCRIPT = f"""
import os, sys
from robocritics.cli import main
status = main(["check", {str(PROGRAM)!r}, "--scene", "sorting", "--json"])
assert "numpy" in sys.modules
print(status, len(os.listdir("/proc/self/task")), os.environ.get("OPENBLAS_NUM_THREADS"), file=sys.stderr)
"""


def run(env_update: dict[str, str]) -> list[str]:
    env = {k: v for k, v in os.environ.items() if k not in SINGLE_THREADED_ENV}
    env.update(env_update)
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stderr.strip().splitlines()[-1].split()


needs_proc = pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="counts threads in /proc")


@needs_proc
def test_check_runs_with_one_blas_thread():
    status, threads, value = run({})
    assert status == "1"  # sorting_naive has an Error: the check really ran
    assert value == "1"
    assert threads == "1"  # the main thread only: OpenBLAS started no pool


@needs_proc
def test_a_thread_count_the_user_exported_wins():
    status, threads, value = run({"OPENBLAS_NUM_THREADS": "2"})
    assert value == "2"
    # OpenBLAS honoured it: the main thread and one pool thread (OpenBLAS caps the pool at the usable CPUs)
    assert threads == str(min(2, len(os.sched_getaffinity(0))))


def test_sets_only_unset_variables_and_only_before_numpy_loads(monkeypatch):
    environ = {"OMP_NUM_THREADS": "3"}
    monkeypatch.setitem(sys.modules, "numpy", sys)  # numpy loaded: too late, nothing changes
    assert single_threaded_blas(environ) is False and environ == {"OMP_NUM_THREADS": "3"}
    monkeypatch.delitem(sys.modules, "numpy")
    assert single_threaded_blas(environ) is True
    assert environ == {**SINGLE_THREADED_ENV, "OMP_NUM_THREADS": "3"}
