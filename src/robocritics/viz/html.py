"""The replay as HTML: one self-contained page, and the notebook display.

Everything is inlined (three.js, the replay component, its styles, the data), so a
page opens from ``file://`` with no server and no network, and a notebook keeps its
replay when it is saved and reopened. The notebook display is an ``<iframe
srcdoc>``: the page's scripts then run in their own document, apart from the
notebook's.
"""

from __future__ import annotations

import html
import json
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .replay import Run, replay_data

if TYPE_CHECKING:  # pragma: no cover
    from ..critic.report import Report

__all__ = ["assets", "replay_html", "write_replay_html", "Replay", "script_json"]

_ASSET_FILES = {"three.js": "three.min.js", "replay.js": "replay.js", "replay.css": "replay.css"}


@lru_cache(maxsize=None)
def _asset(name: str) -> str:
    return resources.files(__package__).joinpath("static", name).read_text(encoding="utf-8")


def assets() -> dict[str, str]:
    """The replay's JavaScript and CSS texts: ``three.js`` (three.js r159, global ``THREE``),
    ``replay.js`` (global ``RoboReplay``) and ``replay.css``."""
    return {key: _asset(name) for key, name in _ASSET_FILES.items()}


def script_json(value: Any) -> str:
    """``value`` as JSON that is safe inside ``<script type="application/json">`` (no ``</script>``, no ``<!--``)."""
    text = json.dumps(value, separators=(",", ":"), allow_nan=False)
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def _page(data: dict[str, Any], title: str, report_html: str, *, embedded: bool) -> str:
    a = assets()
    height = "100vh" if not embedded else "560px"
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta http-equiv="Content-Security-Policy" content="default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; img-src data:">
<title>{html.escape(title)}</title>
<style>{a["replay.css"]}
body {{ margin: 0; font: 14px/1.4 system-ui, sans-serif; background: #f6f7f9; color: #1d2329; }}
.rc-page-replay {{ height: {height}; min-height: 420px; }}
.rc-page-report {{ padding: 8px 16px 24px; overflow-x: auto; }}
.rc-page-report table {{ font-size: 13px; background: #fff; }}
</style></head>
<body>
<div class="rc-page-replay" id="replay"></div>
<div class="rc-page-report">{report_html}</div>
<script type="application/json" id="replay-data">{script_json(data)}</script>
<script>{a["three.js"]}</script>
<script>{a["replay.js"]}</script>
<script>
window.replay = RoboReplay.mount(document.getElementById("replay"),
  JSON.parse(document.getElementById("replay-data").textContent), {{verdictList: true}});
</script>
</body></html>
"""


def _replay_page(execution: Run, report: Report | None, title: str | None, *, embedded: bool) -> str:
    data = replay_data(execution, report, title=title)
    report_html = report._repr_html_() if report is not None else ""
    return _page(data, data["title"], report_html, embedded=embedded)


def replay_html(execution: Run, report: Report | None = None, *, title: str | None = None) -> str:
    """One self-contained HTML page: the 3-D replay with its timeline and verdicts, then the report table."""
    return _replay_page(execution, report, title, embedded=False)


def write_replay_html(path: str | Path, execution: Run, report: Report | None = None, *, title: str | None = None) -> Path:
    """Write :func:`replay_html` to ``path`` (UTF-8); returns the path."""
    return _write(path, replay_html(execution, report, title=title))


def _write(path: str | Path, page: str) -> Path:
    """``page`` written to ``path`` through the safe writer (a temporary file renamed over it, never through a link)."""
    from .._files import write_file_atomically

    return write_file_atomically(path, page, "replay page")


class Replay:
    """A replay for Jupyter: displays inline (``_repr_html_``) as an ``<iframe srcdoc>`` of the whole page.

    ``execution.show(report)`` returns one; ``Replay(...).html`` is the page itself.
    """

    def __init__(self, execution: Run, report: Report | None = None, *, title: str | None = None,
                 height_px: int = 760):  # fmt: skip
        self.html = _replay_page(execution, report, title, embedded=True)
        self.height_px = int(height_px)

    def _repr_html_(self) -> str:
        return (
            f'<iframe class="robocritics-replay" srcdoc="{html.escape(self.html, quote=True)}" '
            f'style="width:100%;height:{self.height_px}px;border:1px solid #ccd;border-radius:6px" '
            'sandbox="allow-scripts"></iframe>'
        )

    def save(self, path: str | Path) -> Path:
        """Write the page to ``path`` (UTF-8); returns the path."""
        return _write(path, self.html)
