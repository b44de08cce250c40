"""The local engine: a pool of warm, resource-limited worker processes on this machine.

Each worker is a :class:`~robocritics.child.Child` (``spawn``, with :data:`WORKER_ENV`: single-threaded BLAS, since
with several workers a multi-threaded BLAS in each would only fight for the same cores, and glibc malloc tunables). It loads the robot
once, then evaluates rows one at a time, keeping the scenes it has loaded. Limits, set per worker:

* address space (``RLIMIT_AS``, ``memory_bytes``): a row that runs out of memory ends its worker;
* wall-clock time per row (``timeout_s``): the parent kills a worker whose row takes longer.

A worker that dies during a row (out of memory, segfault, ``os._exit``, killed) or exceeds its timeout
is replaced, and its row is an error row of type ``WorkerDied``/``WorkerTimeout``/``WorkerMemory``.
"""

from __future__ import annotations

import os
import tempfile
import threading
import time
from collections import deque
from collections.abc import Iterator
from multiprocessing.connection import wait
from typing import Any

from ..child import MAX_JOBS_PER_CHILD, SINGLE_THREADED_ENV, WORKER_ENV, Child, address_space_limit, limit_address_space
from ..errors import RoboCriticsError
from .rows import Job, SceneCache, error_row, evaluate_job

__all__ = ["LocalEngine", "BatchError", "WORKER_ENV", "DEFAULT_TIMEOUT_S", "DEFAULT_MEMORY_BYTES", "MAX_WORKERS_PER_CPU", "max_workers"]

#: Wall-clock seconds one row may take in a worker.
DEFAULT_TIMEOUT_S = 60.0
#: Address-space limit of a worker, bytes (a checked bundled program peaks near 0.5 GB of address space); lowered to
#: the hard limit the batch runs under (``ulimit -v``) when that is lower.
DEFAULT_MEMORY_BYTES = 3 * 1024**3
#: Most local workers per CPU: a mistyped count (``workers=10**6``) must not start thousands of processes, and more
#: workers than cores only queue for them.
MAX_WORKERS_PER_CPU = 4
#: Rows a worker evaluates before a fresh one replaces it (not counted as a restart; see MAX_JOBS_PER_CHILD).
MAX_ROWS_PER_WORKER = MAX_JOBS_PER_CHILD
#: Wall-clock seconds a worker may take to start (imports, the robot model).
STARTUP_TIMEOUT_S = 120.0
#: Workers in a row that may fail to start before the batch stops with a BatchError.
MAX_START_FAILURES = 3
# How often the parent wakes to check timeouts when no worker has answered, s.
_TICK_S = 0.05


def max_workers() -> int:
    """The most local workers on this machine: :data:`MAX_WORKERS_PER_CPU` per CPU."""
    return MAX_WORKERS_PER_CPU * (os.cpu_count() or 1)


class BatchError(RoboCriticsError):
    """The batch itself cannot run (a worker cannot start, a missing engine): not one row's problem."""


def _serve(conn, robot, memory_bytes: int, sample_rate_hz: float, startup_log: str) -> None:
    """A worker's main loop: set the limit, load the robot, then answer Jobs with output rows.

    While it starts, what the process writes to its standard error goes to the file ``startup_log``: a library
    that cannot allocate under the limit (OpenBLAS) prints there and exits, and the parent names that line in
    its one-line error instead of the lines reaching the user's terminal from every try.
    """
    os.environ.update(SINGLE_THREADED_ENV)  # for anything this process starts
    stderr = os.dup(2)
    with open(startup_log, "wb") as log:
        os.dup2(log.fileno(), 2)
    limit_address_space(memory_bytes)
    try:
        import coal  # noqa: F401 - every row's critics measure with it (the hull): a limit too small to load it
        # fails here, once, as a worker that could not start, not in every row as a critic's ImportError
        from ..robot.model import default_robot

        robot = robot if robot is not None else default_robot()
    except BaseException as exc:  # noqa: BLE001 - the parent raises it as a BatchError
        conn.send(("failed", f"{type(exc).__name__}: {exc}"))
        return
    scenes = SceneCache()
    os.dup2(stderr, 2)
    os.close(stderr)
    conn.send(("ready", os.getpid()))
    while True:
        try:
            job = conn.recv()
        except EOFError:
            return
        try:
            conn.send(("row", evaluate_job(job, robot, scenes, sample_rate_hz)))
        except MemoryError:
            try:
                conn.send(("memory", None))
            finally:
                os._exit(1)


class _Worker(Child):
    """One child process and the row it is working on."""

    def __init__(self, robot, memory_bytes: int, sample_rate_hz: float):
        fd, self.startup_log = tempfile.mkstemp(prefix="robocritics-worker-", suffix=".log")
        os.close(fd)
        args = (robot, memory_bytes, sample_rate_hz, self.startup_log)
        super().__init__(_serve, args, name="robocritics-batch", env=WORKER_ENV)
        self.ready = False
        self.job: Job | None = None
        self.job_started = 0.0
        self.rows_done = 0

    def startup_output(self) -> str:
        """The last line the worker wrote to its standard error while starting ('' for none), and the file gone."""
        try:
            with open(self.startup_log, "rb") as f:
                f.seek(0, os.SEEK_END)
                f.seek(max(0, f.tell() - 4096))
                lines = [line.strip() for line in f.read().decode("utf-8", "replace").splitlines() if line.strip()]
        except OSError:
            lines = []
        self.forget_startup_log()
        return lines[-1][:300] if lines else ""

    def forget_startup_log(self) -> None:
        try:
            os.unlink(self.startup_log)
        except OSError:
            pass

    def kill(self) -> None:
        super().kill()
        self.forget_startup_log()


class LocalEngine:
    """A pool of ``workers`` warm processes (default: the CPU count) evaluating Jobs.

    ``robot`` (default the UR3e, loaded in each worker) is pickled to each worker once;
    ``timeout_s`` is the wall-clock limit per row, s; ``memory_bytes`` a worker's address-space
    limit, bytes; ``sample_rate_hz`` the trajectories' sample rate, Hz; ``max_rows_per_worker`` the rows a
    worker evaluates before a fresh one replaces it (:data:`MAX_ROWS_PER_WORKER`). Use it as a context manager.
    """

    def __init__(
        self,
        workers: int | None = None,
        *,
        robot=None,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        memory_bytes: int = DEFAULT_MEMORY_BYTES,
        sample_rate_hz: float = 125.0,
        max_rows_per_worker: int = MAX_ROWS_PER_WORKER,
    ):
        workers = (os.cpu_count() or 1) if workers is None else workers
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
            raise ValueError(f"workers must be a whole number of at least 1, got {workers!r:.40}")
        if workers > max_workers():
            raise ValueError(f"workers={workers}: at most {max_workers()} on this machine ({os.cpu_count() or 1} CPUs); "
                             "each worker is a process with its own robot model, and more than the cores only queue "
                             "for them")  # fmt: skip
        if not timeout_s > 0 or not 0 < memory_bytes < 2**62:
            raise ValueError(f"timeout_s and memory_bytes must be positive, got {timeout_s}, {memory_bytes}")
        if isinstance(max_rows_per_worker, bool) or not isinstance(max_rows_per_worker, int) or max_rows_per_worker < 1:
            raise ValueError(f"max_rows_per_worker must be a whole number of at least 1, got {max_rows_per_worker!r}")
        self.workers = workers
        self.max_rows_per_worker = max_rows_per_worker
        self.recycled = 0  # workers replaced after max_rows_per_worker rows
        self.timeout_s = float(timeout_s)
        self.memory_bytes = address_space_limit(int(memory_bytes))  # what a worker can set under `ulimit -v`
        self._args = (robot, self.memory_bytes, float(sample_rate_hz))
        self._pool: list[_Worker] = []
        self._start_failures = 0
        self.restarts = 0  # workers replaced after a death or a limit
        self._lock = threading.Lock()

    # --- lifetime ---

    def __enter__(self) -> LocalEngine:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def close(self) -> None:
        """Stop every worker. Idempotent."""
        pool, self._pool = self._pool, []
        for w in pool:
            w.kill()

    def running(self) -> dict[int, Any]:
        """``{worker pid: id of the row it is evaluating}`` right now (for monitoring)."""
        with self._lock:
            return {w.pid: w.job.id for w in self._pool if w.job is not None and w.pid is not None}

    def _spawn(self) -> _Worker:
        return _Worker(*self._args)

    def _replace(self, worker: _Worker, recycle: bool = False) -> None:
        worker.kill()
        with self._lock:
            self._pool[self._pool.index(worker)] = self._spawn()
        if recycle:
            self.recycled += 1
        else:
            self.restarts += 1

    # --- rows ---

    def run(self, jobs: Iterator[Job | dict]) -> Iterator[dict]:
        """Evaluate ``jobs``, yielding one output row per job as each finishes (not in input order); a dict
        among them (the error row of a bad input row, :func:`~robocritics.batch.evaluate.jobs_of`) is yielded
        as it is read."""
        while len(self._pool) < self.workers:
            self._pool.append(self._spawn())
        queue: deque[Job] = deque()
        exhausted = False
        try:
            while True:
                for w in self._pool:  # give every idle, ready worker a job
                    if w.ready and w.job is None:
                        if not queue and not exhausted:
                            nxt = next(jobs, None)
                            while isinstance(nxt, dict):  # a bad input row's error row: out at once
                                yield nxt
                                nxt = next(jobs, None)
                            exhausted = nxt is None
                            if nxt is not None:
                                queue.append(nxt)
                        if queue:
                            with self._lock:
                                w.job, w.job_started = queue.popleft(), time.monotonic()
                            w.conn.send(w.job)
                if exhausted and not queue and all(w.job is None for w in self._pool):
                    return
                ready = set(wait([w.conn for w in self._pool] + [w.process.sentinel for w in self._pool], _TICK_S))
                now = time.monotonic()
                for w in list(self._pool):
                    row = self._poll(w, w.conn in ready or w.process.sentinel in ready, now)
                    if row is not None:
                        yield row
        finally:  # abandoned early (the caller stopped reading): a busy worker's late row must not reach the next run
            for w in list(self._pool):
                if w.job is not None:
                    self._replace(w)

    def _poll(self, w: _Worker, signalled: bool, now: float) -> dict | None:
        """The row ``w`` finished, or its error row if it died or timed out (then it is replaced)."""
        job = w.job
        if signalled:
            try:
                message = w.conn.recv() if w.conn.poll() else None
            except (EOFError, OSError):  # the pipe's end closed: the worker is gone
                message = ("died", None)
            if message is None:
                if w.process.is_alive():
                    return None
                message = ("died", None)
            kind, value = message
            if kind == "ready":
                w.ready, self._start_failures = True, 0
                w.forget_startup_log()
                return None
            if kind == "row":
                with self._lock:
                    w.job = None
                w.rows_done += 1
                if w.rows_done >= self.max_rows_per_worker:
                    self._replace(w, recycle=True)
                return value
            if kind == "failed" or not w.ready:
                said = "" if value else w.startup_output()
                why = value or f"the worker died while starting ({w.death()})" + (f": {said}" if said else "")
                self._start_failure(w, why)
                return None
            if job is None:  # died between rows
                self._replace(w)
                return None
            duration = now - w.job_started
            if kind == "memory":
                text = f"the row ran out of memory (the worker's address-space limit is {self.memory_bytes} bytes)"
                row = error_row(job.id, "WorkerMemory", text, duration_s=duration)
            else:
                row = error_row(job.id, "WorkerDied", f"the worker process died during the row ({w.death()})", duration_s=duration)
            self._replace(w)
            return row
        if not w.ready and now - w.started > STARTUP_TIMEOUT_S:
            self._start_failure(w, f"the worker did not start within {STARTUP_TIMEOUT_S:g} s")
        elif job is not None and now - w.job_started > self.timeout_s:
            duration = now - w.job_started
            self._replace(w)
            return error_row(
                job.id, "WorkerTimeout", f"the row took longer than its timeout of {self.timeout_s:g} s", duration_s=duration
            )
        return None

    def _start_failure(self, w: _Worker, why: str) -> None:
        self._start_failures += 1
        if self._start_failures >= MAX_START_FAILURES:
            self.close()
            raise BatchError(f"a batch worker could not start ({self._start_failures} times, with an address-space "
                             f"limit of {self.memory_bytes:,} bytes): {why}")  # fmt: skip
        self._replace(w)
