"""Markdown as viser's client renders it (CommonMark with raw HTML and tables), to check that
text shown in the app makes no element of its own. Not a test module; ``markdown-it-py`` is a
test dependency (modules importing this one are skipped without it).
"""

from __future__ import annotations

import html
import re

import pytest

markdown_it = pytest.importorskip("markdown_it")

OWN_TAGS = {"p", "br", "strong", "em", "code", "sub", "ul", "li"} | {
    "table",
    "thead",
    "tbody",
    "tr",
    "th",
    "td",
}
"""Tags the app's own markdown produces (bold titles, lists, tables, the v<sub>r</sub> heading)."""


def render(markdown: str) -> str:
    """``markdown`` rendered to HTML as viser's client does (raw HTML on, GFM tables)."""
    return markdown_it.MarkdownIt("commonmark", {"html": True}).enable("table").render(markdown)


def tags(rendered: str) -> set[str]:
    """The tag names in rendered HTML (lower case)."""
    return {m.lower() for m in re.findall(r"<\s*/?\s*([a-zA-Z][\w-]*)", rendered)}


def visible(rendered: str) -> str:
    """The text a browser shows (comments are invisible; other tags separate words)."""
    text = re.sub(r"<[^>]*>", " ", re.sub(r"<!--.*?-->", "", rendered))
    return " ".join(html.unescape(text).split())


def assert_only_text(markdown: str) -> None:
    """The markdown, rendered as viser does, holds no tag but the app's own (:data:`OWN_TAGS`)."""
    rendered = render(markdown)
    assert tags(rendered) <= OWN_TAGS, rendered
