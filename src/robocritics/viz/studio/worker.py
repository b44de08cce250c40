"""Check programs for the studio in one warm, resource-limited child process.

The studio runs :func:`~robocritics.pipeline.simulate` and
:func:`~robocritics.critic.critique` on programs an LLM (or a user) wrote. The
sandbox bounds what a program can do, but planning and critiquing a motion
still costs memory and CPU, and a bug in a native library (Pinocchio, coal) can
crash the process. So every check runs in a child process started with the
``spawn`` context (the studio's server has threads; forking them is unsafe),
kept warm between jobs (imports and the robot model loaded once), with limits
set in the child:

* address space (``RLIMIT_AS``, :data:`DEFAULT_MEMORY_BYTES`);
* CPU seconds per job: a watchdog in the parent reads the child's
  ``/proc/<pid>/stat`` while it works, and ``RLIMIT_CPU`` (the soft limit
  raised before each job to what the child has used plus the job's allowance
  plus :data:`CPU_BACKSTOP_S`) kills it should the parent miss it;
* wall-clock seconds per job (``timeout_s``).

A job that exceeds a limit, or that the child dies during (MemoryError,
segfault, ``os._exit``, killed), is reported as an :class:`EvaluatorError` in
:attr:`Evaluation.error` and the child is replaced, so the next job works.
Jobs run one at a time (a lock): the Evaluator is safe to share between
threads.

A script that makes an Evaluator at import time must do so under
``if __name__ == "__main__":`` (see :mod:`robocritics.child`).
"""

from __future__ import annotations

import math
import os
import resource
import signal
import threading
import time
import traceback
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ...child import MAX_JOBS_PER_CHILD, Child, cpu_seconds, limit_address_space
from ...errors import CriticError, PlanningError, ProgramError, RoboCriticsError, SceneError, TrajectoryError

if TYPE_CHECKING:  # pragma: no cover
    from ...critic.report import Report
    from ...robot.model import Robot
    from ...scene import Scene
    from ...execution import Execution

__all__ = [
    "DEFAULT_CPU_S",
    "DEFAULT_MEMORY_BYTES",
    "DEFAULT_TIMEOUT_S",
    "Evaluation",
    "Evaluator",
    "EvaluatorError",
]

#: Address-space limit of the child, bytes (a checked sorting program peaks near 0.5 GB of address space).
DEFAULT_MEMORY_BYTES = 3 * 1024**3
#: CPU seconds one job may use in the child.
DEFAULT_CPU_S = 60.0
#: Wall-clock seconds one job may take.
DEFAULT_TIMEOUT_S = 60.0
#: Wall-clock seconds the child may take to start (imports, the robot model).
STARTUP_TIMEOUT_S = 120.0
#: CPU seconds past a job's allowance at which RLIMIT_CPU kills the child, should the parent's watchdog miss it.
CPU_BACKSTOP_S = 2.0
# How often the parent looks at the child's CPU time while a job runs, s.
_WATCH_INTERVAL_S = 0.05
# The program the child checks once at start, so the first job does not pay for first-use work.
_WARM_UP = "home()\n"
# Types sent back by name and rebuilt in the parent (their constructors take (reason, line[, col])).
_TYPED = {cls.__name__: cls for cls in (ProgramError, PlanningError, SceneError, TrajectoryError, CriticError)}


class EvaluatorError(RoboCriticsError):
    """A check could not finish in the worker process: a limit was hit or the process died.

    ``limit`` names the limit (``"timeout_s"``, ``"cpu_s"``, ``"memory_bytes"``) or is ``""`` for a
    process that died otherwise; ``value`` is that limit's value (s or bytes), None if no limit.
    """

    def __init__(self, message: str, limit: str = "", value: float | None = None):
        self.limit = limit
        self.value = value
        self.reason = message
        super().__init__(message)


@dataclass
class Evaluation:
    """The outcome of one :meth:`Evaluator.evaluate`.

    ``error`` is None or ``{"type", "message", "line", "col"}`` (the error's type name, its reason
    without the position, 1-based program line and column, 0 if unknown); an ``"EvaluatorError"``
    also has ``"limit"`` and ``"value"`` (:class:`EvaluatorError`). ``duration_s`` is the
    job's wall time, s; ``cpu_s`` the CPU time the child spent on it, s.
    """

    program: str
    report: Report | None = None
    execution: Execution | None = None
    error: dict[str, Any] | None = None
    duration_s: float = 0.0
    cpu_s: float = 0.0
    repair: Any = None  # the Repair of a repair job (Evaluator.loop_repair)

    @property
    def ok(self) -> bool:
        return self.error is None and self.report is not None


def _error_dict(exc: BaseException) -> dict[str, Any]:
    error = {
        "type": type(exc).__name__,
        "message": str(getattr(exc, "reason", None) or exc),
        "line": int(getattr(exc, "line", 0) or 0),
        "col": int(getattr(exc, "col", 0) or 0),
    }
    if isinstance(exc, EvaluatorError):
        error.update(type="EvaluatorError", limit=exc.limit, value=exc.value)
    return error


def _rebuild(error: Mapping[str, Any]) -> RoboCriticsError:
    """The typed error an :attr:`Evaluation.error` describes (the Loop's runtime feedback reads its fields)."""
    kind, message, line = error["type"], error["message"], int(error.get("line") or 0)
    if kind in ("URScriptError", "UnsupportedURScript"):  # URScript has lines, no columns
        from ...formats.urscript import URScriptError

        return URScriptError(message, line)
    if kind == "ProgramError":
        return ProgramError(message, line, int(error.get("col") or 0))
    if kind == "MotionBudgetError" or kind == "PlanningError":
        return PlanningError(message, line)
    if kind in _TYPED:
        return _TYPED[kind](message)
    if kind == "EvaluatorError":
        return EvaluatorError(message, error.get("limit", ""), error.get("value"))
    return EvaluatorError(f"the check failed in the worker: {kind}: {message}")


# --- the child ------------------------------------------------------------------------------------


def _serve(conn, scene, robot, critics, params, goals, sample_rate_hz, memory_bytes) -> None:
    """The child's main loop: set the limits, warm up, then answer ``(kind, program, critics, params, cpu_s, motion)``
    jobs.

    ``kind`` is ``"check"`` (simulate and critique), ``"repair"`` (:func:`robocritics.repair.repair`, whose
    every re-simulation then runs under this process's limits too), ``"urscript"`` or ``"recording"`` (motion
    from another tool, :func:`_imported`).
    """
    limit_address_space(memory_bytes)
    try:
        from ...critic import critique
        from ...pipeline import check, simulate
        from ...robot.model import default_robot

        robot = robot if robot is not None else default_robot()
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, which raises it typed
        conn.send(("failed", f"{type(exc).__name__}: {exc}"))
        return
    rate = {} if sample_rate_hz is None else {"sample_rate_hz": sample_rate_hz}
    try:  # warm up: the first check builds the scene's collision models and the critics' caches
        critique(simulate(_WARM_UP, scene, robot, **rate).trajectory, scene, critics, params)
    except RoboCriticsError:
        pass  # a scene or critic the warm-up cannot check: each job reports its own error
    conn.send(("ready", os.getpid()))
    hard = resource.getrlimit(resource.RLIMIT_CPU)[1]
    while True:
        try:
            job = conn.recv()
        except EOFError:
            return
        kind, program, job_critics, job_params, cpu_s, motion = job
        used = time.process_time()
        soft = math.ceil(used + cpu_s + CPU_BACKSTOP_S)
        resource.setrlimit(resource.RLIMIT_CPU, (soft if hard == resource.RLIM_INFINITY else min(soft, hard), hard))
        try:
            repaired = None
            if kind == "repair":
                from ...repair import repair

                repaired = repair(program, scene, goal=goals or None, critics=job_critics, robot=robot,
                                  params=job_params or None)  # fmt: skip
                execution, report = repaired.execution, repaired.report
            elif kind in ("urscript", "recording"):  # motion from another tool: no goals (it names no grasps)
                execution = _imported(kind, program, motion, scene, robot)
                report = critique(execution, scene, job_critics, job_params)
            else:
                checked = check(program, scene, robot=robot, goals=goals, critics=job_critics, params=job_params,
                                **rate)  # fmt: skip
                if checked.error is not None:  # the program did not run: the parent rebuilds this error, typed
                    raise checked.error
                execution, report = checked
            conn.send(("done", execution, report, None, time.process_time() - used, repaired))
        except MemoryError:
            _out_of_memory(conn, time.process_time() - used)
        except Exception as exc:  # noqa: BLE001 - typed errors, a bug in a check, a result that does not pickle
            if not isinstance(exc, RoboCriticsError):
                traceback.print_exc()
            try:
                conn.send(("done", None, None, _error_dict(exc), time.process_time() - used, None))
            except MemoryError:
                _out_of_memory(conn, time.process_time() - used)


def _imported(kind: str, program: str, motion: dict, scene, robot):
    """The Execution of a URScript ``program`` (its text) or of the recording at path ``program``, read and
    bounded by :mod:`robocritics.formats` in this limited process. ``motion``: ``name`` (the file's) and the
    keyword options of :func:`~robocritics.formats.load_motion` (``passes``, ``tcp``, ``payload_kg``,
    ``start_q``, ``gripper_io`` for a script; ``topic`` for a rosbag)."""
    options = {k: v for k, v in motion.items() if v is not None}
    if kind == "urscript":
        from ...formats.urscript import ArmOptions, run_urscript

        arm = ArmOptions(**{k: (tuple(v) if k in ("tcp", "start_q") else v) for k, v in options.items()
                            if k in ("tcp", "payload_kg", "start_q", "gripper_io")})
        return run_urscript(program, robot, scene, arm, passes=int(options.get("passes", 1)),
                            name=options.get("name") or "script")
    from ...formats import load_motion

    return load_motion(program, robot, scene, topic=options.get("topic"))


def _out_of_memory(conn, cpu_s: float) -> None:
    """Tell the parent the job ran out of memory, then exit: the heap may be in any state."""
    try:
        conn.send(("memory", cpu_s))
    finally:
        os._exit(1)


# --- the parent -----------------------------------------------------------------------------------


class Evaluator:
    """Simulate and critique programs in one warm child process with memory, CPU and time limits.

    ``scene``, ``robot`` (default the UR3e, loaded in the child), ``critics``, ``params`` and
    ``sample_rate_hz`` (Hz) are as in :func:`~robocritics.pipeline.simulate` and
    :func:`~robocritics.critic.critique`; ``critics``/``params`` are checked here and are the
    defaults for :meth:`evaluate`. ``goals`` are task goals (``"green_apple in white_box"``, checked here
    against the scene: a bad one raises GoalError) that ``task_outcome`` checks on every job's final scene,
    together with the program's own ``expect(...)`` calls. ``timeout_s`` is the wall-clock limit per job, s; ``cpu_s`` the
    CPU limit per job, s; ``memory_bytes`` the child's address-space limit, bytes.
    Use it as a context manager, or call :meth:`close`.
    """

    def __init__(
        self,
        scene: Scene,
        robot: Robot | None = None,
        *,
        critics: Iterable[str] | str | None = None,
        params: Mapping[str, Any] | None = None,
        goals: Iterable[Any] | str | None = None,
        sample_rate_hz: float | None = None,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        memory_bytes: int = DEFAULT_MEMORY_BYTES,
        cpu_s: float = DEFAULT_CPU_S,
    ):
        from ...critic import select_critics
        from ...goals import parse_goals

        if not timeout_s > 0 or not cpu_s > 0 or not memory_bytes > 0:
            raise ValueError(
                f"timeout_s, cpu_s and memory_bytes must be positive, got {timeout_s}, {cpu_s}, {memory_bytes}"
            )
        self.critics = self._names(critics, params, select_critics)
        self.params = dict(params or {})
        self.scene = scene
        self.goals = parse_goals(goals, scene)
        self.robot = robot
        self.sample_rate_hz = None if sample_rate_hz is None else float(sample_rate_hz)
        self.timeout_s = float(timeout_s)
        self.cpu_s = float(cpu_s)
        self.memory_bytes = int(memory_bytes)
        self.restarts = 0  # children replaced after a crash or a limit
        self.recycled = 0  # children replaced after max_jobs jobs
        self.max_jobs = MAX_JOBS_PER_CHILD  # jobs a child runs before a fresh one replaces it (robocritics.child)
        self._lock = threading.Lock()
        self._closed = False
        self._child: Child | None = None
        self._ready = False
        self._start()

    @staticmethod
    def _names(critics, params, select_critics) -> list[str] | None:
        if isinstance(critics, str):
            critics = [c.strip() for c in critics.split(",") if c.strip()]
        selected = select_critics(critics, params)  # fail fast on unknown critics / parameters
        return None if critics is None else [critic.name for critic, _ in selected]

    # --- the child's lifetime ---

    @property
    def pid(self) -> int | None:
        """The child's process id (None when closed or not started)."""
        return None if self._child is None else self._child.pid

    @property
    def _conn(self):
        return self._child.conn  # type: ignore[union-attr]

    def _start(self) -> None:
        args = (self.scene, self.robot, self.critics, self.params, self.goals, self.sample_rate_hz, self.memory_bytes)
        self._child = Child(_serve, args, name="robocritics-evaluator")
        self._ready = False
        self._jobs_done = 0

    def _stop(self) -> None:
        child, self._child = self._child, None
        if child is not None:
            child.kill()

    def _replace(self) -> None:
        self._stop()
        if not self._closed:
            self.restarts += 1
            self._start()

    def _await_ready(self) -> None:
        """Wait for the child's warm-up; a child that cannot start is an EvaluatorError."""
        if self._ready:
            return
        assert self._child is not None
        if not self._conn.poll(STARTUP_TIMEOUT_S):
            raise EvaluatorError(f"the worker did not start within {STARTUP_TIMEOUT_S:g} s", "startup", STARTUP_TIMEOUT_S)
        try:
            message = self._conn.recv()
        except (EOFError, OSError):
            raise self._death("while starting") from None
        if message[0] != "ready":
            raise EvaluatorError(
                f"the worker could not start within its address-space limit (memory_bytes={self.memory_bytes} bytes): "
                f"{message[1]}",
                "memory_bytes",
                self.memory_bytes,
            )
        self._ready = True

    def _death(self, when: str) -> EvaluatorError:
        assert self._child is not None
        how = self._child.death()
        if self._child.exitcode == -signal.SIGXCPU:
            return EvaluatorError(
                f"the check used more than its CPU limit of {self.cpu_s:g} s (cpu_s; RLIMIT_CPU stopped it)",
                "cpu_s",
                self.cpu_s,
            )
        return EvaluatorError(f"the worker process died {when} ({how})")

    def close(self) -> None:
        """Kill the child; a job running in another thread ends with an EvaluatorError. Idempotent."""
        self._closed = True
        child = self._child
        if child is not None and child.is_alive():
            child.process.kill()  # now: a job in another thread holds the lock and sees the pipe close
        with self._lock:
            self._stop()

    def __enter__(self) -> Evaluator:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def __del__(self) -> None:  # a forgotten Evaluator must not leave its child behind
        child = getattr(self, "_child", None)
        if child is not None and child.is_alive():
            child.process.kill()

    # --- jobs ---

    def evaluate(
        self,
        program: str,
        critics: Iterable[str] | str | None = None,
        params: Mapping[str, Any] | None = None,
    ) -> Evaluation:
        """Simulate and critique ``program`` in the child; every failure comes back in ``error``.

        ``critics``/``params`` default to the Evaluator's. Raises only for a closed Evaluator
        (EvaluatorError), a non-str program (TypeError) or unknown critics/parameters (CriticError).
        """
        return self._job("check", program, critics, params)

    def evaluate_motion(self, kind: str, program: str, name: str = "", **options) -> Evaluation:
        """Like :meth:`evaluate` for motion from another tool (:mod:`robocritics.formats`): ``kind``
        ``"urscript"`` with ``program`` the script's text and ``name`` its file's, or ``"recording"`` with
        ``program`` the path of a recording (ur_rtde or generic CSV, JointTrajectory JSON, MoveIt YAML, rosbag2),
        read in the child under its limits. ``options``: ``passes``, ``tcp``, ``payload_kg``, ``start_q``,
        ``gripper_io`` (a script), ``topic`` (a rosbag), as :func:`~robocritics.formats.load_motion` takes them."""
        if kind not in ("urscript", "recording"):
            raise ValueError(f"kind must be 'urscript' or 'recording', got {kind!r}")
        unknown = set(options) - {"passes", "tcp", "payload_kg", "start_q", "gripper_io", "topic"}
        if unknown:
            raise TypeError(f"evaluate_motion: unknown option(s) {', '.join(sorted(unknown))}")
        return self._job(kind, program, None, None, {"name": name, **options})

    def _job(self, kind: str, program: str, critics, params, motion: dict | None = None) -> Evaluation:
        from ...critic import select_critics

        if not isinstance(program, str):
            raise TypeError(f"program must be a str, got {type(program).__name__}")
        job_critics = self.critics if critics is None else self._names(critics, params, select_critics)
        job_params = self.params if params is None else dict(params)
        if params is not None and critics is None:
            select_critics(job_critics, job_params)
        with self._lock:
            if self._closed:
                raise EvaluatorError("the Evaluator is closed")
            assert self._child is not None
            evaluation = Evaluation(program)
            try:
                # died between jobs (killed from outside): start afresh. An idle, ready child sends nothing, so a
                # readable pipe is its end closing (seen before the process can be reaped).
                if not self._child.is_alive() or (self._ready and self._conn.poll(0)):
                    self._replace()
                if self._child is None:  # close() in another thread killed it after the check above
                    raise EvaluatorError("the Evaluator was closed during the check")
                self._await_ready()
                self._run(evaluation, (kind, program, job_critics, job_params, self.cpu_s, motion or {}))
                self._jobs_done += 1
                if self._jobs_done >= self.max_jobs and not self._closed:  # bound any native leak
                    self._stop()
                    self._start()
                    self.recycled += 1
            except EvaluatorError as exc:
                evaluation.error = _error_dict(exc)
                if not self._closed:
                    self._replace()
            return evaluation

    def _run(self, evaluation: Evaluation, job: tuple) -> None:
        assert self._child is not None
        pid = self._child.pid
        cpu_before = cpu_seconds(pid)
        started = time.monotonic()
        try:
            self._conn.send(job)
            while not self._conn.poll(_WATCH_INTERVAL_S):
                evaluation.duration_s = time.monotonic() - started
                evaluation.cpu_s = cpu_seconds(pid) - cpu_before
                if self._closed:
                    raise EvaluatorError("the Evaluator was closed during the check")
                if evaluation.cpu_s > self.cpu_s:
                    raise EvaluatorError(
                        f"the check used more than its CPU limit of {self.cpu_s:g} s (cpu_s)", "cpu_s", self.cpu_s
                    )
                if evaluation.duration_s > self.timeout_s:
                    raise EvaluatorError(
                        f"the check took longer than its timeout of {self.timeout_s:g} s (timeout_s)",
                        "timeout_s",
                        self.timeout_s,
                    )
                if not self._child.is_alive() and not self._conn.poll():
                    raise self._death("during the check")
            answer = self._conn.recv()
        except (EOFError, OSError):
            if self._closed:
                raise EvaluatorError("the Evaluator was closed during the check") from None
            raise self._death("during the check") from None
        finally:
            evaluation.duration_s = time.monotonic() - started
        if evaluation.duration_s > self.timeout_s:
            # the answer came after the deadline, between two looks (this thread was not scheduled on a loaded
            # host): a job is judged by when it ended, not by when it was last looked at
            raise EvaluatorError(
                f"the check took longer than its timeout of {self.timeout_s:g} s (timeout_s)", "timeout_s", self.timeout_s
            )
        if answer[0] == "memory":
            evaluation.cpu_s = float(answer[1])
            raise EvaluatorError(
                f"the check ran out of memory (address-space limit memory_bytes={self.memory_bytes} bytes)",
                "memory_bytes",
                self.memory_bytes,
            )
        _, evaluation.execution, evaluation.report, evaluation.error, evaluation.cpu_s, evaluation.repair = answer

    def loop_simulate(self, program: str) -> tuple[Execution, Report]:
        """:meth:`evaluate` for ``Loop(..., simulate=evaluator.loop_simulate)``: the errors raised, typed.

        ProgramError (with line and column), PlanningError (with line), TrajectoryError, CriticError
        and SceneError are raised as in-process checking raises them. A limit hit or a dead child
        (EvaluatorError) is raised as a ProgramError caused by it, so the Loop tells the model its
        program could not be checked instead of stopping.
        """
        evaluation = self.evaluate(program)
        if evaluation.error is None:
            assert evaluation.execution is not None and evaluation.report is not None
            return evaluation.execution, evaluation.report
        error = _rebuild(evaluation.error)
        if isinstance(error, EvaluatorError):
            raise ProgramError(f"the program could not be checked: {error.reason}") from error
        raise error

    def loop_repair(self, program: str):
        """:func:`robocritics.repair.repair` of ``program`` in the child, for ``Loop(..., repairs=evaluator.loop_repair)``.

        Returns the :class:`~robocritics.repair.Repair` (with this Evaluator's scene, critics, params and goals);
        every re-simulation a repair makes runs under the child's limits, the whole repair within one job's
        ``cpu_s`` and ``timeout_s``. A program that does not run and that no repair makes run comes back as
        :func:`~robocritics.repair.repair` returns it (no changes, the runtime report); a limit hit or a dead
        child raises :class:`EvaluatorError` (a RoboCriticsError: the Loop then asks the model instead).
        """
        evaluation = self._job("repair", program, None, None)
        if evaluation.error is None:
            return evaluation.repair
        raise _rebuild(evaluation.error)
