"""The RoboCritics studio: a local web app to write, check, fix, replay and deploy robot programs (issue 12).

``Studio(scene, program, ...)`` (:mod:`.server`) serves one inlined page (:mod:`.page`); simulation runs in the
resource-limited :class:`~robocritics.viz.studio.worker.Evaluator`. See docs/studio.md.
"""

from .common import StudioBusy, StudioError, is_loopback
from .server import Studio

__all__ = ["Studio", "StudioBusy", "StudioError", "is_loopback"]
