"""Reading a user's file (scene, program, params) with bounds: one regular file, at most N bytes, UTF-8."""

from __future__ import annotations

import stat
from pathlib import Path


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
