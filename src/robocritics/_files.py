"""Files from and for the user: reading one (scene, program, params) with bounds, and writing one safely.

Reading: one regular file, at most N bytes, UTF-8. Writing: see the comment above :class:`OutputFileError`.
"""

from __future__ import annotations

import errno
import os
import stat
import tempfile
from pathlib import Path
from typing import BinaryIO

from .errors import RoboCriticsError


def read_bounded_text(path: object, what: str, shown: str, max_bytes: int, error: type[Exception]) -> str:
    """The text of the regular file ``path``: at most ``max_bytes`` bytes of UTF-8 (a leading BOM is dropped).

    Anything else raises ``error`` with a message that starts with the file's role ``what`` (e.g.
    ``"scene"``) and its name as ``shown`` (already quoted and shortened by the caller): no such file, a
    directory, a FIFO or device, unreadable, too large, not UTF-8. Never reads more than
    ``max_bytes + 1`` bytes, so ``/dev/zero`` or a huge file costs nothing.
    """
    if isinstance(path, str) and not path:
        raise error(f"the {what} file name is empty")
    try:
        p = Path(path)  # type: ignore[arg-type]
        info = p.stat()
    except FileNotFoundError:
        raise error(f"no such {what} file {shown}") from None
    except (OSError, ValueError) as exc:  # ValueError: a NUL byte in the name
        raise error(f"cannot read {what} file {shown}: {getattr(exc, 'strerror', None) or exc}") from None
    except TypeError:
        raise error(f"a {what} file is a path, got {type(path).__name__}") from None
    if stat.S_ISDIR(info.st_mode):
        raise error(f"{what} file {shown} is a directory, not a file")
    if not stat.S_ISREG(info.st_mode):
        raise error(f"{what} file {shown} is not a regular file")
    try:
        with open(p, "rb") as f:
            raw = f.read(max_bytes + 1)
    except OSError as exc:
        raise error(f"cannot read {what} file {shown}: {exc.strerror or exc}") from None
    if len(raw) > max_bytes:
        raise error(f"{what} file {shown} is larger than the limit of {max_bytes:,} bytes")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise error(f"{what} file {shown} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None


# --- writing ----------------------------------------------------------------------------------------
#
# Every file robocritics writes (batch output and its temporary file, ``fix -o``, ``check --html``, the interaction
# memory's database, the docs' screenshots) goes through the functions below, so that no file is written through a
# link someone placed at its name:
#
# * a new file's bytes go to a temporary file created exclusively (``mkstemp``: ``O_CREAT|O_EXCL|O_NOFOLLOW``, a
#   random name) in the output's own directory, which is then renamed over the output (``os.replace``, atomic; a
#   rename replaces a link itself, never its target);
# * an existing symbolic link, directory, FIFO or device at the output path is refused up front with an
#   :class:`OutputFileError` naming the path (the choice: a link there is more likely an attack or a mistake than a
#   wish to replace it, and refusing is the answer that never surprises), so nothing is computed for nothing;
# * a file that must be appended to (``batch --resume``) is opened with ``O_NOFOLLOW`` and must be a regular file
#   with one name (a hard link would write into another file too).
#
# Only the last component of a path is guarded: links among the directories above it are the user's own path.


class OutputFileError(RoboCriticsError, OSError):
    """An output file cannot be written safely: a symbolic link, a directory, a FIFO or a device sits at its name,
    its directory is missing or read-only, or the disk is full. ``path`` names the file."""

    def __init__(self, message: str, path: str | os.PathLike[str]):
        self.path = os.fspath(path)
        super().__init__(message)

    def __str__(self) -> str:  # OSError's __str__ would show the errno fields, which are unused
        return str(self.args[0]) if self.args else ""


def _shown(path: str | os.PathLike[str]) -> str:
    """``path`` quoted for a message, at most 200 characters, any control character escaped."""
    text = os.fspath(path)
    text = text if isinstance(text, str) else os.fsdecode(text)
    quoted = repr(text)
    return quoted if len(quoted) <= 200 else f"{quoted[:160]}...' ({len(text):,} characters)"


def check_output_path(path: str | os.PathLike[str], what: str = "output") -> Path:
    """``path`` as a Path, if a new file may be written there; else an :class:`OutputFileError` saying why.

    Refused: an empty name, a NUL byte, a symbolic link (even a dangling one), anything but a regular file
    (a directory, FIFO, socket, device), a directory that does not exist or is not a directory."""
    if isinstance(path, str) and not path:
        raise OutputFileError(f"the {what} file name is empty", "")
    try:
        p = Path(path)
    except TypeError:
        raise OutputFileError(f"the {what} file must be a path, got {type(path).__name__}", repr(path)) from None
    shown = _shown(p)
    try:
        info = os.lstat(p)
    except FileNotFoundError:
        info = None
    except (OSError, ValueError) as exc:  # ValueError: a NUL byte in the name
        raise OutputFileError(f"{what} {shown}: {getattr(exc, 'strerror', None) or exc}", p) from None
    if info is not None:
        if stat.S_ISLNK(info.st_mode):
            raise OutputFileError(f"{what} {shown} is a symbolic link; robocritics does not write through links: "
                                  "remove it or name another file", p)  # fmt: skip
        if stat.S_ISDIR(info.st_mode):
            raise OutputFileError(f"{what} {shown} is a directory; name a file in it", p)
        if not stat.S_ISREG(info.st_mode):
            raise OutputFileError(f"{what} {shown} is not a regular file (a FIFO, socket or device); name a file", p)
    parent = p.parent
    if not parent.is_dir():
        raise OutputFileError(f"{what} {shown}: the directory {_shown(parent)} does not exist", p)
    return p


def _creation_mode() -> int:
    """The permissions ``open(path, "w")`` would give a new file: 0o666 less the umask (mkstemp's files are 0o600).

    Read from /proc (Linux), so that no other thread sees a changed umask; elsewhere the umask is set and restored."""
    try:
        with open("/proc/self/status", "rb") as f:
            for line in f:
                if line.startswith(b"Umask:"):
                    return 0o666 & ~int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


class AtomicFile:
    """A file written under a temporary name beside ``path`` and renamed over ``path`` by :meth:`commit`.

    ``file`` is the open binary file. Used as a context manager it commits when the block ends normally and
    removes the temporary file when it raises. Every failure is an :class:`OutputFileError` naming ``path``."""

    def __init__(self, path: str | os.PathLike[str], what: str = "output", suffix: str = ".partial"):
        self.path = check_output_path(path, what)
        self.what = what
        try:
            # the name's first 40 characters (at most 160 bytes) keep the temporary name under NAME_MAX
            fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name[:40]}.", suffix=suffix, dir=self.path.parent)
        except OSError as exc:
            raise OutputFileError(f"{what} {_shown(self.path)}: cannot create a file in its directory: "
                                  f"{exc.strerror or exc}", self.path) from None  # fmt: skip
        self.tmp = Path(tmp)
        try:
            os.fchmod(fd, _creation_mode())
        except OSError:
            pass  # a file system without permissions (FAT): the file stays private, which is no harm
        self.file = os.fdopen(fd, "wb")

    def commit(self) -> Path:
        """Flush the file to disk and rename it over ``path`` (a link put there meanwhile is replaced, not followed)."""
        try:
            if not self.file.closed:
                self.file.flush()
                os.fsync(self.file.fileno())
                self.file.close()
            os.replace(self.tmp, self.path)
        except OSError as exc:
            self.discard()
            raise OutputFileError(f"cannot write {self.what} {_shown(self.path)}: {exc.strerror or exc}", self.path) from None
        return self.path

    def discard(self) -> None:
        """Close and remove the temporary file (idempotent)."""
        try:
            self.file.close()
        except OSError:
            pass
        try:
            os.unlink(self.tmp)
        except OSError:
            pass

    def __enter__(self) -> AtomicFile:
        return self

    def __exit__(self, kind, value, traceback) -> None:
        if kind is None:
            self.commit()
        else:
            self.discard()


def write_file_atomically(path: str | os.PathLike[str], data: bytes | str, what: str = "output") -> Path:
    """Write ``data`` (text as UTF-8) to ``path`` through an :class:`AtomicFile`; returns the path.

    A reader sees either the old file or the whole new one, never a part."""
    atomic = AtomicFile(path, what)
    with atomic:
        try:
            atomic.file.write(data.encode("utf-8") if isinstance(data, str) else data)
        except OSError as exc:
            raise OutputFileError(f"cannot write {what} {_shown(atomic.path)}: {exc.strerror or exc}", atomic.path) from None
    return atomic.path


def open_new_stream(path: str | os.PathLike[str], what: str = "output") -> BinaryIO:
    """A new, empty file at ``path`` open for writing, for output that readers should see as it is written
    (``batch -o OUT.jsonl``): an :class:`AtomicFile` renamed over ``path`` at once, its descriptor kept open."""
    atomic = AtomicFile(path, what)
    try:
        os.replace(atomic.tmp, atomic.path)
    except OSError as exc:
        atomic.discard()
        raise OutputFileError(f"cannot write {what} {_shown(atomic.path)}: {exc.strerror or exc}", atomic.path) from None
    return atomic.file


def open_regular(path: str | os.PathLike[str], flags: int, what: str = "output") -> BinaryIO:
    """The existing regular file ``path`` (or a new one, with ``O_CREAT`` in ``flags``) opened with ``os.open``
    ``flags`` (``O_RDWR``, ``O_WRONLY | O_APPEND``) as a binary file; a symbolic link (``O_NOFOLLOW``), FIFO (opened non-blocking, so nothing waits for a writer),
    directory or device is an :class:`OutputFileError`."""
    shown = _shown(path)
    try:
        fd = os.open(path, flags | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC, 0o666)  # the mode if O_CREAT
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise OutputFileError(f"{what} {shown} is a symbolic link; robocritics does not write through links: "
                                  "remove it or name another file", path) from None  # fmt: skip
        raise OutputFileError(f"{what} {shown}: {exc.strerror or exc}", path) from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise OutputFileError(f"{what} {shown} is not a regular file", path)
        if flags & os.O_ACCMODE != os.O_RDONLY and info.st_nlink > 1:  # a hard link writes into another file too
            raise OutputFileError(f"{what} {shown} has {info.st_nlink} hard links: writing it would change the "
                                  "other names too; copy it to a file of its own", path)  # fmt: skip
        os.set_blocking(fd, True)
    except BaseException:
        os.close(fd)
        raise
    access = flags & os.O_ACCMODE
    mode = "rb" if access == os.O_RDONLY else "rb+" if access == os.O_RDWR else "ab" if flags & os.O_APPEND else "wb"
    return os.fdopen(fd, mode)
