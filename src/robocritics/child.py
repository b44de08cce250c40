"""One warm ``spawn`` child process with limits: how the studio and the batch engine run untrusted checks.

The studio's :class:`~robocritics.viz.studio.worker.Evaluator` and the batch
:class:`~robocritics.batch.local.LocalEngine` both check programs an LLM wrote
in child processes, so that a limit hit or a crash in a native library
(Pinocchio, coal) ends the child, not the caller. This module is what they
share: the start (``spawn``, since the callers have threads and forking them is
unsafe; single-threaded BLAS in the child's environment before it imports
numpy), the address-space limit, the child's CPU time as the kernel counts it,
and the description of how a child died.

A ``spawn`` child re-imports the main module of a script: a script that starts
one at import time must do so under ``if __name__ == "__main__":`` (console
scripts, notebooks and pytest need nothing).
"""

from __future__ import annotations

import multiprocessing
import os
import resource
import signal
import threading
import time
from collections.abc import Callable, Mapping

from ._threads import SINGLE_THREADED_ENV

__all__ = ["Child", "MAX_JOBS_PER_CHILD", "SINGLE_THREADED_ENV", "WORKER_ENV", "MALLOC_TUNABLES", "address_space_limit", "cpu_seconds", "limit_address_space"]

#: glibc malloc settings of a warm child (``GLIBC_TUNABLES``, read when the interpreter starts; other C libraries
#: ignore it): arrays up to 32 MiB come from the heap instead of fresh ``mmap`` pages, and up to 64 MiB of freed heap
#: is kept instead of returned. A check allocates a few MB per array (``(pairs, samples)`` float64) and frees it;
#: with glibc's defaults every program faults in ~1,700 fresh zeroed pages (~5-10 % of a warm check's CPU,
#: ``benchmarks/bench_pipeline.py``), with these ~1. The price: up to 64 MiB of free heap held per child.
MALLOC_TUNABLES = "glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=67108864"

#: Jobs a warm child runs before a fresh one replaces it (between jobs; not a failure). Native libraries may leak
#: per program (coal's Qhull leaks the hull it refuses: ~0.5 MB for a 3,000-point fan), and a leak must not grow
#: until an innocent job hits the address-space limit; a restart (~1-2 s) over this many jobs costs a few per cent.
MAX_JOBS_PER_CHILD = 1000

#: Environment a warm child starts with: :data:`SINGLE_THREADED_ENV` and :data:`MALLOC_TUNABLES` (a
#: ``GLIBC_TUNABLES`` the user exported is kept: :meth:`Child.__init__` sets only what is unset).
WORKER_ENV: Mapping[str, str] = {**SINGLE_THREADED_ENV, "GLIBC_TUNABLES": MALLOC_TUNABLES}

# os.environ is process-wide: a child is started with its environment under this lock.
_ENV_LOCK = threading.Lock()


def address_space_limit(memory_bytes: int) -> int:
    """The address-space limit a child can set for a wanted ``memory_bytes``, bytes: the lower of it and this
    process's hard ``RLIMIT_AS`` (``ulimit -v``), which a child inherits and may lower but never raise."""
    hard = resource.getrlimit(resource.RLIMIT_AS)[1]
    return memory_bytes if hard == resource.RLIM_INFINITY else min(memory_bytes, hard)


def limit_address_space(memory_bytes: int) -> int:
    """In the child: cap its address space at ``memory_bytes`` bytes, or at the hard limit it inherited if that is
    lower (:func:`address_space_limit`; ``RLIMIT_AS``); an allocation past it raises MemoryError (or kills a native
    library that does not check). Returns the limit set, bytes."""
    limit = address_space_limit(memory_bytes)
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    return limit


def cpu_seconds(pid: int) -> float:
    """utime + stime of process ``pid`` from /proc/<pid>/stat, s (0 if it is gone)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
    except (OSError, IndexError):
        return 0.0
    # fields[0] is field 3 (state): utime and stime are fields 14 and 15
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class Child:
    """A started ``spawn`` child running ``target(conn, *args)``, with ``conn`` its end of a duplex pipe.

    ``env`` is set in the child's environment before it starts (numpy reads it on import, glibc at exec), except
    ``GLIBC_TUNABLES`` when the user has exported one;
    ``started`` is the monotonic time it was started, s.
    """

    def __init__(self, target: Callable, args: tuple, *, name: str, env: Mapping[str, str] = WORKER_ENV):
        context = multiprocessing.get_context("spawn")
        parent, child = context.Pipe()
        self.process = context.Process(target=target, args=(child, *args), name=name, daemon=True)
        with _ENV_LOCK:  # the spawned interpreter inherits os.environ as it is at start()
            saved = {k: os.environ.get(k) for k in env}
            os.environ.update({k: v for k, v in env.items() if k != "GLIBC_TUNABLES" or saved[k] is None})
            try:
                self.process.start()
            finally:
                for k, v in saved.items():
                    if v is None:
                        os.environ.pop(k, None)
                    else:
                        os.environ[k] = v
        child.close()
        self.conn = parent
        self.started = time.monotonic()

    @property
    def pid(self) -> int | None:
        return self.process.pid

    @property
    def exitcode(self) -> int | None:
        """The exit code once it has ended (negative: the signal that ended it), else None."""
        return self.process.exitcode

    def is_alive(self) -> bool:
        return self.process.is_alive()

    def kill(self) -> None:
        """SIGKILL the child, reap it and close the pipe. Idempotent."""
        if self.process.is_alive():
            self.process.kill()
        self.process.join(10.0)
        self.conn.close()

    def death(self) -> str:
        """How the child ended, e.g. ``"signal SIGKILL"`` or ``"exit code 1"`` (waits up to 5 s for it)."""
        self.process.join(5.0)
        code = self.process.exitcode
        if code is not None and code < 0:
            try:
                return f"signal {signal.Signals(-code).name}"
            except ValueError:
                return f"signal {-code}"
        return f"exit code {code}"
