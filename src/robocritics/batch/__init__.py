"""Batch evaluation of many programs: a local process pool (default) or a Ray cluster; a reward API for RL.

* :func:`evaluate` — input rows in, one output row per program out, as they finish
  (row formats: :mod:`robocritics.batch.rows`).
* :func:`reward` — one float per program, for a trainer's reward function.

See docs/batch.md.
"""

from .evaluate import evaluate
from .local import BatchError, LocalEngine
from .reward import reward
from .rows import RowError

__all__ = ["evaluate", "reward", "BatchError", "LocalEngine", "RowError"]
