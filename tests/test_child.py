"""robocritics.child: the spawn child both the studio's Evaluator and the batch engine start.

Real processes: the limits are the kernel's, the CPU time is /proc's, the deaths are real signals.
"""

from __future__ import annotations

import os
import platform
import signal
import time

import pytest

from robocritics.child import MALLOC_TUNABLES, SINGLE_THREADED_ENV, WORKER_ENV, Child, cpu_seconds


def _echo_env(conn, names):
    conn.send({name: os.environ.get(name) for name in names})
    conn.recv()


def _allocate(conn, memory_bytes):
    from robocritics.child import limit_address_space

    limit_address_space(memory_bytes)
    try:
        bytearray(2 * memory_bytes)
    except MemoryError:
        conn.send("MemoryError")
    else:
        conn.send("allocated")


def _spin(conn, seconds):
    end = time.process_time() + seconds
    while time.process_time() < end:
        pass
    conn.send("done")
    conn.recv()


def _fresh_page_faults(conn):
    """Minor page faults of 10 rounds of: ten 4 MB arrays alive together, then all freed (after a warm-up round),
    as a check's temporaries are."""
    import resource

    import numpy as np

    def round_of_arrays():
        arrays = [np.ones(500_000) for _ in range(10)]
        del arrays

    round_of_arrays()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(10):
        round_of_arrays()
    conn.send(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
    conn.recv()


def _faults_in_child(env) -> int:
    child = Child(_fresh_page_faults, (), name="test-malloc", env=env)
    try:
        assert child.conn.poll(60)
        return child.conn.recv()
    finally:
        child.kill()


def _exit_with(conn, code):
    os._exit(code)


def test_the_child_gets_its_environment_and_the_parent_keeps_its_own():
    before = {name: os.environ.get(name) for name in SINGLE_THREADED_ENV}
    child = Child(_echo_env, (list(SINGLE_THREADED_ENV),), name="test-env", env=SINGLE_THREADED_ENV)
    try:
        assert child.conn.recv() == SINGLE_THREADED_ENV
        assert {name: os.environ.get(name) for name in SINGLE_THREADED_ENV} == before
    finally:
        child.kill()
    assert not child.is_alive() and child.death() == "signal SIGKILL"


def test_the_address_space_limit_turns_a_large_allocation_into_memory_error():
    child = Child(_allocate, (512 * 1024**2,), name="test-memory")
    try:
        assert child.conn.poll(60) and child.conn.recv() == "MemoryError"
    finally:
        child.kill()


def test_cpu_seconds_counts_the_child_s_cpu_not_its_wall_time():
    child = Child(_spin, (0.3,), name="test-cpu")
    try:
        assert child.conn.poll(60) and child.conn.recv() == "done"
        used = cpu_seconds(child.pid)
        assert 0.3 <= used < 30  # the spin plus the interpreter's start, never less than the spin
    finally:
        child.kill()
    assert cpu_seconds(child.pid) == 0.0  # reaped: gone from /proc


def test_death_names_the_exit_code_or_the_signal():
    exited = Child(_exit_with, (3,), name="test-exit")
    assert exited.death() == "exit code 3" and exited.exitcode == 3
    exited.kill()  # idempotent on an ended child
    spinning = Child(_spin, (60.0,), name="test-term")
    try:
        os.kill(spinning.pid, signal.SIGTERM)
        assert spinning.death() == "signal SIGTERM"
    finally:
        spinning.kill()


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="GLIBC_TUNABLES is glibc's")
def test_a_warm_child_reuses_its_heap_instead_of_faulting_in_fresh_pages():
    # glibc's default serves many of these arrays with fresh zeroed pages each time (a fault per 4 KiB)
    plain, tuned = _faults_in_child(SINGLE_THREADED_ENV), _faults_in_child(WORKER_ENV)
    assert plain > 10 * 5_000 and tuned < 200, (plain, tuned)


def test_a_user_s_glibc_tunables_are_kept(monkeypatch):
    monkeypatch.setenv("GLIBC_TUNABLES", "glibc.malloc.arena_max=2")
    child = Child(_echo_env, (["GLIBC_TUNABLES", "OMP_NUM_THREADS"],), name="test-env")
    try:
        assert child.conn.recv() == {"GLIBC_TUNABLES": "glibc.malloc.arena_max=2", "OMP_NUM_THREADS": "1"}
    finally:
        child.kill()
    assert os.environ["GLIBC_TUNABLES"] == "glibc.malloc.arena_max=2"
    assert WORKER_ENV["GLIBC_TUNABLES"] == MALLOC_TUNABLES
