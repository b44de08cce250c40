"""robocritics.child: the spawn child both the studio's Evaluator and the batch engine start.

Real processes: the limits are the kernel's, the CPU time is /proc's, the deaths are real signals.
"""

from __future__ import annotations

import os
import signal
import time

from robocritics.child import SINGLE_THREADED_ENV, Child, cpu_seconds


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
