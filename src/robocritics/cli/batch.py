"""``robocritics batch IN.jsonl -o OUT.jsonl``: evaluate many programs, one output row each, streamed."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TextIO

from ._common import UsageError, bounded_float, positive_int, shown_path, subcommand

#: Longest input line, bytes: a program is at most 100,000 characters and a scene is bounded; a longer
#: line is an error row, not read whole.
MAX_LINE_BYTES = 4_000_000


@subcommand("batch")
def _build_batch(sub) -> None:
    p = sub.add_parser(
        "batch",
        help="simulate and critique many programs (JSONL rows) on a local process pool or a Ray cluster",
        description="Evaluate every row of IN (JSON lines: {\"id\", \"scene\", \"program\", \"goal\"?, \"critics\"?, "
        "\"params\"?}) and write one output row per input row to OUT as each finishes ({\"id\", \"score\", \"flags\", "
        "\"passed\", \"duration_s\", \"samples\", \"error\"}). A bad row, scene or program, or a worker that dies "
        "or times out, is an error row. Progress goes to stderr. Exit status: 0 every row was evaluated (error "
        "rows included: they are results), 2 bad usage, 130 interrupted (rerun with --resume).",
    )
    p.add_argument("input", metavar="IN.jsonl", help="input rows, one JSON object per line")
    p.add_argument("-o", "--output", metavar="OUT.jsonl", required=True,
                   help="output rows (JSON lines; Parquet when the name ends in .parquet, which needs pyarrow)")  # fmt: skip
    p.add_argument("--engine", choices=("local", "ray"), default="local",
                   help="local: worker processes on this machine (default); ray: Ray actors (robocritics[ray])")  # fmt: skip
    p.add_argument("--workers", type=positive_int, metavar="N", help="worker processes or actors; default the CPUs")
    p.add_argument("--ray-address", metavar="ADDR", help="a running Ray cluster (e.g. ray://head:10001); default a "
                   "local one on 127.0.0.1")  # fmt: skip
    p.add_argument("--resume", action="store_true", help="keep OUT's rows and evaluate only the ids not in it")
    p.add_argument("--timeout", type=bounded_float(0.001, 86400.0, "s"), default=60.0, metavar="S",
                   help="wall-clock limit per row, s (default 60): a slower row's worker is replaced")  # fmt: skip
    p.set_defaults(func=_cmd_batch)


# --- input ----------------------------------------------------------------------------------------


class _Line(dict):
    """An input row that remembers its line number (error messages name it)."""

    input_line = 0


def read_rows(path: str) -> Iterator[Any]:
    """The rows of the JSONL file ``path``, read lazily; a malformed line is a RowError naming its number."""
    from ..batch.rows import RowError
    from ..errors import SceneError
    from ..scene import parse_json

    try:
        f = open(path, "rb")  # noqa: SIM115 - closed below, the generator reads it lazily
    except OSError as exc:
        raise UsageError(f"input {shown_path(path)}: {exc.strerror or exc}") from None
    with f:
        number = 0
        while True:
            raw = f.readline(MAX_LINE_BYTES + 1)
            if not raw:
                return
            number += 1
            if len(raw) > MAX_LINE_BYTES and not raw.endswith(b"\n"):
                while raw and not raw.endswith(b"\n"):  # skip the rest of the line
                    raw = f.readline(MAX_LINE_BYTES)
                yield RowError(f"input line {number}: longer than {MAX_LINE_BYTES:,} bytes")
                continue
            if not raw.strip():
                continue
            try:
                data = parse_json(raw.decode("utf-8"), f"input line {number}")
            except UnicodeDecodeError:
                yield RowError(f"input line {number}: not UTF-8 text")
                continue
            except SceneError as exc:
                yield RowError(str(exc) if "line" in str(exc) else f"input line {number}: {exc}")
                continue
            if not isinstance(data, dict):
                yield RowError(f"input line {number}: a row must be a JSON object, got {type(data).__name__}")
                continue
            row = _Line(data)
            row.input_line = number
            yield row


def count_rows(path: str) -> int:
    """Non-blank lines of ``path`` (the progress total)."""
    with open(path, "rb") as f:
        return sum(1 for line in f if line.strip())


# --- output ---------------------------------------------------------------------------------------


def _key(row_id: Any) -> str:
    return json.dumps(row_id)


def done_rows(path: Path) -> list[dict]:
    """The complete rows already in the JSONL file ``path``; a torn last line (an interrupted write) is cut off."""
    if not path.exists():
        return []
    with open(path, "rb+") as f:
        data = f.read()
        end = data.rfind(b"\n") + 1
        if end < len(data):  # a torn last line: drop it, so the next row starts on its own line
            f.truncate(end)
    rows = []
    for line in data[:end].splitlines():
        try:
            row = json.loads(line)
        except ValueError:
            continue
        if isinstance(row, dict) and "id" in row:
            rows.append(row)
    return rows


class JsonlWriter:
    """Output rows as JSON lines, flushed per row (a reader sees each row as it finishes)."""

    def __init__(self, path: Path, append: bool):
        self.f = open(path, "a" if append else "w", encoding="utf-8")  # noqa: SIM115

    def write(self, row: dict) -> None:
        self.f.write(json.dumps(row, allow_nan=False) + "\n")
        self.f.flush()

    def close(self) -> None:
        self.f.close()


class ParquetWriter:
    """Output rows as Parquet (pyarrow), a row group per :data:`GROUP_ROWS` rows; ``flags`` and ``error`` are
    JSON text columns. Parquet cannot be appended to, so ``--resume`` rewrites the file with the old rows first."""

    GROUP_ROWS = 64

    def __init__(self, path: Path, old_rows: list[dict]):
        self.pa, self.pq = _pyarrow()
        self.path, self.tmp = path, path.with_name(path.name + ".partial")
        self.schema = self.pa.schema([
            ("id", self.pa.string()), ("score", self.pa.float64()), ("flags", self.pa.string()),
            ("passed", self.pa.bool_()), ("duration_s", self.pa.float64()), ("samples", self.pa.int64()),
            ("error", self.pa.string()),
        ])  # fmt: skip
        self.writer = self.pq.ParquetWriter(str(self.tmp), self.schema)
        self.pending: list[dict] = []
        for row in old_rows:
            self.write(row)

    @staticmethod
    def flat(row: dict) -> dict:
        return {**row, "id": row["id"] if isinstance(row["id"], str) or row["id"] is None else json.dumps(row["id"]),
                "flags": json.dumps(row["flags"]), "error": None if row["error"] is None else json.dumps(row["error"])}  # fmt: skip

    def write(self, row: dict) -> None:
        self.pending.append(self.flat(row))
        if len(self.pending) >= self.GROUP_ROWS:
            self._flush()

    def _flush(self) -> None:
        if self.pending:
            self.writer.write_table(self.pa.Table.from_pylist(self.pending, schema=self.schema))
            self.pending = []

    def close(self) -> None:
        self._flush()
        self.writer.close()
        os.replace(self.tmp, self.path)


def _pyarrow():
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise UsageError("writing Parquet (an output name ending in .parquet) needs pyarrow: pip install pyarrow") from None
    return pa, pq


def parquet_rows(path: Path) -> list[dict]:
    if not path.exists():
        return []
    _, pq = _pyarrow()
    rows = pq.read_table(str(path)).to_pylist()
    for row in rows:
        row["flags"] = json.loads(row["flags"] or "{}")
        row["error"] = None if row["error"] is None else json.loads(row["error"])
    return rows


# --- progress -------------------------------------------------------------------------------------


class Progress:
    """Rows done, rate (rows/s) and ETA on ``stream``: a ``\\r`` bar on a terminal, else a line per ``every`` rows.

    ``clock`` returns seconds (monotonic); injected by tests.
    """

    def __init__(self, total: int, stream: TextIO, clock: Callable[[], float] = time.monotonic, every: int | None = None):
        self.total, self.stream, self.clock = total, stream, clock
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        self.every = every or max(1, total // 20)
        self.started = clock()
        self.done = self.errors = 0

    def text(self) -> str:
        elapsed = max(self.clock() - self.started, 1e-9)
        rate = self.done / elapsed
        left = max(self.total - self.done, 0)
        eta = f"{left / rate:.0f} s" if rate > 0 else "?"
        pct = 100.0 * self.done / self.total if self.total else 100.0
        return f"{self.done}/{self.total} rows ({pct:.0f} %), {self.errors} error rows, {rate:.2f} rows/s, ETA {eta}"

    def update(self, row: dict) -> None:
        self.done += 1
        self.errors += row.get("error") is not None
        if self.tty:
            width = 30
            filled = int(width * self.done / self.total) if self.total else width
            self.stream.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {self.text()}")
            self.stream.flush()
        elif self.done % self.every == 0 or self.done == self.total:
            self.stream.write(f"robocritics batch: {self.text()}\n")
            self.stream.flush()

    def finish(self) -> None:
        if self.tty:
            self.stream.write("\n")
        elapsed = self.clock() - self.started
        self.stream.write(f"robocritics batch: {self.done} rows in {elapsed:.1f} s, {self.errors} error rows\n")
        self.stream.flush()


# --- the command ----------------------------------------------------------------------------------


def _cmd_batch(args: argparse.Namespace) -> int:
    from ..batch import evaluate
    from ..batch.local import BatchError

    source = Path(args.input)
    if not source.is_file():
        raise UsageError(f"input {shown_path(args.input)} is not a file")
    out = Path(args.output)
    if not out.resolve().parent.is_dir():
        raise UsageError(f"--output {shown_path(args.output)}: the directory {out.resolve().parent} does not exist")
    parquet = out.suffix.lower() == ".parquet"
    if parquet:
        _pyarrow()  # fail before any work
    old = (parquet_rows(out) if parquet else done_rows(out)) if args.resume else []
    done = {_key(r["id"]) for r in old if r.get("id") is not None}
    reported = {json.dumps(r.get("error"), sort_keys=True) for r in old if r.get("id") is None}

    def pending() -> Iterator[Any]:
        for row in read_rows(args.input):
            if isinstance(row, dict) and _key(row.get("id")) in done:
                continue
            yield row

    total = count_rows(args.input) - len(old)
    writer = ParquetWriter(out, old) if parquet else JsonlWriter(out, append=args.resume)
    progress = Progress(max(total, 0), sys.stderr)
    try:
        rows = evaluate(pending(), args.engine, args.workers, timeout_s=args.timeout, ray_address=args.ray_address)
        for row in rows:
            if row["id"] is None and json.dumps(row["error"], sort_keys=True) in reported:
                continue  # an unreadable line already reported before --resume
            writer.write(row)
            progress.update(row)
    except BatchError as exc:
        raise UsageError(str(exc)) from None
    finally:
        writer.close()
    progress.finish()
    return 0
