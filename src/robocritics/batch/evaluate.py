"""``evaluate(rows, engine=...)``: many programs, one output row each, as they finish."""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from typing import Any

from .rows import Job, RowError, check_row, error_row, plain_id

__all__ = ["evaluate", "jobs_of", "ENGINES"]

ENGINES = ("local", "ray")


def _shown_id(row: Any) -> str | int | None:
    """The id an error row echoes: the row's own if it is a valid id, else None (an over-long or broken id
    is not copied into the output)."""
    return plain_id(row.get("id")) if isinstance(row, Mapping) else None


def jobs_of(rows: Iterable[Any]) -> Iterator[Job | dict]:
    """The :class:`Job` of each input row, read lazily; a bad row (or a :class:`RowError` item, a reader's way
    of reporting an unreadable line) is its error row (a dict) instead, in its place: the engines pass such rows
    straight through, so a million bad lines are never held in memory at once."""
    seen: set = set()
    for row in rows:
        if isinstance(row, RowError):
            yield error_row(getattr(row, "row_id", None), "RowError", str(row))
            continue
        try:
            job = check_row(row)
            if job.id in seen:
                raise RowError(f"duplicate id {job.id!r}: an earlier row has it, so this one is not evaluated")
        except RowError as exc:
            shown = _shown_id(row)
            where = getattr(row, "input_line", 0)  # a reader's line number (robocritics batch)
            yield error_row(shown, "RowError", f"input line {where}: {exc}" if where else str(exc))
            continue
        seen.add(job.id)
        yield job


def evaluate(
    rows: Iterable[Any],
    engine: Any = "local",
    workers: int | None = None,
    *,
    timeout_s: float | None = None,
    memory_bytes: int | None = None,
    robot=None,
    sample_rate_hz: float = 125.0,
    ray_address: str | None = None,
) -> Iterator[dict]:
    """Simulate and critique every input row, yielding one output row per input row as each finishes.

    ``rows``: input rows (see :mod:`robocritics.batch.rows`), read lazily. ``engine``: ``"local"`` (a pool of
    worker processes on this machine, :class:`~robocritics.batch.local.LocalEngine`) or ``"ray"`` (Ray actors,
    the optional extra ``robocritics[ray]``; ``ray_address`` names a cluster, default a local one).
    ``workers``: processes or actors, default the CPU count. ``timeout_s``: wall-clock limit per row, s
    (default 60); ``memory_bytes``: a local worker's address-space limit, bytes (default 3 GiB);
    ``robot``: default the UR3e; ``sample_rate_hz``: the trajectories' sample rate, Hz.

    Rows come back in the order they finish, not the input order: match them by ``id``. A bad row, scene or
    program, a worker that dies or a row over its limits is an error row; only a batch that cannot run at all
    (a worker that cannot start, ray not installed) raises :class:`~robocritics.batch.local.BatchError`.
    """
    from .local import DEFAULT_MEMORY_BYTES, DEFAULT_TIMEOUT_S, LocalEngine

    if isinstance(rows, (Mapping, str, bytes)):  # iterating one would make an error row per key or character
        what = "one row (a mapping): pass a list of rows, [row]" if isinstance(rows, Mapping) else type(rows).__name__
        raise TypeError(f"rows must be an iterable of input rows, got {what}")
    if not isinstance(engine, str):  # an open engine, reused: the caller closes it
        yield from engine.run(jobs_of(rows))
        return
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    timeout_s = DEFAULT_TIMEOUT_S if timeout_s is None else timeout_s
    jobs = jobs_of(rows)
    if engine == "local":
        pool = LocalEngine(
            workers,
            robot=robot,
            timeout_s=timeout_s,
            memory_bytes=DEFAULT_MEMORY_BYTES if memory_bytes is None else memory_bytes,
            sample_rate_hz=sample_rate_hz,
        )
    else:
        from .ray_engine import RayEngine

        pool = RayEngine(workers, robot=robot, timeout_s=timeout_s, sample_rate_hz=sample_rate_hz, address=ray_address)
    with pool:
        yield from pool.run(jobs)
