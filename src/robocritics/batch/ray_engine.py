"""The Ray engine: the same rows on a Ray cluster (local by default), one warm actor per worker.

Needs the optional extra ``robocritics[ray]``. Each actor loads the robot once (the ``robot`` given is put
in Ray's object store once and shipped to every actor) and keeps the scenes it has loaded; rows are
evaluated by the same function as the local engine's (:func:`~robocritics.batch.rows.evaluate_job`), so the
results are equal. An actor that dies or whose row exceeds ``timeout_s`` is replaced and its row is an
error row (``WorkerDied``/``WorkerTimeout``; ``WorkerMemory`` for a MemoryError).
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from typing import Any

from .local import (
    DEFAULT_TIMEOUT_S,
    MAX_ROWS_PER_WORKER,
    MAX_START_FAILURES,
    STARTUP_TIMEOUT_S,
    WORKER_ENV,
    BatchError,
    max_workers,
)
from .rows import Job, SceneCache, error_row, evaluate_job

__all__ = ["RayEngine", "import_ray"]

_TICK_S = 0.05


#: Ray reads this when it is imported: "0" makes a local cluster use 127.0.0.1 as its node address, so
#: every port it opens (GCS, raylet, object store, workers) listens on loopback only. Ray's own default
#: on Linux is this host's network address on all interfaces, i.e. a cluster that runs programs for anyone
#: who can reach the machine.
LOOPBACK_ENV = {"RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"}


def import_ray(loopback: bool = True):
    """The ``ray`` module, or a BatchError naming the extra that installs it.

    ``loopback``: when this call is the first import of Ray in the process, make a local cluster it
    starts bind to 127.0.0.1 only (:data:`LOOPBACK_ENV`; an explicit setting in the environment wins).
    """
    if loopback:
        for name, value in LOOPBACK_ENV.items():
            os.environ.setdefault(name, value)
    try:
        import ray
    except ImportError:
        raise BatchError(
            "the ray engine needs Ray: install the extra with pip install 'robocritics[ray]' (ray>=2.9)"
        ) from None
    return ray


class _Actor:
    """A Ray actor: the robot loaded once, scenes cached, rows evaluated one at a time."""

    def __init__(self, robot, sample_rate_hz: float):
        from ..robot.model import default_robot

        self.robot = robot if robot is not None else default_robot()
        self.scenes = SceneCache()
        self.sample_rate_hz = sample_rate_hz

    def pid(self) -> int:
        return os.getpid()

    def evaluate(self, job: Job) -> dict:
        try:
            return evaluate_job(job, self.robot, self.scenes, self.sample_rate_hz)
        except MemoryError:
            return {"memory": True}


class RayEngine:
    """``workers`` Ray actors (default: the cluster's CPUs) evaluating Jobs; use it as a context manager.

    ``address`` names a running cluster (``"ray://host:10001"`` or ``"auto"``); by default, if Ray is not
    initialised yet, a local one is started on loopback only (127.0.0.1, see :data:`LOOPBACK_ENV`) and shut
    down on :meth:`close`. A cluster you start yourself is yours to secure: see docs/batch.md.
    """

    def __init__(
        self,
        workers: int | None = None,
        *,
        robot=None,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        sample_rate_hz: float = 125.0,
        address: str | None = None,
        max_rows_per_worker: int = MAX_ROWS_PER_WORKER,
    ):
        ray = self._ray = import_ray(loopback=address is None)
        if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
            raise ValueError(f"workers must be a whole number of at least 1, got {workers!r:.40}")
        if address is None and workers is not None and workers > max_workers():  # a local cluster: this machine's cap
            raise ValueError(f"workers={workers}: at most {max_workers()} on this machine ({os.cpu_count() or 1} CPUs)")
        if not timeout_s > 0:
            raise ValueError(f"timeout_s must be positive, got {timeout_s}")
        self._owns_ray = not ray.is_initialized()
        if self._owns_ray:
            options: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False}
            if address is None:
                options.update(num_cpus=workers)
            ray.init(address=address, **options)
        self.workers = workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
        self.timeout_s = float(timeout_s)
        self.restarts = 0
        self.max_rows_per_worker = int(max_rows_per_worker)
        self.recycled = 0  # actors replaced after max_rows_per_worker rows
        self._rows_done: dict[str, int] = {}  # actor id -> rows it has evaluated
        self._robot_ref = ray.put(robot)
        self._sample_rate_hz = float(sample_rate_hz)
        self._remote = ray.remote(num_cpus=1, max_restarts=0)(_Actor)
        self._actors: list = []
        self._pid_of: dict[str, int] = {}  # actor id -> its process id, once started
        self._running: dict[str, Any] = {}  # actor id -> the id of the row it is evaluating
        self._start_failures = 0

    def _spawn(self):
        return self._remote.options(runtime_env={"env_vars": dict(WORKER_ENV)}).remote(
            self._robot_ref, self._sample_rate_hz
        )

    def __enter__(self) -> RayEngine:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def close(self) -> None:
        """Kill the actors (and shut down the local Ray this engine started). Idempotent."""
        actors, self._actors = self._actors, []
        for a in actors:
            self._ray.kill(a)
        if self._owns_ray and self._ray.is_initialized():
            self._ray.shutdown()
        self._owns_ray = False

    def pids(self) -> list[int]:
        """The actors' process ids (asks each actor: waits for a busy one)."""
        return self._ray.get([a.pid.remote() for a in self._actors])

    def running(self) -> dict[int, Any]:
        """``{actor pid: id of the row it is evaluating}`` right now (for monitoring; no call to the actors)."""
        return {self._pid_of[a]: row_id for a, row_id in list(self._running.items()) if a in self._pid_of}

    def run(self, jobs: Iterator[Job | dict]) -> Iterator[dict]:
        """See :meth:`_run`; a run abandoned early cancels its rows still in flight."""
        flight: dict[Any, tuple[Any, Job, float]] = {}
        try:
            yield from self._run(jobs, flight)
        finally:
            for ref in flight:
                self._ray.cancel(ref)
            self._running.clear()

    def _run(self, jobs: Iterator[Job | dict], flight: dict) -> Iterator[dict]:
        """Evaluate ``jobs``, yielding output rows as they finish, and a dict among them (a bad input row's
        error row) as it is read.

        A row's timeout starts when it is sent to an actor that has started (loaded the robot)."""
        ray = self._ray
        while len(self._actors) < self.workers:
            self._actors.append(self._spawn())
        idle: list = []
        starting = {actor.pid.remote(): actor for actor in self._actors}  # ready when the robot is loaded
        waiting_since = time.monotonic()  # for the startup timeout: the last time an actor became ready
        # flight: ObjectRef -> (actor, job, started)
        exhausted = False
        while True:
            while idle and not exhausted:
                job = next(jobs, None)
                while isinstance(job, dict):  # a bad input row's error row: out at once
                    yield job
                    job = next(jobs, None)
                if job is None:
                    exhausted = True
                    break
                actor = idle.pop()
                flight[actor.evaluate.remote(job)] = (actor, job, time.monotonic())
                self._running[actor._actor_id.hex()] = job.id
            if exhausted and not flight:
                return
            done, _ = ray.wait([*starting, *flight], num_returns=1, timeout=_TICK_S)
            now = time.monotonic()
            for ref in done:
                if ref in starting:
                    actor = starting.pop(ref)
                    try:
                        self._pid_of[actor._actor_id.hex()] = ray.get(ref)
                    except ray.exceptions.RayError as exc:  # could not start, or died while idle: replace it
                        self._start_failures += 1
                        if self._start_failures >= MAX_START_FAILURES:
                            raise BatchError(
                                f"a Ray actor could not start ({self._start_failures} times): {' '.join(str(exc).split())[:300]}"
                            ) from None
                        fresh = self._replace(actor)
                        starting[fresh.pid.remote()] = fresh
                        continue
                    self._start_failures, waiting_since = 0, now
                    idle.append(actor)
                    continue
                actor, job, started = flight.pop(ref)
                self._running.pop(actor._actor_id.hex(), None)
                try:
                    row = ray.get(ref)
                except ray.exceptions.RayActorError as exc:
                    why = " ".join(str(exc).split())[:300]
                    yield error_row(job.id, "WorkerDied", f"the worker process died during the row: {why}", duration_s=now - started)
                    fresh = self._replace(actor)
                    starting[fresh.pid.remote()] = fresh
                    continue
                if "memory" in row:
                    yield error_row(job.id, "WorkerMemory", "the row ran out of memory", duration_s=now - started)
                    fresh = self._replace(actor)
                    starting[fresh.pid.remote()] = fresh
                    continue
                done = self._rows_done[actor._actor_id.hex()] = self._rows_done.get(actor._actor_id.hex(), 0) + 1
                if done >= self.max_rows_per_worker:  # a fresh actor: a native leak must not grow without bound
                    fresh = self._replace(actor, recycle=True)
                    starting[fresh.pid.remote()] = fresh
                else:
                    idle.append(actor)
                yield row
            if starting and not idle and not flight and now - waiting_since > STARTUP_TIMEOUT_S:
                raise BatchError(
                    f"no Ray actor started within {STARTUP_TIMEOUT_S:g} s: does the cluster have a free CPU for each "
                    f"of the {self.workers} workers?"
                )
            for ref, (actor, job, started) in list(flight.items()):
                if now - started > self.timeout_s:
                    flight.pop(ref)
                    self._running.pop(actor._actor_id.hex(), None)
                    yield error_row(
                        job.id, "WorkerTimeout", f"the row took longer than its timeout of {self.timeout_s:g} s", duration_s=now - started
                    )
                    fresh = self._replace(actor)
                    starting[fresh.pid.remote()] = fresh

    def _replace(self, actor, recycle: bool = False):
        self._ray.kill(actor, no_restart=True)
        self._rows_done.pop(actor._actor_id.hex(), None)
        fresh = self._spawn()
        self._actors[self._actors.index(actor)] = fresh
        if recycle:
            self.recycled += 1
        else:
            self.restarts += 1
        return fresh
