"""See the robot move: the 3-D replay of a simulated run, in a notebook, an offline HTML file and the studio.

One replay component (``static/replay.js``, on a vendored three.js) draws
:func:`replay_data`; :func:`replay_html` wraps it in one self-contained page (no
external URLs: it opens from ``file://`` with no server); :class:`Replay` shows it
inline in Jupyter (``execution.show(report)``); :mod:`robocritics.viz.studio` is
the interactive web interface.
"""

from .html import Replay, assets, replay_html, write_replay_html
from .replay import MAX_FRAME_RATE_HZ, REPLAY_FORMAT, replay_data

__all__ = [
    "replay_data",
    "replay_html",
    "write_replay_html",
    "Replay",
    "assets",
    "REPLAY_FORMAT",
    "MAX_FRAME_RATE_HZ",
]
