"""The Ray engine on one local Ray cluster (2 CPUs, no dashboard, bound to 127.0.0.1) for this module.

Results must equal the local engine's; an actor killed from outside is replaced and its row marked.
"""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import pytest

ray = pytest.importorskip("ray")

from robocritics.batch import evaluate  # noqa: E402
from robocritics.batch.ray_engine import RayEngine  # noqa: E402

PROGRAMS = Path(__file__).resolve().parent.parent / "examples" / "programs"
SHORT = "move_above(green_apple)\nhome()\n"
LONG = (
    "for i in range(120):\n"
    "    move_to(0.25 + 0.0005 * i, 0.15 - 0.001 * i, 0.25)\n"
    "    move_to(0.3, -0.1 + 0.0005 * i, 0.3)\n"
)
ROWS = [
    *({"id": p.stem, "scene": p.stem.split("_")[0], "program": p.read_text()} for p in sorted(PROGRAMS.glob("sorting_*.py"))),
    {"id": "goal", "scene": "sorting", "program": SHORT, "goal": "green_apple in white_box"},
    {"id": "syntax", "scene": "sorting", "program": "move_to(0.3,\n"},
    {"id": "scene", "scene": "kitchen", "program": SHORT},
    {"scene": "sorting", "program": SHORT},
]


@pytest.fixture(scope="module")
def cluster():
    ray.init(num_cpus=2, include_dashboard=False, _node_ip_address="127.0.0.1", log_to_driver=False)
    try:
        yield
    finally:
        ray.shutdown()


@pytest.fixture(scope="module")
def engine(cluster):
    with RayEngine(2) as pool:
        yield pool


def _keyed(rows):
    return sorted(({k: v for k, v in r.items() if k != "duration_s"} for r in rows), key=lambda r: json.dumps(r["id"]))


def test_ray_rows_equal_local_rows(engine):
    got = _keyed(evaluate(ROWS, engine))
    assert got == _keyed(evaluate(ROWS, "local", workers=1))
    assert len(got) == len(ROWS) and sum(r["error"] is None for r in got) == 3


def test_ray_actors_run_with_single_threaded_blas(engine):
    list(evaluate([{"id": 1, "scene": "sorting", "program": SHORT}], engine))
    for pid in engine.pids():
        environ = Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
        assert b"OMP_NUM_THREADS=1" in environ and b"OPENBLAS_NUM_THREADS=1" in environ


def test_a_killed_actor_is_replaced_and_its_row_marked(engine):
    for pid in engine.pids():  # both actors die while idle: the next rows sent to them fail
        os.kill(pid, signal.SIGKILL)
    restarts = engine.restarts
    out = {r["id"]: r for r in evaluate([{"id": i, "scene": "sorting", "program": SHORT} for i in range(4)], engine)}
    died = [r for r in out.values() if r["error"] is not None]
    assert len(out) == 4 and died and all(r["error"]["type"] == "WorkerDied" for r in died)
    assert engine.restarts == restarts + len(died)
    again = list(evaluate([{"id": "after", "scene": "sorting", "program": SHORT}], engine))
    assert again[0]["error"] is None


def test_a_ray_row_over_its_timeout_is_marked(cluster):
    with RayEngine(1, timeout_s=0.05) as pool:
        (row,) = evaluate([{"id": "long", "scene": "sorting", "program": LONG}], pool)
    assert row["error"]["type"] == "WorkerTimeout" and pool.restarts == 1
