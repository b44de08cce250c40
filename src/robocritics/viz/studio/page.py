"""The studio page: ONE HTML text with every asset inlined (three.js, the replay, the studio's JS and CSS)."""

from __future__ import annotations

from functools import lru_cache
from importlib.resources import files

from .. import assets

__all__ = ["studio_page"]


def _static(name: str) -> str:
    return files("robocritics.viz").joinpath("static", name).read_text(encoding="utf-8")


def _script(text: str) -> str:
    return "<script>" + text.replace("</script", "<\\/script") + "</script>"


@lru_cache(maxsize=1)
def studio_page() -> str:
    """The whole page (no external URL): studio.html with the assets put in its placeholders."""
    a = assets()
    page = _static("studio.html")
    return (
        page.replace("<!--STYLE-->", "<style>" + a["replay.css"] + "\n" + _static("studio.css") + "</style>")
        .replace("<!--SCRIPTS-->", _script(a["three.js"]) + _script(a["replay.js"]) + _script(_static("studio.js")))
    )
