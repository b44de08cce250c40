"""Python frames of the interpreter: how deep the stack is (so nested calls never pass the recursion limit), and
an error cut loose from the frames it was raised in (so a failed program's values are freed at once).
"""

from __future__ import annotations

import sys
import traceback

from ..errors import ProgramError

__all__ = ["stack_depth", "released"]


def stack_depth() -> int:
    """Python frames on the calling thread's stack."""
    depth = 0
    frame = sys._getframe(1)
    while frame is not None:
        depth += 1
        frame = frame.f_back
    return depth


def released(error: ProgramError) -> ProgramError:
    """``error`` cut loose from the interpreter's frames, so the program's values are freed now, not at the
    next garbage collection (each frame of the traceback holds the exception it caught, a reference cycle)."""
    seen: BaseException | None = error
    while seen is not None:
        traceback.clear_frames(seen.__traceback__)
        seen = seen.__context__
    error.__context__ = error.__cause__ = None
    error.__suppress_context__ = True
    return error.with_traceback(None)
