"""``robocritics batch IN.jsonl -o OUT.jsonl``: evaluate many programs, one output row each, streamed."""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TextIO

from ._common import (
    UsageError,
    add_robot_options,
    bounded_float,
    file_name,
    one_line,
    positive_int,
    robot_for,
    shown_path,
    subcommand,
)

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
        "rows included: they are results), 2 bad usage, 130 interrupted by Ctrl-C or SIGTERM (rerun with --resume).",
    )
    p.add_argument("input", metavar="IN.jsonl", help="input rows, one JSON object per line")
    p.add_argument("-o", "--output", metavar="OUT.jsonl", required=True, type=file_name,
                   help="output rows (JSON lines; Parquet when the name ends in .parquet, which needs pyarrow; "
                   "- for standard output)")  # fmt: skip
    add_robot_options(p)  # the rows' arm, unless a row names a bundled one ("robot"); a scene made for another is an error row
    p.add_argument("--engine", choices=("local", "ray"), default="local",
                   help="local: worker processes on this machine (default); ray: Ray actors (robocritics[ray])")  # fmt: skip
    p.add_argument("--workers", type=positive_int, metavar="N",
                   help="worker processes or actors; default the CPUs (local: at most 4 per CPU)")  # fmt: skip
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
            try:  # a file saved by a Windows editor starts with a byte-order mark: not part of the row
                data = parse_json(raw.decode("utf-8-sig" if number == 1 else "utf-8"), f"input line {number}")
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


#: Bytes :func:`count_rows` reads at a time.
COUNT_CHUNK_BYTES = 1 << 20


def count_rows(path: str) -> int:
    """Non-blank lines of ``path`` (the progress total), read in :data:`COUNT_CHUNK_BYTES` chunks: a line of
    gigabytes (which :func:`read_rows` skips as too long) is never held in memory."""
    count, blank = 0, True  # blank: the current line holds only whitespace so far
    with open(path, "rb") as f:
        while chunk := f.read(COUNT_CHUNK_BYTES):
            *ended, rest = chunk.split(b"\n")
            for part in ended:
                count += not (blank and not part.strip())
                blank = True
            blank = blank and not rest.strip()
    return count + (not blank)


# --- output ---------------------------------------------------------------------------------------


def _key(row_id: Any) -> str | None:
    """The resume key of a row's id: its JSON text (``7`` and ``"7"`` differ), None for an id no row may have
    (a float, null, an object, a parser's marker for an over-long integer: such a row is an error row)."""
    if isinstance(row_id, bool) or not isinstance(row_id, (str, int)):
        return None
    return json.dumps(row_id)


#: Longest line of an output file that can be a row, bytes (a row is a few kB: its id and error message are bounded).
_MAX_OUT_LINE_BYTES = 1 << 20


class Finished:
    """What ``--resume`` keeps of OUT's rows: the resume keys of their ids (:func:`_key`) and a 16-byte digest of
    each id-less error row's error (an unreadable input line, reported once) — never the rows themselves, so a
    million earlier rows cost their ids, not their text."""

    def __init__(self) -> None:
        self.keys: set[str] = set()
        self.reported: set[bytes] = set()

    def add(self, row_id: Any, error: Any) -> None:
        key = _key(row_id)
        if key is not None:
            self.keys.add(key)
        elif row_id is None:
            self.reported.add(error_digest(error))

    def __len__(self) -> int:
        return len(self.keys) + len(self.reported)


def error_digest(error: Any) -> bytes:
    """A 16-byte digest of an output row's ``error`` (its JSON text with sorted keys)."""
    return hashlib.blake2b(json.dumps(error, sort_keys=True).encode("utf-8", "surrogatepass"), digest_size=16).digest()


def _output_row(line: bytes) -> dict | None:
    """The output row a JSONL line holds, or None if it holds something else: not JSON, nested too deep for the
    decoder (a RecursionError, caught here: a line is at most 1 MiB), an integer of thousands of digits, another shape.

    The standard decoder, not the input rows' bounded parser: a line is already bounded, and reading the ids of a
    million rows with it costs a sixth of the CPU."""
    from ..batch.rows import OUTPUT_KEYS

    try:
        row = json.loads(line)
    except (ValueError, RecursionError):  # ValueError: not JSON, not UTF-8, an integer of over 4,300 digits
        return None
    if not (isinstance(row, dict) and set(row) == set(OUTPUT_KEYS)):
        return None
    return row if row["id"] is None or _key(row["id"]) is not None else None  # an id no output row has: not ours


def finished_jsonl(path: Path) -> Finished:
    """The ids of the rows already in the JSONL output file ``path``, read a line at a time; a torn last line (an
    interrupted write) is cut off.

    Any other line that is not an output row (a log, the wrong file, JSON nested thousands deep) means ``path``
    is not a batch's output: a UsageError naming the line, and the file is left as it was."""
    finished = Finished()
    if not os.path.lexists(path):
        return finished
    end, number = 0, 0
    with _opened(path, os.O_RDWR) as f:
        while line := f.readline(_MAX_OUT_LINE_BYTES):
            number += 1
            row = None
            if line.endswith(b"\n"):
                row = _output_row(line)
            elif len(line) < _MAX_OUT_LINE_BYTES:  # readline stopped at the end of the file
                break  # the torn last line
            if row is None:
                raise UsageError(f"--resume: line {number} of {shown_path(path)} is not an output row of robocritics "
                                 "batch; is it the right file? (it was not changed)")  # fmt: skip
            finished.add(row["id"], row["error"])
            end = f.tell()
        f.truncate(end)  # drop a torn last line, so the next row starts on its own line
    return finished


def _opened(path: Path, flags: int):
    """``path`` opened by :func:`~robocritics._files.open_regular` (no link, FIFO or device), as a UsageError."""
    from .._files import OutputFileError, open_regular

    try:
        return open_regular(path, flags, "--output")
    except OutputFileError as exc:
        raise UsageError(f"--resume: {exc}") from None


class JsonlWriter:
    """Output rows as JSON lines, flushed per row (a reader sees each row as it finishes). A new file is created
    exclusively and renamed into place at once (:func:`~robocritics._files.open_new_stream`); ``append`` opens the
    existing regular file (never a link)."""

    def __init__(self, path: Path, append: bool):
        from .._files import open_new_stream

        self.f = _opened(path, os.O_WRONLY | os.O_APPEND) if append else open_new_stream(path, "--output")

    def write(self, row: dict) -> None:
        self.f.write((json.dumps(row, allow_nan=False) + "\n").encode("utf-8"))
        self.f.flush()

    def close(self) -> None:
        self.f.close()


class StdoutWriter(JsonlWriter):
    """Output rows as JSON lines on standard output (``-o -``).

    While it is open, file descriptor 1 points at stderr and the rows go to a private copy of stdout: nothing
    else (a library printing, a worker process, which inherits descriptor 1) can write into the rows."""

    def __init__(self) -> None:
        sys.stdout.flush()
        self.saved = os.dup(1)
        os.dup2(2, 1)
        self.f = os.fdopen(os.dup(self.saved), "wb")

    def close(self) -> None:
        try:
            self.f.close()
        finally:
            os.dup2(self.saved, 1)
            os.close(self.saved)


#: The Parquet columns: an output row's fields, ``flags`` and ``error`` as JSON text, and ``id`` as text with
#: ``id_is_int`` saying whether it was an integer (``7`` and ``"7"`` are different ids; one Parquet column
#: cannot hold both types, and an id may have 20 digits, beyond int64).
PARQUET_COLUMNS = ("id", "id_is_int", "score", "flags", "passed", "duration_s", "samples", "error")


class ParquetWriter:
    """Output rows as Parquet (pyarrow), a row group per :data:`GROUP_ROWS` rows, with the columns
    :data:`PARQUET_COLUMNS`. Parquet cannot be appended to, so the rows go to a temporary file beside OUT
    (:class:`~robocritics._files.AtomicFile`: created exclusively, never through a link), renamed to OUT when the
    batch ends (or is interrupted); ``resume`` first copies OUT's rows into it, a row group at a time."""

    GROUP_ROWS = 64

    def __init__(self, path: Path, resume: bool = False):
        from .._files import AtomicFile, OutputFileError

        self.pa, self.pq = _pyarrow()
        pa = self.pa
        types = (pa.string(), pa.bool_(), pa.float64(), pa.string(), pa.bool_(), pa.float64(), pa.int64(), pa.string())
        self.schema = pa.schema(list(zip(PARQUET_COLUMNS, types)))
        try:
            self.out = AtomicFile(path, "--output", suffix=".partial")
        except OutputFileError as exc:
            raise UsageError(str(exc)) from None
        self.pending: list[dict] = []
        try:
            self.writer = self.pq.ParquetWriter(self.out.file, self.schema)
        except BaseException:
            self.out.discard()
            raise
        try:
            if resume and os.path.lexists(path):
                for batch in _parquet_batches(path, self.GROUP_ROWS):
                    self.writer.write_table(self.pa.Table.from_batches([batch]).cast(self.schema))
        except BaseException:
            self.writer.close()
            self.out.discard()
            raise

    @staticmethod
    def flat(row: dict) -> dict:
        """``row`` as a Parquet record (see :data:`PARQUET_COLUMNS`)."""
        row_id = row["id"]
        is_int = isinstance(row_id, int) and not isinstance(row_id, bool)
        return {**row, "id": str(row_id) if is_int else row_id, "id_is_int": is_int, "flags": json.dumps(row["flags"]),
                "error": None if row["error"] is None else json.dumps(row["error"])}  # fmt: skip

    def write(self, row: dict) -> None:
        self.pending.append(self.flat(row))
        if len(self.pending) >= self.GROUP_ROWS:
            self._flush()

    def _flush(self) -> None:
        if self.pending:
            self.writer.write_table(self.pa.Table.from_pylist(self.pending, schema=self.schema))
            self.pending = []

    def close(self) -> None:
        try:
            self._flush()
        finally:
            self.writer.close()
            self.out.commit()


def _pyarrow():
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise UsageError("writing Parquet (an output name ending in .parquet) needs pyarrow: pip install pyarrow") from None
    return pa, pq


def _parquet_batches(path: Path, batch_rows: int, columns: list[str] | None = None) -> Iterator[Any]:
    """The record batches of our Parquet output ``path`` (``batch_rows`` rows each); a UsageError if it is not one."""
    _, pq = _pyarrow()
    f = _opened(path, os.O_RDONLY)
    with f:
        try:
            parquet = pq.ParquetFile(f)
            names = tuple(parquet.schema_arrow.names)
        except Exception as exc:  # noqa: BLE001 - pyarrow's errors have no common base but Exception
            raise UsageError(f"--resume: {shown_path(path)} is not a readable Parquet file: {one_line(exc)[:200]}") from None
        if names != PARQUET_COLUMNS:
            raise UsageError(f"--resume: {shown_path(path)} is not a robocritics batch output: its columns are "
                             f"{', '.join(names)[:200]}, not {', '.join(PARQUET_COLUMNS)}")  # fmt: skip
        try:
            yield from parquet.iter_batches(batch_size=batch_rows, columns=columns)
        except Exception as exc:  # noqa: BLE001 - as above
            raise UsageError(f"--resume: {shown_path(path)} is not a readable Parquet file: {one_line(exc)[:200]}") from None


def _parquet_record(rec: dict) -> dict:
    """A Parquet record (:data:`PARQUET_COLUMNS`) as the output row JSONL would hold."""
    from ..batch.rows import OUTPUT_KEYS

    is_int = rec.pop("id_is_int")
    rec["id"] = int(rec["id"]) if is_int and rec["id"] is not None else rec["id"]
    rec["flags"] = json.loads(rec["flags"] or "{}")
    rec["error"] = None if rec["error"] is None else json.loads(rec["error"])
    return {k: rec[k] for k in OUTPUT_KEYS}


def finished_parquet(path: Path) -> Finished:
    """The ids of the rows in the Parquet output ``path``, read a row group at a time (only the id and error columns)."""
    finished = Finished()
    if not os.path.lexists(path):
        return finished
    for batch in _parquet_batches(path, 4096, ["id", "id_is_int", "error"]):
        for rec in batch.to_pylist():
            try:
                is_int, row_id, error = rec["id_is_int"], rec["id"], rec["error"]
                row_id = int(row_id) if is_int and row_id is not None else row_id
                finished.add(row_id, None if error is None else _output_error(error))
            except (ValueError, TypeError):
                raise UsageError(f"--resume: {shown_path(path)} holds a row that is not an output row of robocritics "
                                 f"batch (id {str(rec.get('id'))[:60]!r}); is it the right file?") from None  # fmt: skip
    return finished


def _output_error(text: str) -> Any:
    """A Parquet ``error`` cell's JSON (ValueError if it is not JSON or nested too deep for the decoder)."""
    try:
        return json.loads(text)
    except RecursionError:
        raise ValueError("nested too deep") from None


def parquet_rows(path: Path) -> list[dict]:
    """Every output row of the Parquet file ``path`` (written by :class:`ParquetWriter`), as JSONL would hold them
    (all in memory: for reading a result, not for ``--resume``)."""
    if not os.path.lexists(path):
        return []
    return [_parquet_record(rec) for batch in _parquet_batches(path, 4096) for rec in batch.to_pylist()]


# --- progress -------------------------------------------------------------------------------------


class Progress:
    """Rows done, rate (rows/s) and ETA on ``stream``: a ``\\r`` bar on a terminal, else a line per ``every`` rows.

    ``total``: the input's rows; rows skipped by ``--resume`` (:meth:`skip`) count as done but not in the rate.
    ``clock`` returns seconds (monotonic); injected by tests.
    """

    def __init__(self, total: int, stream: TextIO, clock: Callable[[], float] = time.monotonic, every: int | None = None):
        self.total, self.stream, self.clock = total, stream, clock
        try:
            self.tty = bool(stream.isatty())
        except (AttributeError, OSError, ValueError):  # not a file, or a closed one
            self.tty = False
        self.every = every or max(1, total // 20)
        self.started = clock()
        self.done = self.errors = self.skipped = 0
        self._shown = 0  # characters of the last bar on a terminal

    def skip(self) -> None:
        """One input row needs no work (its id is in OUT already)."""
        self.skipped += 1

    def text(self) -> str:
        elapsed = max(self.clock() - self.started, 1e-9)
        rate = self.done / elapsed
        finished = self.done + self.skipped
        left = max(self.total - finished, 0)
        eta = f"{left / rate:.0f} s" if rate > 0 else "?"
        pct = 100.0 * min(finished, self.total) / self.total if self.total else 100.0
        kept = f", {self.skipped} kept from OUT" if self.skipped else ""
        return f"{finished}/{self.total} rows ({pct:.0f} %){kept}, {self.errors} error rows, {rate:.2f} rows/s, ETA {eta}"

    def _say(self, text: str) -> None:
        """Write ``text`` to the stream; a stream that fails (stderr closed, a full pipe) ends the progress,
        never the batch."""
        if self.stream is None:
            return
        try:
            self.stream.write(text)
            self.stream.flush()
        except (OSError, ValueError):  # ValueError: a closed file object
            self.stream = None

    def update(self, row: dict) -> None:
        self.done += 1
        self.errors += row.get("error") is not None
        finished = self.done + self.skipped
        if self.tty:
            width = 30
            filled = min(int(width * finished / self.total), width) if self.total else width
            bar = f"[{'#' * filled}{'.' * (width - filled)}] {self.text()}"
            self._say(f"\r{bar.ljust(self._shown)}")  # spaces over the end of a longer earlier bar
            self._shown = len(bar)
        elif self.done % self.every == 0 or finished == self.total:
            self._say(f"robocritics batch: {self.text()}\n")

    def finish(self, interrupted: bool = False) -> None:
        elapsed = self.clock() - self.started
        how = "interrupted after " if interrupted else ""
        kept = f" ({self.skipped} kept from OUT)" if self.skipped else ""
        end = "\n" if self.tty else ""
        self._say(f"{end}robocritics batch: {how}{self.done} rows in {elapsed:.1f} s, {self.errors} error rows{kept}\n")


# --- the command ----------------------------------------------------------------------------------


def _check_output(out: Path, source: Path) -> None:
    """A one-line UsageError for an output path the batch cannot write safely (a link, a directory, a FIFO or
    device, a missing directory: :func:`~robocritics._files.check_output_path`), or the input itself, before any work."""
    from .._files import OutputFileError, check_output_path

    try:
        check_output_path(out, "--output")
    except OutputFileError as exc:
        raise UsageError(str(exc)) from None
    if out.exists() and os.path.samefile(out, source):
        raise UsageError(f"--output {shown_path(out)} is the input file: writing it would destroy the input")


def _terminated(signum, frame) -> None:
    """SIGTERM (a scheduler, ``timeout``, ``kill``) stops the batch as Ctrl-C does: the finished rows are
    written (a Parquet file is completed), the workers stopped, the exit status 130."""
    raise KeyboardInterrupt


def _cmd_batch(args: argparse.Namespace) -> int:
    from ..batch import evaluate
    from ..batch.local import BatchError, max_workers

    source = Path(args.input)
    if not source.is_file():
        raise UsageError(f"input {shown_path(args.input)} is not a file")
    cpus = os.cpu_count() or 1
    if args.engine == "local" and args.workers is not None and args.workers > max_workers():
        raise UsageError(f"--workers {args.workers}: at most {max_workers()} on this machine ({cpus} "
                         "CPUs); each worker is a process with its own robot model, and more than the cores only "
                         "queue for them")  # fmt: skip
    to_stdout = args.output == "-"
    out = Path(args.output)
    if to_stdout and args.resume:
        raise UsageError("--resume needs an output file to read the finished rows from, not -o - (standard output)")
    if not to_stdout:
        _check_output(out, source)
    parquet = not to_stdout and out.suffix.lower() == ".parquet"
    if parquet:
        _pyarrow()  # fail before any work
    try:
        finished = (finished_parquet(out) if parquet else finished_jsonl(out)) if args.resume else Finished()
    except OSError as exc:
        raise UsageError(f"--resume: cannot read --output {shown_path(out)}: {exc.strerror or exc}") from None
    done, reported = finished.keys, finished.reported
    matched: set[str] = set()  # ids of OUT seen in IN; the others (a different input?) are kept, and said so at the end
    progress = Progress(count_rows(args.input), sys.stderr)

    def pending() -> Iterator[Any]:
        for row in read_rows(args.input):
            key = _key(row.get("id")) if isinstance(row, dict) else None
            if key in done or key in matched:  # a repeated id of IN is skipped again, as before
                if key in done:
                    done.discard(key)  # matched: moved, so OUT's ids are held once
                    matched.add(key)
                progress.skip()
                continue
            yield row

    try:
        if to_stdout:
            writer = StdoutWriter()
        else:
            writer = ParquetWriter(out, args.resume) if parquet else JsonlWriter(out, append=args.resume)
    except OSError as exc:
        raise UsageError(f"--output {shown_path(args.output)}: cannot write it: {exc.strerror or exc}") from None
    from ..scene import Scene

    robot = robot_for(args, Scene())  # a URDF's error is bad usage, before any worker starts
    rows = evaluate(pending(), args.engine, args.workers, robot=robot, timeout_s=args.timeout, ray_address=args.ray_address)
    failed = True
    on_main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminated) if on_main_thread else None
    try:
        for row in rows:
            if reported and row["id"] is None and error_digest(row["error"]) in reported:
                progress.skip()
                continue  # an unreadable line already reported before --resume
            try:
                writer.write(row)
            except BrokenPipeError:
                raise  # -o - into a reader that stopped (`| head`): main exits quietly
            except OSError as exc:
                raise UsageError(f"cannot write to --output {shown_path(args.output)}: {exc.strerror or exc} (after "
                                 f"{progress.done} rows; rerun with --resume once it is fixed)") from None  # fmt: skip
            progress.update(row)
        failed = False
    except BatchError as exc:
        raise UsageError(str(exc)) from None
    except KeyboardInterrupt:
        progress.finish(interrupted=True)
        where = "" if to_stdout else f"; {shown_path(args.output)} holds every finished row: rerun with --resume"
        progress._say(f"robocritics batch: interrupted{where}\n")
        raise
    finally:
        # the output first: a second Ctrl-C while the workers stop must not cost a Parquet file its rows
        try:
            writer.close()
        except OSError as exc:
            if not failed:  # else the error that stopped the batch is the one to report
                raise UsageError(f"cannot write to --output {shown_path(args.output)}: {exc.strerror or exc}") from None
        finally:
            if on_main_thread:
                signal.signal(signal.SIGTERM, previous)
            rows.close()  # stops the workers now, not when the generator is collected
    progress.finish()
    if done:  # what is left: OUT's ids not seen in IN
        progress._say(f"robocritics batch: note: {len(done)} rows of {shown_path(args.output)} have ids that are "
                      f"not in {shown_path(args.input)} (from another input?); they were kept\n")  # fmt: skip
    return 0
