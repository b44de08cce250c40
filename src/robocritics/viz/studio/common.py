"""What the studio's server and its HTTP handler share: the limits, the error types, the loopback test."""

from __future__ import annotations

import ipaddress

from ...errors import RoboCriticsError

__all__ = ["MAX_BODY_BYTES", "MAX_PROGRAM_CHARS", "APPROVAL_TIMEOUT_S", "MAX_CHAT_CHARS", "CHAT_LOG_ENTRIES",
           "CHAT_ENTRY_CHARS", "CANCELLED_TURN_WAIT_S", "StudioError", "StudioBusy", "is_loopback"]

#: Largest request body accepted, bytes.
MAX_BODY_BYTES = 1_000_000
#: Longest program accepted, characters.
MAX_PROGRAM_CHARS = 200_000
#: Seconds a revision waits for the page's approve/reject before it counts as rejected.
APPROVAL_TIMEOUT_S = 600.0
#: Longest chat message accepted, characters.
MAX_CHAT_CHARS = 20_000
#: Chat entries kept (and sent to pages), and the characters kept of each.
CHAT_LOG_ENTRIES = 60
CHAT_ENTRY_CHARS = 4_000
#: Seconds a new turn waits for a cancelled turn's thread to end before it is refused.
CANCELLED_TURN_WAIT_S = 30.0


class StudioError(RoboCriticsError):
    """The studio cannot do what was asked (not configured, no such revision, refused); the message says why."""


class StudioBusy(StudioError):
    """Another job is running (one at a time); the message says which."""


def is_loopback(host: str) -> bool:
    """True for ``localhost``, any 127.0.0.0/8 address and ::1."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


