"""The one safe file writer (issue 22, class 2): no file robocritics writes goes through a link placed at its name.

Every case puts a victim file behind a symbolic link (at the output path, or at the temporary name an older
version used, ``OUT.partial``) and checks that the victim's bytes stay as they were, and that the command ends
with a one-line error naming the path (or, for a link at a temporary name, is not fooled by it at all).
"""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from robocritics._files import AtomicFile, OutputFileError, open_new_stream, open_regular, write_file_atomically
from robocritics.cli.main import main

PROGRAMS = Path(__file__).resolve().parents[1] / "examples" / "programs"
CLI = [sys.executable, "-m", "robocritics.cli"]
VICTIM = b"precious bytes, not robocritics output\n"


@pytest.fixture
def victim(tmp_path):
    path = tmp_path / "victim.txt"
    path.write_bytes(VICTIM)
    path.chmod(0o644)
    return path


def _untouched(victim: Path) -> bool:
    return victim.read_bytes() == VICTIM and stat.S_IMODE(victim.stat().st_mode) == 0o644


def _listing(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


# --- the writer itself --------------------------------------------------------------------------------------------


def test_writes_the_bytes_with_the_umask_permissions_and_leaves_no_temporary_file(tmp_path):
    old = os.umask(0o027)
    try:
        path = write_file_atomically(tmp_path / "out.txt", "héllo ✓\n")
    finally:
        os.umask(old)
    assert path.read_bytes() == "héllo ✓\n".encode() and stat.S_IMODE(path.stat().st_mode) == 0o640
    assert _listing(tmp_path) == ["out.txt"]


def test_replaces_an_existing_regular_file_whole(tmp_path):
    path = tmp_path / "out.txt"
    path.write_bytes(b"x" * 10_000)
    write_file_atomically(path, b"short")
    assert path.read_bytes() == b"short" and _listing(tmp_path) == ["out.txt"]


@pytest.mark.parametrize("dangling", [False, True])
def test_a_link_at_the_output_path_is_refused_naming_it_and_its_target_is_unchanged(tmp_path, victim, dangling):
    link = tmp_path / "out.html"
    link.symlink_to(tmp_path / "nowhere" if dangling else victim)
    with pytest.raises(OutputFileError, match="out.html' is a symbolic link") as caught:
        write_file_atomically(link, b"attacker-chosen page")
    assert caught.value.path == str(link) and link.is_symlink()
    assert _untouched(victim) and _listing(tmp_path) == ["out.html", "victim.txt"]


def test_a_link_placed_at_the_output_path_while_writing_is_replaced_itself_never_followed(tmp_path, victim):
    out = tmp_path / "out.txt"
    atomic = AtomicFile(out)
    atomic.file.write(b"the new content")
    out.symlink_to(victim)  # the race: a link appears after the check
    atomic.commit()
    assert not out.is_symlink() and out.read_bytes() == b"the new content" and _untouched(victim)


def test_a_link_at_the_old_fixed_temporary_name_is_never_used(tmp_path, victim):
    (tmp_path / "out.parquet.partial").symlink_to(victim)
    write_file_atomically(tmp_path / "out.parquet", b"data")
    assert (tmp_path / "out.parquet").read_bytes() == b"data" and _untouched(victim)
    assert (tmp_path / "out.parquet.partial").is_symlink()


def test_a_fifo_a_directory_and_a_device_are_refused_without_blocking(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    (tmp_path / "adir").mkdir()
    for path, message in ((fifo, "not a regular file"), (tmp_path / "adir", "is a directory"), ("/dev/null", "not a regular file")):
        with pytest.raises(OutputFileError, match=message):
            write_file_atomically(path, b"x")
    # appending (batch --resume) opens non-blocking, so a FIFO with no writer does not hang the open
    with pytest.raises(OutputFileError, match="not a regular file"):
        open_regular(fifo, os.O_RDWR)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_open_regular_refuses_a_link_and_appends_to_a_regular_file(tmp_path, victim):
    link = tmp_path / "out.jsonl"
    link.symlink_to(victim)
    with pytest.raises(OutputFileError, match="symbolic link"):
        open_regular(link, os.O_WRONLY | os.O_APPEND)
    assert _untouched(victim)
    real = tmp_path / "real.jsonl"
    real.write_bytes(b"a\n")
    with open_regular(real, os.O_WRONLY | os.O_APPEND) as f:
        f.write(b"b\n")
    assert real.read_bytes() == b"a\nb\n"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only directories")
def test_a_read_only_directory_is_a_typed_error(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        with pytest.raises(OutputFileError, match="cannot create a file in its directory"):
            write_file_atomically(ro / "out.txt", b"x")
    finally:
        ro.chmod(0o755)


def test_a_read_only_directory_is_a_typed_error_even_for_root(tmp_path):
    """``/proc`` refuses new files to everyone: the same typed error, no traceback."""
    with pytest.raises(OutputFileError, match="cannot create a file in its directory"):
        write_file_atomically("/proc/robocritics-out.txt", b"x")


@pytest.mark.parametrize("name", ["", "nul\x00byte.txt", "missing-dir/out.txt"])
def test_bad_names_are_typed_errors(tmp_path, name):
    with pytest.raises(OutputFileError):
        write_file_atomically(str(tmp_path / name) if name else name, b"x")
    assert _listing(tmp_path) == []


def test_unicode_and_long_names_work(tmp_path):
    path = write_file_atomically(tmp_path / ("ünïcödé ✓ " + "x" * 200 + ".txt"), b"ok")
    assert path.read_bytes() == b"ok" and _listing(tmp_path) == [path.name]


def test_a_failed_write_leaves_no_temporary_file(tmp_path):
    atomic = AtomicFile(tmp_path / "out.txt")
    with pytest.raises(RuntimeError):
        with atomic:
            atomic.file.write(b"half")
            raise RuntimeError("stopped")
    assert _listing(tmp_path) == []


def test_a_stream_is_created_new_and_its_rows_are_visible_at_once(tmp_path):
    out = tmp_path / "out.jsonl"
    out.write_bytes(b"old content\n")
    f = open_new_stream(out)
    f.write(b"row\n")
    f.flush()
    assert out.read_bytes() == b"row\n"  # a reader sees the row before the stream is closed
    f.close()


def test_concurrent_writers_each_leave_a_whole_file(tmp_path):
    out = tmp_path / "out.bin"
    payloads = [bytes([i]) * 200_000 for i in range(8)]
    threads = [threading.Thread(target=write_file_atomically, args=(out, p)) for p in payloads]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert out.read_bytes() in payloads and _listing(tmp_path) == ["out.bin"]


# --- every command that writes a file -----------------------------------------------------------------------------


def _batch_input(tmp_path: Path, rows: int = 2) -> Path:
    src = tmp_path / "in.jsonl"
    src.write_text("".join(json.dumps({"id": i, "scene": "sorting", "program": "home("}) + "\n" for i in range(rows)))
    return src


@pytest.mark.parametrize("name", ["out.jsonl", "out.parquet"])
@pytest.mark.parametrize("resume", [False, True])
def test_batch_refuses_a_link_at_the_output(capsys, tmp_path, victim, name, resume):
    if name.endswith(".parquet"):
        pytest.importorskip("pyarrow")
    src, out = _batch_input(tmp_path), tmp_path / name
    out.symlink_to(victim)
    code = main(["batch", str(src), "-o", str(out), *(["--resume"] if resume else [])])
    err = capsys.readouterr().err
    assert code == 2 and f"{name}' is a symbolic link" in err and len(err.strip().splitlines()) == 1, err
    assert _untouched(victim) and out.is_symlink()


def test_batch_parquet_ignores_a_link_at_out_partial(tmp_path, victim):
    """The reported attack: a link at ``X.parquet.partial`` (the old fixed temporary name) overwrote its target."""
    pq = pytest.importorskip("pyarrow.parquet")
    src, out = _batch_input(tmp_path, 3), tmp_path / "X.parquet"
    (tmp_path / "X.parquet.partial").symlink_to(victim)
    done = subprocess.run([*CLI, "batch", str(src), "-o", str(out), "--workers", "1"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert _untouched(victim) and (tmp_path / "X.parquet.partial").is_symlink() and not out.is_symlink()
    assert sorted(pq.read_table(out).column("id").to_pylist()) == ["0", "1", "2"]
    assert _listing(tmp_path) == ["X.parquet", "X.parquet.partial", "in.jsonl", "victim.txt"]


def test_batch_refuses_a_fifo_at_the_output_without_hanging(tmp_path):
    src, fifo = _batch_input(tmp_path), tmp_path / "out.jsonl"
    os.mkfifo(fifo)
    for extra in ([], ["--resume"]):
        done = subprocess.run([*CLI, "batch", str(src), "-o", str(fifo), *extra], capture_output=True, text=True, timeout=120)
        assert done.returncode == 2 and "not a regular file" in done.stderr and "Traceback" not in done.stderr, done.stderr


def test_batch_to_a_unicode_path(tmp_path):
    src, out = _batch_input(tmp_path), tmp_path / "résultats ✓" / "sortie ü.jsonl"
    out.parent.mkdir()
    assert main(["batch", str(src), "-o", str(out), "--workers", "1"]) == 0
    assert sorted(json.loads(line)["id"] for line in out.read_text().splitlines()) == [0, 1]


def test_fix_refuses_a_link_at_its_output_before_repairing(capsys, tmp_path, victim):
    out = tmp_path / "fixed.py"
    out.symlink_to(victim)
    code = main(["fix", str(PROGRAMS / "sorting_naive.py"), "-o", str(out)])
    cap = capsys.readouterr()
    assert code == 2 and "fixed.py' is a symbolic link" in cap.err and cap.out == "", cap  # refused before any work
    assert _untouched(victim)


def test_check_html_refuses_a_link_and_writes_a_regular_file(capsys, tmp_path, victim):
    link, page = tmp_path / "replay.html", tmp_path / "réplay ✓.html"
    link.symlink_to(victim)
    program = str(PROGRAMS / "sorting_naive.py")
    assert main(["check", program, "--html", str(link)]) == 2
    assert "replay.html' is a symbolic link" in capsys.readouterr().err and _untouched(victim)
    assert main(["check", program, "--html", str(page)]) in (0, 1)
    assert page.read_text(encoding="utf-8").startswith("<!DOCTYPE html>") and not page.is_symlink()


def test_resume_refuses_an_output_hard_linked_to_another_file(capsys, tmp_path, victim):
    """A hard link is a link too: appending to it would append to the victim."""
    src, out = _batch_input(tmp_path), tmp_path / "out.jsonl"
    os.link(victim, out)
    code = main(["batch", str(src), "-o", str(out), "--resume"])
    err = capsys.readouterr().err
    assert code == 2 and "has 2 hard links" in err, err
    assert _untouched(victim)


def test_a_name_of_255_bytes_gets_a_temporary_name_that_fits(tmp_path):
    name = "é" * 120 + ".jsonl"  # 246 bytes of UTF-8
    path = write_file_atomically(tmp_path / name, b"ok")
    assert path.read_bytes() == b"ok" and _listing(tmp_path) == [name]
