"""The Ray engine on one local Ray cluster (2 CPUs, no dashboard) started by the engine, on loopback only.

Results must equal the local engine's; an actor killed from outside is replaced and its row marked.
"""

from __future__ import annotations

import json
import os
import signal
import threading
import time
from pathlib import Path

import pytest

from robocritics.batch import evaluate  # noqa: E402
from robocritics.batch.local import BatchError  # noqa: E402
from robocritics.batch.ray_engine import RayEngine, import_ray  # noqa: E402

try:  # the engine's own import (not pytest.importorskip): a local cluster it starts listens on 127.0.0.1 only
    ray = import_ray()
except BatchError:  # pragma: no cover - the ray extra is in the test extra; kept for a partial install
    pytest.skip("ray is not installed", allow_module_level=True)

PROGRAMS = Path(__file__).resolve().parent.parent / "examples" / "programs"
SHORT = "move_above(green_apple)\nhome()\n"
LONG = (
    "for i in range(120):\n"
    "    move_to(0.25 + 0.0005 * i, 0.15 - 0.001 * i, 0.25)\n"
    "    move_to(0.3, -0.1 + 0.0005 * i, 0.3)\n"
)
ROWS = [
    {"id": "naive", "scene": "sorting", "program": (PROGRAMS / "sorting_naive.py").read_text()},
    {"id": "short", "scene": "sorting", "program": SHORT},
    {"id": "goal", "scene": "sorting", "program": SHORT, "goal": "green_apple in white_box"},
    {"id": "syntax", "scene": "sorting", "program": "move_to(0.3,\n"},
    {"id": "scene", "scene": "kitchen", "program": SHORT},
    {"scene": "sorting", "program": SHORT},
]


@pytest.fixture(scope="module")
def engine():
    if ray.is_initialized():  # pragma: no cover - another module's cluster: this one must start its own
        ray.shutdown()
    with RayEngine(2) as pool:
        yield pool
    assert not ray.is_initialized()  # the engine shut down the cluster it started


def _listening_ports(pids):
    """``{(address, port)}`` of the TCP sockets in LISTEN state owned by ``pids`` (from /proc, IPv4 and IPv6)."""
    inodes = set()
    for pid in pids:
        fd_dir = Path(f"/proc/{pid}/fd")
        for fd in fd_dir.iterdir():
            try:
                target = os.readlink(fd)
            except OSError:
                continue
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    found = set()
    for table, width in (("/proc/net/tcp", 8), ("/proc/net/tcp6", 32)):
        for line in Path(table).read_text().splitlines()[1:]:
            fields = line.split()
            if fields[3] == "0A" and fields[9] in inodes:  # 0A: TCP_LISTEN
                address, port = fields[1].split(":")
                found.add((address, int(port, 16)))
    return found


def _is_loopback(hex_address):
    """/proc/net's hex address (little-endian words) is 127.0.0.0/8, ::1 or ::ffff:127.x.y.z."""
    if len(hex_address) == 8:
        return bytes.fromhex(hex_address)[::-1][0] == 127
    words = [bytes.fromhex(hex_address[i : i + 8])[::-1] for i in range(0, 32, 8)]
    raw = b"".join(words)
    return raw == bytes(15) + b"\x01" or (raw[:12] == bytes(10) + b"\xff\xff" and raw[12] == 127)


def test_the_local_cluster_listens_on_loopback_only(engine):
    (row,) = evaluate([{"id": 1, "scene": "sorting", "program": SHORT}], engine)
    assert row["error"] is None and engine.pids()  # the actors are up
    node = ray.nodes()[0]
    assert node["NodeManagerAddress"] == "127.0.0.1"
    assert ray.get_runtime_context().gcs_address.startswith("127.0.0.1:")
    ray_pids = [int(p.name) for p in Path("/proc").iterdir() if p.name.isdigit() and _is_ray_process(p)]
    ports = _listening_ports(ray_pids)
    assert len(ports) >= 3  # GCS, raylet, the actors' workers
    assert all(_is_loopback(address) for address, _ in ports), sorted(ports)


def _is_ray_process(proc_dir):
    try:
        cmdline = (proc_dir / "cmdline").read_bytes()
    except OSError:
        return False
    return b"ray" in cmdline and str(os.getuid()) == str((proc_dir / "status").stat().st_uid)


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
    restarts, killed = engine.restarts, []

    def kill_when_running():
        for _ in range(3000):
            pid = next((p for p, row_id in engine.running().items() if row_id == "long"), None)
            if pid is not None:
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
                return
            time.sleep(0.01)

    killer = threading.Thread(target=kill_when_running)
    killer.start()
    out = {r["id"]: r for r in evaluate([{"id": "long", "scene": "sorting", "program": LONG}], engine)}
    killer.join(30)
    assert killed and out["long"]["error"]["type"] == "WorkerDied"
    assert engine.restarts == restarts + 1
    again = list(evaluate([{"id": i, "scene": "sorting", "program": SHORT} for i in range(2)], engine))
    assert [r["error"] for r in again] == [None, None]


def test_an_actor_killed_while_idle_is_replaced_before_its_next_row(engine):
    os.kill(engine.pids()[0], signal.SIGKILL)
    restarts = engine.restarts
    out = list(evaluate([{"id": i, "scene": "sorting", "program": SHORT} for i in range(2)], engine))
    assert [r["error"] for r in out] == [None, None] and engine.restarts == restarts + 1


def test_a_ray_row_over_its_timeout_is_marked(engine):
    # the module's engine (its actors hold the cluster's 2 CPUs), with a tiny timeout for this test
    restarts, engine.timeout_s = engine.restarts, 0.05
    try:
        (row,) = evaluate([{"id": "long", "scene": "sorting", "program": LONG}], engine)
    finally:
        engine.timeout_s = 60.0
    assert row["error"]["type"] == "WorkerTimeout" and engine.restarts == restarts + 1
    assert row["duration_s"] >= 0.05


def test_a_ray_batch_abandoned_early_does_not_leak_into_the_next(engine):
    rows = evaluate([{"id": f"old{i}", "scene": "sorting", "program": LONG} for i in range(3)], engine)
    assert next(rows)["id"].startswith("old")
    rows.close()
    out = list(evaluate([{"id": "new", "scene": "sorting", "program": SHORT}], engine))
    assert [r["id"] for r in out] == ["new"] and out[0]["error"] is None and engine.running() == {}


def test_a_ray_actor_is_replaced_by_a_fresh_one_after_max_rows_per_worker(engine):
    restarts, recycled, engine.max_rows_per_worker = engine.restarts, engine.recycled, 2
    try:
        out = list(evaluate([{"id": i, "scene": "sorting", "program": SHORT} for i in range(4)], engine))
    finally:
        engine.max_rows_per_worker = 1000
    assert [r["error"] for r in out] == [None] * 4
    assert engine.recycled >= recycled + 1 and engine.restarts == restarts  # 4 rows on 2 actors: 1 or 2 recycled
